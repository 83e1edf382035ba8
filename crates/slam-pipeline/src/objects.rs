//! The object mapper: posed detections in, ellipsoids out.
//!
//! Per frame: the boxes of the objects' projected ellipsoids are given to the associator (ODA's
//! `a^g` cue), detections are assigned to tracks, and each track keeps its observations (frame,
//! camera, box). An object gets an ellipsoid once it has `min_views` boxes away from the image border
//! seen with at least `min_parallax_deg` between the first and the latest ray; it is re-optimised each
//! time `refit_every` new boxes have arrived. Fitting is [`slam_optim::object::refine`] (DQP starts,
//! box error with Huber on the exact clipped bounds, class prior on the axes, upright constraint, and a
//! joint stage under a pose-drift prior when boxes and poses disagree) on at most `max_views` evenly
//! spaced views. An object whose fitted boxes still miss by more than `dynamic_rms_px` (RMS) is flagged
//! dynamic: a moving object cannot be explained by one static ellipsoid.

use std::{collections::BTreeMap, path::Path};

use nalgebra::Vector3;
use serde::Serialize;
use slam_assoc::{ObjectTracker, TrackerConfig, TrackerInput};
use slam_core::{geometry::BBox, Associator, ClassId, Detection, TrackId};
use slam_optim::object::{refine, ObjectPrior, RefineConfig};
use slam_quadric::{init::BoxView, project, Camera, Ellipsoid, ImageSize};

/// How an object's ellipsoid is computed from its views.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FitMethod {
    /// DQP starts + object optimisation ([`slam_optim::object::refine`]).
    #[default]
    Refine,
    /// QuadricSLAM's SVD (baseline).
    QSlam,
    /// Rubino et al.'s conic method (baseline).
    Conic,
    /// Triangulated centre + full 3×3 block (baseline).
    Tri,
    /// The paper's DQP as printed (baseline).
    TriYaw,
}

impl FitMethod {
    /// Short name.
    pub fn name(&self) -> &'static str {
        match self {
            FitMethod::Refine => "Tri+Yaw+refine",
            FitMethod::QSlam => "Q-SLAM",
            FitMethod::Conic => "Conic",
            FitMethod::Tri => "Tri",
            FitMethod::TriYaw => "Tri+Yaw",
        }
    }
}

/// Settings of the [`ObjectMapper`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapperConfig {
    /// Fitting method.
    pub method: FitMethod,
    /// Image size (for clipped bounds and the border test).
    pub image: ImageSize,
    /// Fewest border-free boxes before an ellipsoid is fitted. Default 3.
    pub min_views: usize,
    /// Smallest angle between the first and the latest ray through the box centres, degrees. Default 3.
    pub min_parallax_deg: f64,
    /// Boxes within this many pixels of the border are not used for fitting (the paper's rule). Default 5.
    pub border_margin_px: f64,
    /// Refit after this many new boxes. Default 5.
    pub refit_every: usize,
    /// Most views used in one fit (evenly spaced over the track). Default 20.
    pub max_views: usize,
    /// RMS box misfit above which a fitted object is flagged dynamic, pixels. Default 12.
    pub dynamic_rms_px: f64,
    /// Tracker settings.
    pub tracker: TrackerConfig,
}

impl Default for MapperConfig {
    fn default() -> Self {
        Self {
            method: FitMethod::Refine,
            image: ImageSize::new(1242.0, 375.0),
            min_views: 3,
            min_parallax_deg: 3.0,
            border_margin_px: 5.0,
            refit_every: 5,
            max_views: 20,
            dynamic_rms_px: 12.0,
            tracker: TrackerConfig::default(),
        }
    }
}

