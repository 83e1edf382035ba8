//! Fitting: how an ellipsoid is computed ([`FitMethod`]), when an object is due for a fit and what
//! the fit needs ([`FitJob`], [`ObjectMapper::fit_jobs`]), and what is accepted of its result
//! ([`ObjectMapper::apply`]: physical size, the stereo gate, the dynamic flags).

use nalgebra::{Vector3, Vector4};
use slam_core::{ClassId, KeyframeId, PointId, TrackId};
use slam_optim::{
    object::{box_residual, refine_with_cues, BoxShape, Cues, RefineConfig, SurfaceCue, SurfacePoint, YawCue},
    SharedOptimizer,
};
use slam_quadric::{init::BoxView, Ellipsoid, ImageSize};

use super::{
    class_prior, evidence::stereo_agrees, motion::MIN_MOTION_CENTROIDS, physically_plausible, surface_cue,
    ObjectMapper, Observation,
};

pub use super::method::FitMethod;

/// Most surface points a fit uses ([`FitJob::surface_points`]): 16 from each of 20 views.
const SURFACE_POINTS_PER_FIT: usize = 320;

/// An ellipsoid fit to run (possibly on another thread): everything it needs, by value.
#[derive(Debug, Clone)]
pub struct FitJob {
    /// The object.
    pub id: TrackId,
    /// Its class.
    pub class: ClassId,
    /// The views used.
    pub views: Vec<BoxView>,
    /// Reference keyframe and relative pose of each view, when known ([`FitJob::repose`]).
    pub references: Vec<Option<(KeyframeId, nalgebra::Isometry3<f64>)>>,
    /// Its map points (the runner looks up their positions for texture planes).
    pub points: Vec<PointId>,
    /// Positions of its map points when the job was made ([`FitJob::locate`]): the runner's fallback
    /// for points its own map does not hold.
    pub positions: Vec<(PointId, nalgebra::Vector3<f64>)>,
    /// The object's stereo points in each view's frame (its left camera's frame, with their depth σ):
    /// the surface cue, placed in the world with the view's (re-posed) camera when the fit runs.
    pub surfaces: Vec<Vec<(Vector3<f64>, f64)>>,
    /// The object's generation when the job was made (see [`FitResult::generation`]).
    generation: u32,
    method: FitMethod,
    box_shape: BoxShape,
    point_yaw: bool,
    surface: Option<SurfaceCue>,
    image: ImageSize,
    dynamic_rms_px: f64,
    dynamic_prior_sigmas: Option<f64>,
    max_depth_m: f64,
    optimizer: SharedOptimizer,
}

/// Outcome of a [`FitJob`].
#[derive(Debug, Clone)]
pub struct FitResult {
    /// The object.
    pub id: TrackId,
    /// The ellipsoid, when the fit succeeded.
    pub ellipsoid: Option<Ellipsoid>,
    /// Box misfit too large for a static object, or a size its class does not have.
    pub dynamic: bool,
    /// The size alone: semi-axes farther than `dynamic_prior_sigmas` from the class prior.
    pub odd_size: bool,
    /// The object's generation the job was made in: a result from before its observations were
    /// dropped (a refuted trend flag) is discarded.
    pub generation: u32,
}

impl FitJob {
    /// Replace each view's camera pose by `keyframe pose ∘ relative pose` where `keyframe_pose` knows
    /// the view's reference keyframe (the mapper's refined poses).
    pub fn repose(&mut self, keyframe_pose: impl Fn(KeyframeId) -> Option<nalgebra::Isometry3<f64>>) {
        for (v, r) in self.views.iter_mut().zip(&self.references) {
            if let Some(pose) = r.and_then(|(k, rel)| keyframe_pose(k).map(|p| p * rel)) {
                v.camera.world_from_camera = pose;
            }
        }
    }

    /// Keep the positions `position` gives of the job's points (those it knows), for a runner whose map
    /// lacks some of them.
    pub fn locate(&mut self, position: impl Fn(PointId) -> Option<nalgebra::Vector3<f64>>) {
        self.positions = self.points.iter().filter_map(|&p| position(p).map(|x| (p, x))).collect();
    }

    /// Whether [`FitJob::run`] uses texture planes (only a method that refines does).
    pub fn uses_planes(&self) -> bool {
        self.method.refines()
    }

    /// Run the fit: the method's initialiser, then, when the method refines, the object optimisation;
    /// `planes` are texture planes of the object's points (used by the optimisation).
    pub fn run(&self, planes: &[Vector4<f64>]) -> FitResult {
        self.run_with_cue(planes, None)
    }

    /// The surface cue's points in the world, from each view's camera (re-posed where its keyframe
    /// moved): the point, the ray it was seen along, its depth σ and a pixel's width at its depth.
    pub fn surface_points(&self) -> Vec<SurfacePoint> {
        // the points of one frame share that frame's disparity errors (the rig's calibration, the
        // matcher's bias on a surface), so many of them are worth few independent ones: a fit takes
        // `SURFACE_POINTS_PER_FIT` in all, spread over its views, which also bounds its cost
        let per_view = (SURFACE_POINTS_PER_FIT / self.views.len().max(1)).max(1);
        self.views
            .iter()
            .zip(&self.surfaces)
            .flat_map(|(v, points)| {
                let pose = v.camera.world_from_camera;
                let fx = v.camera.intrinsics.fx;
                let step = points.len().div_ceil(per_view).max(1);
                points.iter().step_by(step).map(move |(p, sigma_z)| {
                    let point = (pose * nalgebra::Point3::from(*p)).coords;
                    SurfacePoint { point, camera: pose.translation.vector, sigma_z: *sigma_z, sigma_across: p.z / fx }
                })
            })
            .collect()
    }

    /// Whether the fit wants the stereo-point yaw cue ([`MapperConfig::point_yaw`]) and refines.
    pub fn uses_point_yaw(&self) -> bool {
        self.point_yaw && self.method.refines()
    }

    /// [`FitJob::run`] with a soft yaw prior (the stereo-point cue, [`crate::yaw_cue`]).
    pub fn run_with_cue(&self, planes: &[Vector4<f64>], yaw: Option<YawCue>) -> FitResult {
        let views = &self.views;
        let fitted = if self.method.refines() {
            let config = RefineConfig { box_shape: self.box_shape, ..RefineConfig::default() };
            let prior = class_prior(self.class);
            let init = self.method.initializer();
            let surface_points = self.surface_points();
            let cues = Cues { planes, yaw, surface: self.surface, surface_points: &surface_points };
            refine_with_cues(init, views, &self.image, &prior, &config, &cues, &*self.optimizer)
        } else {
            self.method.initializer().initialize(views)
        };
        let too_far = |e: &Ellipsoid| {
            views
                .last()
                .is_some_and(|v| (e.centre() - v.camera.world_from_camera.translation.vector).norm() > self.max_depth_m)
        };
        match fitted {
            Ok(e) if too_far(&e) => {
                tracing::debug!(object = %self.id, "ellipsoid beyond {} m discarded", self.max_depth_m);
                FitResult { id: self.id, ellipsoid: None, dynamic: false, odd_size: false, generation: self.generation }
            }
            Ok(e) => {
                let rms = box_rms(views, &self.image, &e, self.box_shape);
                // a moving object fitted as a static one usually needs a size its class does not have
                // (a car driving ahead looks like a large car far away): with the prior-using fit, axes
                // this many σ from the class prior (Mahalanobis) flag it too
                let prior = class_prior(self.class);
                let size_dev = (e.semi_axes - prior.axes).component_div(&prior.sigma).norm();
                let odd_size = self.method.refines() && self.dynamic_prior_sigmas.is_some_and(|k| size_dev > k);
                let dynamic = rms.is_none_or(|r| r > self.dynamic_rms_px) || odd_size;
                tracing::debug!(
                    object = self.id.0,
                    views = views.len(),
                    surface_points = self.surfaces.iter().map(Vec::len).sum::<usize>(),
                    centre = ?e.centre().as_slice(),
                    axes = ?e.semi_axes.as_slice(),
                    "fitted: box misfit {} px RMS, size {size_dev:.1} prior sigmas from its class",
                    rms.map_or("(none)".to_string(), |r| format!("{r:.1}"))
                );
                if odd_size {
                    tracing::debug!(object = %self.id, size_dev, axes = ?e.semi_axes.as_slice(), "size unlike its class: dynamic");
                }
                if dynamic {
                    let mut heights: Vec<f64> = views.iter().map(|v| v.bbox.height()).collect();
                    heights.sort_by(f64::total_cmp);
                    tracing::debug!(object = %self.id, rms = ?rms, views = views.len(), median_box_height = heights.get(heights.len() / 2).copied().unwrap_or(0.0), "box misfit: dynamic");
                }
                FitResult { id: self.id, ellipsoid: Some(e), dynamic, odd_size, generation: self.generation }
            }
            Err(err) => {
                tracing::debug!(object = %self.id, "no ellipsoid yet: {err}");
                FitResult { id: self.id, ellipsoid: None, dynamic: false, odd_size: false, generation: self.generation }
            }
        }
    }
}

fn box_rms(views: &[BoxView], image: &ImageSize, e: &Ellipsoid, shape: BoxShape) -> Option<f64> {
    let mut sum = 0.0;
    for v in views {
        sum += box_residual(v, image, e, shape)?.norm_squared();
    }
    Some((sum / (4 * views.len().max(1)) as f64).sqrt())
}