/// Class priors of semi-axes (own x = length, y = height, z = width), from KITTI's average label
/// dimensions (cars 3.9 × 1.5 × 1.6 m), COCO class ids.
pub fn class_prior(class: ClassId) -> ObjectPrior {
    let (a, s) = match class.0 {
        0 => ((0.45, 0.87, 0.35), (0.15, 0.15, 0.1)),  // person
        1 | 3 => ((0.9, 0.87, 0.3), (0.2, 0.15, 0.1)), // bicycle, motorcycle
        5..=7 => ((3.5, 1.5, 1.25), (1.5, 0.5, 0.3)),  // bus, train, truck
        _ => ((1.95, 0.77, 0.82), (0.3, 0.1, 0.1)),    // car and others
    };
    ObjectPrior { axes: Vector3::new(a.0, a.1, a.2), sigma: Vector3::new(s.0, s.1, s.2) }
}

/// One observation of an object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Frame index.
    pub frame: usize,
    /// The camera at that frame.
    pub camera: Camera,
    /// The detected box.
    pub bbox: BBox,
    /// Index of the detection in that frame's input (lets callers trace detections back).
    pub detection: usize,
}

/// An object of the map.
#[derive(Debug, Clone)]
pub struct MappedObject {
    /// Identity (the track's).
    pub id: TrackId,
    /// Class.
    pub class: ClassId,
    /// Observations, in frame order.
    pub observations: Vec<Observation>,
    /// Fitted ellipsoid (world frame), once there is one.
    pub ellipsoid: Option<Ellipsoid>,
    /// Flagged as moving.
    pub dynamic: bool,
    fitted_at: usize,
}

/// The object mapper.
pub struct ObjectMapper {
    tracker: ObjectTracker,
    config: MapperConfig,
    objects: BTreeMap<TrackId, MappedObject>,
    fits: usize,
}

impl ObjectMapper {
    /// A mapper around an associator.
    pub fn new(associator: Box<dyn Associator>, config: MapperConfig) -> Self {
        Self { tracker: ObjectTracker::new(associator, config.tracker), config, objects: BTreeMap::new(), fits: 0 }
    }

    /// All objects, by id.
    pub fn objects(&self) -> impl Iterator<Item = &MappedObject> {
        self.objects.values()
    }

    /// Number of ellipsoid fits run so far.
    pub fn fits(&self) -> usize {
        self.fits
    }

    /// Process one frame; returns each detection's object.
    pub fn step(&mut self, frame: usize, camera: &Camera, detections: &[Detection]) -> Vec<Option<TrackId>> {
        let projected: BTreeMap<TrackId, BBox> = self
            .objects
            .values()
            .filter_map(|o| {
                let e = o.ellipsoid.as_ref()?;
                let b = project(e, camera).and_then(|c| c.clipped_bounds(&self.config.image)).ok()?;
                Some((o.id, b))
            })
            .collect();
        let out = self.tracker.step(&TrackerInput { detections, projected: &projected, flow: &[], keyframe: true });
        let mut touched = Vec::new();
        for (k, (t, d)) in out.tracks.iter().zip(detections).enumerate() {
            let Some(id) = *t else { continue };
            let obj = self.objects.entry(id).or_insert_with(|| MappedObject {
                id,
                class: d.class,
                observations: Vec::new(),
                ellipsoid: None,
                dynamic: false,
                fitted_at: 0,
            });
            obj.observations.push(Observation { frame, camera: *camera, bbox: d.bbox, detection: k });
            touched.push(id);
        }
        for id in touched {
            self.maybe_fit(id);
        }
        out.tracks
    }