impl ObjectMapper {
    /// Fit jobs of every object that is due (sorted by id); marks them as fitted at their current view
    /// count. Moving objects get none.
    pub fn fit_jobs(&mut self) -> Vec<FitJob> {
        let ids: Vec<TrackId> = self.objects.keys().copied().collect();
        ids.into_iter().filter_map(|id| self.job_for(id)).collect()
    }

    /// Take the result of a fit.
    pub fn apply(&mut self, result: FitResult) {
        let id = result.id;
        let Some(obj) = self.objects.get_mut(&id) else { return };
        if result.generation != obj.generation {
            tracing::debug!(object = %id, "fit of observations since dropped: discarded");
            return;
        }
        if let Some(e) = result.ellipsoid {
            // a size no real object of its class has: removed (refitted later, with more views)
            if let Err(why) = physically_plausible(obj.class, &e.semi_axes) {
                tracing::info!(
                    "object {} ({}): ellipsoid not accepted, {why} (axes {:.2?} m)",
                    id.0,
                    obj.class.name(),
                    e.semi_axes.as_slice()
                );
                self.implausible += 1;
                obj.ellipsoid = None;
                return;
            }
            if self.config.stereo_evidence && !obj.moving {
                // a size no object of its class has is no evidence of a static object either
                // and a collapsed fit (a semi-axis under 0.1 m: no person, rider or vehicle is that thin)
                let agrees = if result.odd_size || e.semi_axes.min() < 0.1 {
                    Err(format!("a size unlike its class ({:.2?})", e.semi_axes.as_slice()))
                } else {
                    stereo_agrees(obj, &e, self.config.dynamic_motion_sigmas)
                };
                if let Err(why) = agrees {
                    tracing::debug!(object = %id, "ellipsoid not accepted: {why}");
                    obj.ellipsoid = None;
                    return;
                }
            }
            obj.ellipsoid = Some(e);
            // with stereo points, the points' motion is the dynamic cue and their agreement with the
            // ellipsoid (above) the gate; box misfit and odd size (boxes cut by the border, parts)
            // decide only until the motion test has centroids enough to judge
            let centroids = obj.observations.iter().filter(|o| o.centroid.is_some()).count();
            obj.dynamic =
                obj.moving || (result.dynamic && (!self.config.stereo_evidence || centroids < MIN_MOTION_CENTROIDS));
        }
        self.merge_duplicates(id);
    }

    pub(super) fn job_for(&mut self, id: TrackId) -> Option<FitJob> {
        let cfg = self.config;
        let obj = self.objects.get_mut(&id)?;
        if obj.moving {
            return None;
        }
        let usable: Vec<&Observation> =
            obj.observations.iter().filter(|o| !o.bbox.touches_border(&cfg.image, cfg.border_margin_px)).collect();
        let due = match obj.ellipsoid {
            None => usable.len() >= cfg.min_views,
            Some(_) => usable.len() >= obj.fitted_at + cfg.refit_every,
        };
        if !due || usable.len() < cfg.min_views {
            return None;
        }
        let (first, last) = (usable[0], usable[usable.len() - 1]);
        let ray = |o: &Observation| {
            let [u, v] = o.bbox.centre();
            o.camera.ray_direction(u, v)
        };
        let parallax = ray(first).angle(&ray(last)).to_degrees();
        // without parallax (a standing camera) only the class prior fixes the depth: wait for more views
        let enough_without = cfg.min_views_without_parallax.is_some_and(|n| usable.len() >= n);
        if parallax < cfg.min_parallax_deg && obj.ellipsoid.is_none() && !enough_without {
            return None;
        }
        let n = usable.len();
        let pick: Vec<usize> = if n <= cfg.max_views {
            (0..n).collect()
        } else {
            (0..cfg.max_views).map(|i| i * (n - 1) / (cfg.max_views - 1)).collect()
        };
        let views: Vec<BoxView> = pick.iter().map(|&i| BoxView::new(usable[i].camera, usable[i].bbox)).collect();
        let references = pick.iter().map(|&i| usable[i].reference).collect();
        let surfaces = pick.iter().map(|&i| obj.surface.get(&usable[i].frame).cloned().unwrap_or_default()).collect();
        obj.fitted_at = n;
        self.fits += 1;
        Some(FitJob {
            id,
            class: obj.class,
            views,
            references,
            points: obj.points.iter().copied().collect(),
            positions: Vec::new(),
            surfaces,
            generation: obj.generation,
            method: self.method.clone(),
            box_shape: cfg.box_shape,
            point_yaw: cfg.point_yaw,
            surface: if cfg.surface_depth && obj.ellipsoid.is_some() { surface_cue(obj) } else { None },
            image: cfg.image,
            dynamic_rms_px: cfg.dynamic_rms_px,
            dynamic_prior_sigmas: cfg.dynamic_prior_sigmas,
            max_depth_m: cfg.max_depth_m,
            optimizer: self.optimizer.clone(),
        })
    }
}