    fn maybe_fit(&mut self, id: TrackId) {
        let cfg = self.config;
        let Some(obj) = self.objects.get_mut(&id) else { return };
        let usable: Vec<&Observation> =
            obj.observations.iter().filter(|o| !o.bbox.touches_border(&cfg.image, cfg.border_margin_px)).collect();
        let due = match obj.ellipsoid {
            None => usable.len() >= cfg.min_views,
            Some(_) => usable.len() >= obj.fitted_at + cfg.refit_every,
        };
        if !due || usable.len() < cfg.min_views {
            return;
        }
        let (first, last) = (usable[0], usable[usable.len() - 1]);
        let ray = |o: &Observation| {
            let [u, v] = o.bbox.centre();
            o.camera.ray_direction(u, v)
        };
        let parallax = ray(first).angle(&ray(last)).to_degrees();
        if parallax < cfg.min_parallax_deg && obj.ellipsoid.is_none() {
            return;
        }
        let n = usable.len();
        let pick: Vec<usize> = if n <= cfg.max_views {
            (0..n).collect()
        } else {
            (0..cfg.max_views).map(|i| i * (n - 1) / (cfg.max_views - 1)).collect()
        };
        let views: Vec<BoxView> = pick.iter().map(|&i| BoxView::new(usable[i].camera, usable[i].bbox)).collect();
        obj.fitted_at = n;
        self.fits += 1;
        use slam_quadric::init::{Conic, Dqp, Initializer, QSlamSvd, Tri};
        let fitted = match cfg.method {
            FitMethod::Refine => refine(&views, &cfg.image, &class_prior(obj.class), &RefineConfig::default()),
            FitMethod::QSlam => QSlamSvd.initialize(&views),
            FitMethod::Conic => Conic::default().initialize(&views),
            FitMethod::Tri => Tri::default().initialize(&views),
            FitMethod::TriYaw => Dqp::default().initialize(&views),
        };
        match fitted {
            Ok(e) => {
                let rms = box_rms(&views, &cfg.image, &e);
                obj.dynamic = rms.is_none_or(|r| r > cfg.dynamic_rms_px);
                obj.ellipsoid = Some(e);
            }
            Err(err) => tracing::debug!(object = %id, "no ellipsoid yet: {err}"),
        }
    }
}

fn box_rms(views: &[BoxView], image: &ImageSize, e: &Ellipsoid) -> Option<f64> {
    let mut sum = 0.0;
    for v in views {
        let r = slam_quadric::box_error(e, &v.camera, &v.bbox, &slam_quadric::BoundsModel::Clipped(*image)).ok()?;
        sum += r.error.norm_squared();
    }
    Some((sum / (4 * views.len().max(1)) as f64).sqrt())
}

/// Version of the object-map JSON.
pub const OBJECT_MAP_VERSION: u32 = 1;

#[derive(Serialize)]
struct ObjectJson {
    id: u64,
    class: u16,
    center: [f64; 3],
    semi_axes: [f64; 3],
    rotation: [f64; 9],
    frames: Vec<usize>,
    dynamic: bool,
}

#[derive(Serialize)]
struct MapJson {
    version: u32,
    frame: &'static str,
    objects: Vec<ObjectJson>,
}

/// Write the object map (objects with an ellipsoid) as JSON, atomically. Schema (version 1): `objects`
/// with `id`, `class` (COCO index), `center` `[x, y, z]` and `rotation` (3×3 row-major, world from
/// object) in the world frame of the poses, `semi_axes` metres along the object's x (length), y
/// (height), z (width), `frames` (frames of its detections), `dynamic`.
pub fn write_object_map(path: &Path, objects: &[&MappedObject]) -> std::io::Result<()> {
    let objects = objects
        .iter()
        .filter_map(|o| {
            let e = o.ellipsoid.as_ref()?;
            let r = e.rotation();
            Some(ObjectJson {
                id: o.id.0,
                class: o.class.0,
                center: [e.centre().x, e.centre().y, e.centre().z],
                semi_axes: [e.semi_axes.x, e.semi_axes.y, e.semi_axes.z],
                rotation: [
                    r[(0, 0)],
                    r[(0, 1)],
                    r[(0, 2)],
                    r[(1, 0)],
                    r[(1, 1)],
                    r[(1, 2)],
                    r[(2, 0)],
                    r[(2, 1)],
                    r[(2, 2)],
                ],
                frames: o.observations.iter().map(|x| x.frame).collect(),
                dynamic: o.dynamic,
            })
        })
        .collect();
    let text = serde_json::to_string_pretty(&MapJson {
        version: OBJECT_MAP_VERSION,
        frame: "world of the input poses",
        objects,
    })
    .map_err(std::io::Error::other)?;
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)
}
