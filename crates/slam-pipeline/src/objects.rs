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

use std::{collections::BTreeMap, path::Path, sync::Arc};

use crate::report::median;
use nalgebra::{Vector3, Vector4};
use serde::Serialize;
use slam_assoc::{ObjectTracker, TrackerConfig, TrackerInput};
use slam_core::{geometry::BBox, Associator, ClassId, Detection, FramePoint, KeyframeId, PointId, PointPair, TrackId};
use slam_optim::{
    object::{box_residual, refine_with_cues, BoxShape, Cues, ObjectPrior, RefineConfig, SurfaceCue, YawCue},
    SharedOptimizer,
};
use slam_quadric::{
    init::{BoxView, Conic, Dqp, Initializer, QSlamSvd, Tri},
    project, Camera, Ellipsoid, ImageSize,
};

/// How an object's ellipsoid is computed from its views: an initialiser (any
/// [`slam_quadric::Initializer`]), optionally followed by the object optimisation
/// ([`slam_optim::object::refine_with_cues`]: the initialiser's ellipsoid is one of its starts, texture
/// planes and the class prior enter there). Cheap to clone (the initialiser is shared).
#[derive(Clone)]
pub struct FitMethod {
    initializer: Arc<dyn Initializer>,
    refine: bool,
    name: String,
}

impl std::fmt::Debug for FitMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FitMethod").field("name", &self.name).field("refine", &self.refine).finish()
    }
}

impl PartialEq for FitMethod {
    /// Same name and stages (an initialiser's settings are part of its name for the built-in methods).
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name && self.refine == other.refine
    }
}

impl Default for FitMethod {
    /// The paper's method: DQP (Tri+Yaw) then the object optimisation.
    fn default() -> Self {
        Self::refined(Arc::new(Dqp::default()), "Tri+Yaw+refine")
    }
}

impl FitMethod {
    /// The names [`FitMethod::by_name`] accepts, in the order of the comparison tables.
    pub const NAMES: [&'static str; 5] = ["Tri+Yaw+refine", "Q-SLAM", "Conic", "Tri", "Tri+Yaw"];

    /// The initialiser's ellipsoid as it is.
    pub fn initial(initializer: Arc<dyn Initializer>, name: impl Into<String>) -> Self {
        Self { initializer, refine: false, name: name.into() }
    }

    /// The initialiser's ellipsoid refined by the object optimisation.
    pub fn refined(initializer: Arc<dyn Initializer>, name: impl Into<String>) -> Self {
        Self { initializer, refine: true, name: name.into() }
    }

    /// A built-in method by its table name ([`FitMethod::NAMES`]).
    pub fn by_name(name: &str) -> Option<Self> {
        match name {
            "Tri+Yaw+refine" => Some(Self::default()),
            "Q-SLAM" => Some(Self::qslam()),
            "Conic" => Some(Self::conic()),
            "Tri" => Some(Self::tri()),
            "Tri+Yaw" => Some(Self::tri_yaw()),
            _ => None,
        }
    }

    /// "Q-SLAM": QuadricSLAM's SVD (baseline).
    pub fn qslam() -> Self {
        Self::initial(Arc::new(QSlamSvd), "Q-SLAM")
    }

    /// "Conic": Rubino et al.'s conic method (baseline).
    pub fn conic() -> Self {
        Self::initial(Arc::new(Conic::default()), "Conic")
    }

    /// "Tri": triangulated centre and a full 3×3 block (baseline).
    pub fn tri() -> Self {
        Self::initial(Arc::new(Tri::default()), "Tri")
    }

    /// "Tri+Yaw": the paper's DQP as printed, without the object optimisation (baseline).
    pub fn tri_yaw() -> Self {
        Self::initial(Arc::new(Dqp::default()), "Tri+Yaw")
    }

    /// Short name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether the object optimisation follows the initialiser.
    pub fn refines(&self) -> bool {
        self.refine
    }

    /// The initialiser.
    pub fn initializer(&self) -> &dyn Initializer {
        &*self.initializer
    }
}

/// Settings of the [`ObjectMapper`] (the `[objects]` table of `slam-app run --config`; `image` and
/// `tracker` are set by the caller, not by the file; the fitting method is given to the mapper
/// ([`ObjectMapper::with_method`])).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize, documented::DocumentedFieldsOpt)]
#[serde(default, deny_unknown_fields)]
pub struct MapperConfig {
    /// What a box bounds in the object optimisation: "ellipse" (the ellipsoid's projected ellipse, the
    /// paper's model, default), "cuboid" (its circumscribed cuboid) or "two-stage" (yaw from the cuboid
    /// model, then the ellipse model with that yaw held); docs/objects.md.
    #[serde(with = "crate::settings::box_shape")]
    pub box_shape: BoxShape,
    /// Image size (for clipped bounds and the border test).
    #[serde(skip)]
    pub image: ImageSize,
    /// Fewest border-free boxes before an ellipsoid is fitted. Default 3.
    pub min_views: usize,
    /// Smallest angle between the first and the latest ray through the box centres, degrees. Default 3.
    pub min_parallax_deg: f64,
    /// With less parallax than `min_parallax_deg`, an object is still fitted (its depth then comes from
    /// the class's size prior) once it has this many border-free boxes. Default `None` (the paper's
    /// rule: no fit without parallax; 0 in a settings file); docs/objects.md has what `Some(10)` does on
    /// KITTI.
    #[serde(with = "crate::settings::zero_is_off_usize")]
    pub min_views_without_parallax: Option<usize>,
    /// Boxes within this many pixels of the border are not used for fitting (the paper's rule). Default 5.
    pub border_margin_px: f64,
    /// Refit after this many new boxes. Default 5.
    pub refit_every: usize,
    /// Most views used in one fit (evenly spaced over the track). Default 20.
    pub max_views: usize,
    /// RMS box misfit above which a fitted object is flagged dynamic, pixels. Default 12, for
    /// label-quality boxes (the image-free mode); the running system, fed by a detector, uses 25
    /// (`system::DETECTOR_DYNAMIC_RMS_PX`, measured in docs/system.md).
    pub dynamic_rms_px: f64,
    /// A fitted object (DQP + optimisation) whose semi-axes lie farther than this from its class prior,
    /// in prior standard deviations (Mahalanobis), is flagged dynamic: fitted as static, a moving object
    /// needs a size its class does not have. `None` (0 in a settings file) turns the test off. Default 6
    /// (docs/objects.md).
    #[serde(with = "crate::settings::zero_is_off")]
    pub dynamic_prior_sigmas: Option<f64>,
    /// Standard deviations beyond which the stereo cues call an object moving or misplaced: the robust
    /// trend of its stereo-point centroids (one per measured frame, the last 30) moving farther than
    /// this (Mahalanobis along and across the viewing ray; σ from the depth noise at both ends and the
    /// spread of the visible surface over the object, [`ObjectMapper::add_points`]) on two frames
    /// running; a scene-flow reading and its confirmation ([`ObjectMapper::add_flow`]); the flow that
    /// refutes a trend; and the stereo-evidence gate (`stereo_evidence`). Default 3.
    pub dynamic_motion_sigmas: f64,
    /// A fitted ellipsoid farther than this from the camera of its latest view is discarded (beyond
    /// the stereo range, boxes alone do not fix the depth), metres. Default 80.
    pub max_depth_m: f64,
    /// Static objects of one class group closer than this are merged, metres. Default 2.5 (cars parked
    /// bumper to bumper stand about 4.5 m apart).
    pub merge_distance_m: f64,
    /// A mapped ellipsoid that should have been detected (in front within `visible_depth_m`, its
    /// projected box inside the image, not overlapped by another box, in a frame with detections) and
    /// was not in this many frames in a row is removed (refitted when boxes come again). Default 5: a
    /// detector that finds a visible car 3 times in 4 misses it 5 times running about once in a
    /// thousand. `None`: off.
    #[serde(with = "crate::settings::zero_is_off_usize")]
    pub max_misses: Option<usize>,
    /// Depth within which a mapped object is expected to be detected, metres. Default 40 (a car's box
    /// is then at least 27 px tall at KITTI's focal length).
    pub visible_depth_m: f64,
    /// A mapped static ellipsoid in full view (as for `max_misses`) through which the frame's stereo
    /// points see free space in this many tracked frames in a row is removed (refitted when more boxes
    /// come): most of the rays through the central part of its projection end beyond its far side by
    /// more than their depth noise (3 σ) and the object's own size ([`ObjectMapper::check_free_space`]).
    /// Default 5, as `max_misses`: half a second of KITTI. `None` (0 in a settings file): off. No effect
    /// without stereo points (the image-free mode).
    #[serde(with = "crate::settings::zero_is_off_usize")]
    pub free_space_frames: Option<usize>,
    /// An ellipsoid is accepted only where the object's stereo points put it: it must lie within
    /// `dynamic_motion_sigmas` σ (depth noise and surface spread, as in the motion test) of the median
    /// of the object's centroids (one per measured frame), and an object without any is not mapped.
    /// Off in the library's default (the image-free mode has no points); on in the running system's
    /// (`system::SystemConfig::default`).
    pub stereo_evidence: bool,
    /// Use the stereo-point yaw cue in fits that have map points (the running system): the principal
    /// horizontal direction of the object's points as a soft prior on its length axis, when confident
    /// ([`crate::yaw_cue`]). Default false: on the drives measured it fires for no parked car it could
    /// help (docs/objects.md); no effect without points (the image-free mode).
    pub point_yaw: bool,
    /// Refit a mapped object to the stereo depth of its visible surface too
    /// ([`slam_optim::factors::SurfaceDepth`]): the median of its centroids, once it has at least 4 (as
    /// the motion test), should lie one chord half-length in front of the centre along the line of
    /// sight ([`surface_cue`]). Only refits of an object whose box-only fit was accepted use it, so the
    /// stereo evidence gate still judges boxes against points. Default false: on drive 0005 it did not
    /// bring the parked van nearer its labelled centre and cost its match (docs/objects.md, "Stereo
    /// depth in the fit"); no effect without points (the image-free mode).
    pub surface_depth: bool,
    /// Tracker settings.
    #[serde(skip)]
    pub tracker: TrackerConfig,
}

impl Default for MapperConfig {
    fn default() -> Self {
        Self {
            box_shape: BoxShape::Ellipse,
            image: ImageSize::new(1242.0, 375.0),
            min_views: 3,
            min_parallax_deg: 3.0,
            min_views_without_parallax: None,
            border_margin_px: 5.0,
            refit_every: 5,
            max_views: 20,
            dynamic_rms_px: 12.0,
            dynamic_prior_sigmas: Some(6.0),
            dynamic_motion_sigmas: 3.0,
            max_depth_m: 80.0,
            merge_distance_m: 2.5,
            max_misses: Some(5),
            visible_depth_m: 40.0,
            free_space_frames: Some(5),
            stereo_evidence: false,
            point_yaw: false,
            surface_depth: false,
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

/// Physical extents (full lengths in metres, not semi-axes) a real object of a class can have: the
/// smallest extent at least `min`, the largest at most `max_length`, the middle one (height or width,
/// whichever is larger) at most `max_middle`. Any ellipsoid outside them is a wrong fit, whatever its
/// stereo points say.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicalLimits {
    /// Smallest extent at least this.
    pub min: f64,
    /// Largest extent at most this.
    pub max_length: f64,
    /// Middle extent at most this.
    pub max_middle: f64,
}

/// The limits of a class's real objects (see [`PhysicalLimits`]); sources:
/// - buses and trucks: EU Directive 96/53/EC (as amended) and US 23 CFR 658 cap the width at
///   2.55-2.60 m and the length at 18.75 m (road train, articulated bus); heights reach 4.0-4.3 m
///   (most EU states; 13 ft 6 in - 14 ft in the US). Length limit 20 m and middle extent (height) 4.5 m
///   leave room for fit error. The narrowest vehicles a detector calls a truck are pickups (~1.8 m
///   wide, ~1.7 m tall): no extent under half of that, 0.9 m.
/// - cars (the detector's "car" also covers vans and SUVs): the longest production vans and pickups are
///   about 7.4 m (long-wheelbase panel vans), the tallest about 3 m (high-roof vans); the narrowest
///   and lowest road cars about 1.2 m wide (quadricycles) and 1.0 m tall (sports cars). Limits 8 m,
///   3.5 m and half the lowest car, 0.5 m.
/// - people: no one is taller than 2.5 m, and a walking person with arms and bags spans less than
///   2 m across; at least 0.1 m (the thinnest a fitted ellipsoid may be and still be a body).
/// - bicycles and motorcycles with riders: at most 3.2 m long (touring motorcycles 2.6 m, tandems
///   2.5 m, plus fit error), 2.2 m tall; at least 0.1 m (a bicycle seen end-on is thin).
///
/// A fit misses an object's true extents by its fitting error (semi-axes 0.75 m off on average for the
/// parked van of drive 0005, 0.33 m image-free, where real cars are fitted as thin as 0.65 m); the
/// limits lie beyond what real objects reach (a minimum at half the smallest real extent), so that a
/// real object fitted that badly is still kept (the class prior and the stereo gate deal with it).
pub fn physical_limits(class: ClassId) -> PhysicalLimits {
    let (min, max_length, max_middle) = match class.0 {
        0 => (0.1, 2.5, 2.0),      // person
        1 | 3 => (0.1, 3.2, 2.2),  // bicycle, motorcycle
        5..=7 => (0.9, 20.0, 4.5), // bus, train, truck
        _ => (0.5, 8.0, 3.5),      // car and others
    };
    PhysicalLimits { min, max_length, max_middle }
}

/// Whether an ellipsoid with `semi_axes` could be a real object of `class` ([`physical_limits`]);
/// `Err` says which extent is impossible.
// `!(x <= limit)` on purpose: a NaN extent fails every test
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn physically_plausible(class: ClassId, semi_axes: &Vector3<f64>) -> Result<(), String> {
    let l = physical_limits(class);
    let mut e = [2.0 * semi_axes.x, 2.0 * semi_axes.y, 2.0 * semi_axes.z];
    e.sort_by(f64::total_cmp);
    let [small, middle, large] = e;
    let name = class.name();
    if !(small >= l.min) {
        return Err(format!("{small:.2} m across: no {name} is thinner than {} m", l.min));
    }
    if !(large <= l.max_length) {
        return Err(format!("{large:.2} m long: no {name} is longer than {} m", l.max_length));
    }
    if !(middle <= l.max_middle) {
        return Err(format!("{middle:.2} m wide or tall: no {name} exceeds {} m", l.max_middle));
    }
    Ok(())
}

/// Classes a detector confuses with each other on one object are merged as one group: vehicles (car,
/// bus, truck), two-wheelers (bicycle, motorcycle); others stand alone.
fn class_group(c: ClassId) -> u16 {
    match c.0 {
        2 | 5 | 7 => 2,
        1 | 3 => 1,
        other => other,
    }
}

/// IoU above which two boxes of one class group are one object (the detector's own class-wise NMS
/// threshold).
const DUPLICATE_IOU: f64 = 0.45;
/// Share of a box's area inside a larger box of its class group above which it is a part of that
/// object (a tile's cut of a car, its front or its wheels boxed again).
const NESTED_SHARE: f64 = 0.8;

/// One box per object: boxes of one class group (car / bus / truck; bicycle / motorcycle) that overlap
/// a larger kept box by IoU above 0.45 (the same object boxed twice: across tiles, or as two classes)
/// or lie inside it by 80 % of their area (a part of it) are dropped. Larger boxes are kept first (the
/// whole object, not its part); ties by score, then by position, so the result is deterministic.
/// Returns the kept boxes in their input order and how many were dropped.
pub fn suppress_duplicate_boxes(detections: Vec<Detection>) -> (Vec<Detection>, usize) {
    let mut order: Vec<usize> = (0..detections.len()).collect();
    let key = |d: &Detection| (d.bbox.area(), d.score, d.bbox.xmin, d.bbox.ymin);
    order.sort_by(|&a, &b| {
        let (ka, kb) = (key(&detections[a]), key(&detections[b]));
        kb.0.total_cmp(&ka.0).then(kb.1.total_cmp(&ka.1)).then(ka.2.total_cmp(&kb.2)).then(ka.3.total_cmp(&kb.3))
    });
    let mut keep = vec![false; detections.len()];
    let mut kept: Vec<usize> = Vec::new();
    for i in order {
        let d = &detections[i];
        let duplicate = kept.iter().any(|&j| {
            let o = &detections[j];
            class_group(o.class) == class_group(d.class)
                && (o.bbox.iou(&d.bbox) > DUPLICATE_IOU
                    || o.bbox.intersection(&d.bbox).is_some_and(|x| x.area() >= NESTED_SHARE * d.bbox.area()))
        });
        if !duplicate {
            keep[i] = true;
            kept.push(i);
        }
    }
    let dropped = keep.iter().filter(|k| !**k).count();
    (detections.into_iter().zip(keep).filter_map(|(d, k)| k.then_some(d)).collect(), dropped)
}

/// Where an object's stereo points put it in one frame (its box's depth cluster of that frame's stereo
/// points, or of a keyframe's): the median world position of its points and the standard deviation of
/// that position along the viewing ray from stereo depth noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointsCentroid {
    /// Median world position, metres.
    pub position: Vector3<f64>,
    /// `σ_z = z² σ_d / (f b)` at the points' median depth, metres.
    pub depth_sigma: f64,
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
    /// Median world position of the stereo points on the object in that frame (full pipeline, measured
    /// frames; `None` image-free or with too few points).
    pub centroid: Option<Vector3<f64>>,
    /// Standard deviation of that centroid along its viewing ray from stereo depth noise, metres (0
    /// without a centroid).
    pub depth_sigma: f64,
    /// The frame's reference keyframe and its pose in it (full pipeline): lets the fit use the
    /// keyframe's refined pose.
    pub reference: Option<(KeyframeId, nalgebra::Isometry3<f64>)>,
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
    /// Flagged dynamic: moving, or (until the motion test has centroids enough) a box misfit or a size
    /// unlike its class.
    pub dynamic: bool,
    /// Its stereo points moved (scene flow or centroid trend): not fitted while set. A flag set by the
    /// trend alone is lifted when the object's own scene flow refutes it ([`ObjectMapper::add_flow`]).
    pub moving: bool,
    /// Map points on the object (full pipeline), for texture planes.
    pub points: std::collections::BTreeSet<PointId>,
    fitted_at: usize,
    /// Consecutive measured frames whose centroid trend failed the motion test.
    motion_strikes: usize,
    /// Its scene-flow readings ([`ObjectMapper::add_flow`]): frame id, frame ids since the frame the
    /// flow started in, the reading.
    flows: Vec<(usize, usize, SceneFlow)>,
    /// Consecutive detector frames in which its ellipsoid should have been seen and was not.
    misses: usize,
    /// Consecutive tracked frames whose stereo points see free space through its ellipsoid.
    free_frames: usize,
    /// Set when the centroid trend flagged it moving: what the trend read, so that its own scene flow
    /// can refute it afterwards ([`ObjectMapper::add_flow`]).
    trend_flag: Option<TrendFlag>,
    /// How many times its observations were dropped (a refuted trend flag): a fit job made before
    /// that, answered after, is discarded.
    generation: u32,
}

/// What flagged an object moving by its centroid trend: the frame, the trend's rate (world motion per
/// frame id) and that rate's σ along and across `ray`, and whether the object was flagged dynamic
/// before.
#[derive(Debug, Clone, Copy)]
struct TrendFlag {
    frame: usize,
    rate: Vector3<f64>,
    rate_sigma: (f64, f64),
    ray: Vector3<f64>,
    was_dynamic: bool,
}

impl MappedObject {
    /// A new object of the map: no observation, no ellipsoid, not flagged.
    fn new(id: TrackId, class: ClassId) -> Self {
        Self {
            id,
            class,
            observations: Vec::new(),
            ellipsoid: None,
            dynamic: false,
            moving: false,
            points: Default::default(),
            fitted_at: 0,
            motion_strikes: 0,
            flows: Vec::new(),
            misses: 0,
            free_frames: 0,
            trend_flag: None,
            generation: 0,
        }
    }
}

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

    /// Whether [`FitJob::run`] uses texture planes (only a method that refines does).
    pub fn uses_planes(&self) -> bool {
        self.method.refines()
    }

    /// Run the fit: the method's initialiser, then, when the method refines, the object optimisation;
    /// `planes` are texture planes of the object's points (used by the optimisation).
    pub fn run(&self, planes: &[Vector4<f64>]) -> FitResult {
        self.run_with_cue(planes, None)
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
            let cues = Cues { planes, yaw, surface: self.surface };
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

/// The object mapper.
pub struct ObjectMapper {
    tracker: ObjectTracker,
    config: MapperConfig,
    objects: BTreeMap<TrackId, MappedObject>,
    /// Tracks found to duplicate another object; their detections are ignored.
    merged: BTreeMap<TrackId, TrackId>,
    fits: usize,
    implausible: usize,
    free_space_removed: usize,
    optimizer: SharedOptimizer,
    method: FitMethod,
}

impl ObjectMapper {
    /// A mapper around an associator; object fits use `optimizer`.
    pub fn new(associator: Box<dyn Associator>, config: MapperConfig, optimizer: SharedOptimizer) -> Self {
        Self {
            tracker: ObjectTracker::new(associator, config.tracker),
            config,
            objects: BTreeMap::new(),
            merged: BTreeMap::new(),
            fits: 0,
            implausible: 0,
            free_space_removed: 0,
            optimizer,
            method: FitMethod::default(),
        }
    }

    /// Use `method` for the ellipsoid fits (default: [`FitMethod::default`], Tri+Yaw+refine).
    pub fn with_method(mut self, method: FitMethod) -> Self {
        self.method = method;
        self
    }

    /// The fitting method.
    pub fn method(&self) -> &FitMethod {
        &self.method
    }

    /// All objects, by id.
    pub fn objects(&self) -> impl Iterator<Item = &MappedObject> {
        self.objects.values()
    }

    /// One object.
    pub fn object(&self, id: TrackId) -> Option<&MappedObject> {
        self.objects.get(&id)
    }

    /// Number of ellipsoid fits run so far.
    pub fn fits(&self) -> usize {
        self.fits
    }

    /// Fitted ellipsoids refused because no real object of the class has their size
    /// ([`physically_plausible`]).
    pub fn implausible_fits(&self) -> usize {
        self.implausible
    }

    /// Ellipsoids removed because the stereo points saw free space through them
    /// ([`ObjectMapper::check_free_space`]).
    pub fn free_space_removals(&self) -> usize {
        self.free_space_removed
    }

    /// Process one frame and fit the touched objects that are due, on this thread (image-free mode);
    /// returns each detection's object.
    pub fn step(&mut self, frame: usize, camera: &Camera, detections: &[Detection]) -> Vec<Option<TrackId>> {
        let tracks = self.associate(frame, camera, None, detections, &[]);
        let mut touched: Vec<TrackId> = tracks.iter().flatten().copied().collect();
        touched.sort();
        touched.dedup();
        for id in touched {
            if let Some(job) = self.job_for(id) {
                let result = job.run(&[]);
                self.apply(result);
            }
        }
        tracks
    }

    /// Associate one frame's detections with the objects (ODA with the projected ellipsoids and, when
    /// given, keypoints tracked from the previous frame by optical flow) and record the observations;
    /// returns each detection's object. No fitting: see [`ObjectMapper::fit_jobs`].
    pub fn associate(
        &mut self,
        frame: usize,
        camera: &Camera,
        reference: Option<(KeyframeId, nalgebra::Isometry3<f64>)>,
        detections: &[Detection],
        flow: &[PointPair],
    ) -> Vec<Option<TrackId>> {
        let projected: BTreeMap<TrackId, BBox> = self
            .objects
            .values()
            .filter_map(|o| {
                let e = o.ellipsoid.as_ref()?;
                let b = project(e, camera).and_then(|c| c.clipped_bounds(&self.config.image)).ok()?;
                Some((o.id, b))
            })
            .collect();
        let out = self.tracker.step(&TrackerInput { detections, projected: &projected, flow, keyframe: true });
        self.count_misses(camera, &projected, detections, &out.tracks);
        for (k, (t, d)) in out.tracks.iter().zip(detections).enumerate() {
            let Some(id) = *t else { continue };
            if self.merged.contains_key(&id) {
                continue;
            }
            let obj = self.objects.entry(id).or_insert_with(|| MappedObject::new(id, d.class));
            obj.observations.push(Observation {
                frame,
                camera: *camera,
                bbox: d.bbox,
                detection: k,
                centroid: None,
                depth_sigma: 0.0,
                reference,
            });
        }
        out.tracks
    }

    /// Count, for every mapped static object, the frames in which it should have been detected and was
    /// not; remove its ellipsoid after `max_misses` in a row (see [`MapperConfig::max_misses`]).
    fn count_misses(
        &mut self,
        camera: &Camera,
        projected: &BTreeMap<TrackId, BBox>,
        detections: &[Detection],
        tracks: &[Option<TrackId>],
    ) {
        let cfg = self.config;
        let Some(limit) = cfg.max_misses else { return };
        // a frame without boxes may be one the detector skipped
        if detections.is_empty() {
            return;
        }
        let seen: std::collections::BTreeSet<TrackId> =
            tracks.iter().flatten().map(|t| self.merged.get(t).copied().unwrap_or(*t)).collect();
        let from_world = camera.world_from_camera.inverse();
        let usable_of = |o: &MappedObject| {
            o.observations.iter().filter(|x| !x.bbox.touches_border(&cfg.image, cfg.border_margin_px)).count()
        };
        for o in self.objects.values_mut() {
            let (Some(e), Some(b)) = (o.ellipsoid, projected.get(&o.id)) else { continue };
            if o.dynamic || seen.contains(&o.id) {
                o.misses = 0;
                continue;
            }
            let depth = (from_world * nalgebra::Point3::from(e.centre())).z;
            let in_view =
                depth > 0.0 && depth < cfg.visible_depth_m && !b.touches_border(&cfg.image, cfg.border_margin_px);
            let covered = detections.iter().any(|d| d.bbox.intersection(b).is_some_and(|x| x.area() >= 0.3 * b.area()));
            if !in_view || covered {
                continue;
            }
            o.misses += 1;
            if o.misses >= limit {
                tracing::debug!(object = %o.id, misses = o.misses, "visible but not detected: ellipsoid removed");
                o.ellipsoid = None;
                o.misses = 0;
                o.fitted_at = usable_of(o);
            }
        }
    }

    /// The free-space test ([`MapperConfig::free_space_frames`]) on one tracked frame: for every mapped
    /// static ellipsoid in full view within `visible_depth_m`, the frame's stereo points inside the
    /// central part of its projected box vote ([`free_space_votes`]); when at least
    /// [`MIN_FREE_SPACE_RAYS`] do and most of them see through it, the frame counts against it, and
    /// after `free_space_frames` such frames in a row its ellipsoid is removed (refitted when more
    /// boxes come; counted, [`ObjectMapper::free_space_removals`]). A frame with too few votes, or the
    /// object out of view, leaves the count as it is.
    pub fn check_free_space(&mut self, camera: &Camera, points: &[FramePoint], noise: &StereoNoise) {
        let cfg = self.config;
        let Some(limit) = cfg.free_space_frames else { return };
        if points.is_empty() {
            return;
        }
        let from_world = camera.world_from_camera.inverse();
        for o in self.objects.values_mut() {
            let Some(e) = o.ellipsoid else { continue };
            if o.dynamic || o.moving {
                continue;
            }
            let depth = (from_world * nalgebra::Point3::from(e.centre())).z;
            let Ok(b) = project(&e, camera).and_then(|c| c.clipped_bounds(&cfg.image)) else { continue };
            if depth <= 0.0 || depth >= cfg.visible_depth_m || b.touches_border(&cfg.image, cfg.border_margin_px) {
                continue;
            }
            // the fit may be off by about the object's own size: a point within that of its far side
            // may still lie on it
            let margin = class_prior(o.class).axes.x;
            let (through, on) = free_space_votes(&e, camera, &b, points, noise, margin);
            tracing::trace!(object = %o.id, through, on, depth, "free-space votes");
            if through + on < MIN_FREE_SPACE_RAYS {
                continue;
            }
            if through <= on {
                o.free_frames = 0;
                continue;
            }
            o.free_frames += 1;
            if o.free_frames >= limit {
                tracing::info!(
                    "object {} ({}): stereo sees free space where its ellipsoid stands ({through} of {} rays through it, {} frames in a row): removed",
                    o.id.0,
                    o.class.name(),
                    through + on,
                    o.free_frames
                );
                o.ellipsoid = None;
                o.free_frames = 0;
                o.fitted_at =
                    o.observations.iter().filter(|x| !x.bbox.touches_border(&cfg.image, cfg.border_margin_px)).count();
                self.free_space_removed += 1;
            }
        }
    }

    /// Attach map points seen inside the object's latest box and where they put the object (callers pass
    /// `None` when too few points support it); flags the object as moving when its stereo points have
    /// carried it away from where they first put it.
    ///
    /// The displacement `d` is the robust trend of the object's centroids ([`trend`]: a repeated-median
    /// slope over the latest centroids times the frames they span), read once the object has
    /// [`MIN_MOTION_CENTROIDS`]. A trend, not the distance of the latest centroid from the median of
    /// the earlier ones: that median trails a steady motion by half the track, and one centroid on the
    /// wrong surface moves neither the trend nor the test.
    ///
    /// `d` is split along the latest viewing ray and across it. Along the ray its σ combines the stereo
    /// depth noise (`σ_z = z² σ_d / (f b)`, the median over the first and over the latest
    /// [`MOTION_WINDOW`] of the centroids the trend reads) with the wander of the
    /// visible surface over the object (`s = a / √3`, the σ of a point uniform over the class's
    /// half-length `a`: which side of a car is seen changes with the view); across the ray, `s` and the
    /// first views' depth noise (the ray turns as the camera passes). A static object stays within a
    /// few σ whatever its depth, since its visible surface cannot leave the object; a car driving ahead
    /// at the camera's speed keeps its depth, so its points move with the camera and leave them. The
    /// object is flagged after two failing tests in a row.
    pub fn add_points(&mut self, id: TrackId, points: &[PointId], centroid: Option<PointsCentroid>) {
        let cfg = self.config;
        let Some(obj) = self.objects.get_mut(&id) else { return };
        obj.points.extend(points.iter().copied());
        let class = obj.class;
        let Some(last) = obj.observations.last_mut() else { return };
        last.centroid = centroid.map(|c| c.position);
        last.depth_sigma = centroid.map_or(0.0, |c| c.depth_sigma);
        tracing::trace!(object = %id, frame = last.frame, bbox = ?last.bbox, ?centroid, points = points.len(), "object points");
        let camera = last.camera.world_from_camera.translation.vector;
        if centroid.is_none() {
            return;
        }
        let all: Vec<(usize, Vector3<f64>, f64)> =
            obj.observations.iter().filter_map(|o| o.centroid.map(|c| (o.frame, c, o.depth_sigma))).collect();
        if all.len() < MIN_MOTION_CENTROIDS {
            return;
        }
        // the trend's own span: the depth noise at both ends of the centroids it reads
        let read = &all[all.len().saturating_sub(TREND_CENTROIDS)..];
        let k = MOTION_WINDOW.min(read.len() / 2);
        let (first, now) = (median_sigma(&read[..k]), median_sigma(&read[read.len() - k..]));
        let d = trend(read);
        let Some(ray) = (all[all.len() - 1].1 - camera).try_normalize(1e-9) else {
            return;
        };
        let split = RaySplit::of(&d, &ray);
        let s = class_prior(class).axes.x / 3f64.sqrt();
        let sigma_along = (now.powi(2) + first.powi(2) + s * s).sqrt();
        let sigma_across = (first.powi(2) + s * s).sqrt();
        let m = split.sigmas((sigma_along, sigma_across));
        let (from, to) = (read[0].0, read[read.len() - 1].0);
        // the trend's rate (motion per frame id) and its σ along and across the ray
        let span = (to - from).max(1) as f64;
        let trend_rate = (d / span, (sigma_along / span, sigma_across / span));
        let vetoed = m > cfg.dynamic_motion_sigmas
            && flow_refutes(&obj.flows, (from, to), trend_rate, &ray, cfg.dynamic_motion_sigmas);
        if vetoed {
            tracing::debug!(object = %id, sigmas = m, "centroid trend refuted by the points' own scene flow");
        }
        obj.motion_strikes = if m > cfg.dynamic_motion_sigmas && !vetoed { obj.motion_strikes + 1 } else { 0 };
        if obj.motion_strikes >= 2 && !obj.moving {
            tracing::info!(
                "object {} ({}) moved {:.1} m from frame {from} to {to} ({:.1} m along the viewing ray, {:.1} m across; {m:.1} σ of the stereo noise): moving, not mapped",
                id.0,
                obj.class.name(),
                d.norm(),
                split.along,
                split.across
            );
            obj.trend_flag = Some(TrendFlag {
                frame: to,
                rate: trend_rate.0,
                rate_sigma: trend_rate.1,
                ray,
                was_dynamic: obj.dynamic,
            });
            obj.moving = true;
            obj.dynamic = true;
        }
    }

    /// The scene flow of the object's points between the frame before and this one (`frame` and `gap`:
    /// this frame's id and the ids since the frame before, [`scene_flow`]): two readings of consecutive
    /// frames that each stand more than `dynamic_motion_sigmas` σ above their noise, and whose sum (the
    /// motion over both frames) does too, flag the object as moving. The first reading is the object's
    /// own, or else `same_box`: that of the box its box overlaps in the frame before (the caller's
    /// IoU ≥ 0.5), the same physical object under another track (the association
    /// starts a new track when the detector calls a van a car, then a truck). The sum is what a single
    /// bad pose cannot fake: an error of frame k moves every point by +δ in the reading that ends at k
    /// and by −δ in the next, which cancel. The same points seen in two consecutive frames barely change
    /// view, so their 3-D motion is measured to their depth noise alone (with twenty points, about 0.4 m
    /// per frame at 15 m, 0.16 m at 6 m is 3 σ): traffic moving against the camera is found within a few
    /// frames, where the centroid test ([`ObjectMapper::add_points`]), which must allow for the visible
    /// surface wandering over the object as the view turns, needs it to move by about its own size. An
    /// object already mapped as static is left to the centroid test: two frames of motion under a track
    /// its boxes and points have agreed with for many views are likelier another object taken over by
    /// the association than a parked car pulling out.
    pub fn add_flow(
        &mut self,
        id: TrackId,
        (frame, gap): (usize, usize),
        flow: &SceneFlow,
        same_box: Option<&SceneFlow>,
    ) {
        let cfg = self.config;
        let Some(obj) = self.objects.get_mut(&id) else { return };
        // the reading of the frame before: its own, else that of the box it overlaps there
        let own = obj.flows.last().filter(|(f, _, _)| f + gap == frame).map(|&(_, _, b)| b);
        let before = own.or(same_box.copied());
        obj.flows.push((frame, gap, *flow));
        if obj.moving {
            // flagged by its centroid trend (which mixes the objects an association switch put under
            // one track), refuted by its own points: still, and excluding the trend's rate, over the
            // last readings, all after the flag
            let Some(t) = obj.trend_flag else { return };
            let k = obj.flows.len();
            if k < MIN_REFUTING_READINGS {
                return;
            }
            let (first, first_gap, _) = obj.flows[k - MIN_REFUTING_READINGS];
            let from = first.saturating_sub(first_gap);
            if from >= t.frame
                && flow_refutes(&obj.flows, (from, frame), (t.rate, t.rate_sigma), &t.ray, cfg.dynamic_motion_sigmas)
            {
                tracing::info!(
                    "object {} ({}): flagged moving by its centroid trend at frame {}, its points have stood still since frame {from} (scene flow): static again, its observations before that dropped",
                    id.0,
                    obj.class.name(),
                    t.frame
                );
                obj.moving = false;
                obj.dynamic = t.was_dynamic;
                obj.trend_flag = None;
                obj.motion_strikes = 0;
                // what made the trend was another object under this track: its boxes, centroids and
                // map points before the still readings are dropped (the next keyframes give it points
                // again), and the object is fitted afresh from the rest, with fresh counters
                obj.observations.retain(|o| o.frame >= from);
                obj.points.clear();
                obj.ellipsoid = None;
                obj.fitted_at = 0;
                obj.misses = 0;
                obj.free_frames = 0;
                obj.generation += 1;
            }
            return;
        }
        if obj.ellipsoid.is_some() && !obj.dynamic {
            // mapped as static: its own boxes and points have agreed for views on end, so two frames
            // of motion are likelier another object under its track (an association switch) than a
            // parked car pulling out; the centroid test still watches it
            return;
        }
        let m = flow.sigmas();
        tracing::debug!(
            object = %id,
            points = flow.points,
            along = flow.split().along,
            across = flow.split().across,
            sigmas = m,
            "scene flow"
        );
        let limit = cfg.dynamic_motion_sigmas;
        let confirmed = before.is_some_and(|b| b.sigmas() > limit && SceneFlow::over_both(&b, flow).sigmas() > limit);
        if m > limit && confirmed && !obj.moving {
            tracing::info!(
                "object {} ({}): its {} points moved {:.2} m into frame {frame} ({:.2} m along the viewing ray, {:.2} m across; {m:.1} σ of the stereo noise): moving, not mapped",
                id.0,
                obj.class.name(),
                flow.points,
                flow.split().norm(),
                flow.split().along,
                flow.split().across
            );
            obj.moving = true;
            obj.dynamic = true;
        }
    }

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

    /// Objects of the same class group whose ellipsoid centres are closer than `merge_distance_m` are one
    /// object seen as two tracks (a detector that boxes a car twice, a track broken by a missed
    /// detection): the one with fewer observations is dropped and its later detections ignored.
    fn merge_duplicates(&mut self, id: TrackId) {
        let Some(c) = self.objects.get(&id).and_then(|o| o.ellipsoid.map(|e| (e.centre(), o.class))) else { return };
        let other = self.objects.values().find(|o| {
            o.id != id
                && class_group(o.class) == class_group(c.1)
                && !o.moving
                && o.ellipsoid.is_some_and(|e| (e.centre() - c.0).norm() < self.config.merge_distance_m)
        });
        let Some(other) = other.map(|o| o.id) else { return };
        let n = |k: &TrackId| self.objects.get(k).map_or(0, |o| o.observations.len());
        // keep the longer track (the older one on a tie)
        let (keep, drop) = if (n(&other), std::cmp::Reverse(other)) >= (n(&id), std::cmp::Reverse(id)) {
            (other, id)
        } else {
            (id, other)
        };
        if let Some(gone) = self.objects.remove(&drop) {
            tracing::debug!(kept = %keep, dropped = %drop, "duplicate object merged");
            if let Some(k) = self.objects.get_mut(&keep) {
                k.points.extend(gone.points);
            }
            self.merged.insert(drop, keep);
        }
    }

    /// Tracks merged into another object (dropped → kept).
    pub fn merged(&self) -> &BTreeMap<TrackId, TrackId> {
        &self.merged
    }

    fn job_for(&mut self, id: TrackId) -> Option<FitJob> {
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
        obj.fitted_at = n;
        self.fits += 1;
        Some(FitJob {
            id,
            class: obj.class,
            views,
            references,
            points: obj.points.iter().copied().collect(),
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

/// The object's observations that have a stereo centroid, in frame order.
fn with_centroids(obj: &MappedObject) -> Vec<&Observation> {
    obj.observations.iter().filter(|o| o.centroid.is_some()).collect()
}

/// Where the stereo points of `with` (observations with a centroid, at least one) put the object: the
/// per-axis median of their centroids, and the median of their depth σ.
fn median_centroid(with: &[&Observation]) -> (Vector3<f64>, f64) {
    let axis = |k: usize| median(&mut with.iter().filter_map(|o| o.centroid.map(|c| c[k])).collect::<Vec<_>>());
    (Vector3::new(axis(0), axis(1), axis(2)), median(&mut with.iter().map(|o| o.depth_sigma).collect::<Vec<_>>()))
}

/// Whether an ellipsoid lies where the object's stereo points put it (see
/// [`MapperConfig::stereo_evidence`]): Mahalanobis distance of its centre from the median keyframe
/// centroid, along the ray (depth noise and surface spread) and across it (surface spread).
fn stereo_agrees(obj: &MappedObject, e: &Ellipsoid, sigmas: f64) -> Result<(), String> {
    let with = with_centroids(obj);
    let Some(last) = with.last() else { return Err("no stereo points on it".into()) };
    let (c, sigma_z) = median_centroid(&with);
    let ray =
        (c - last.camera.world_from_camera.translation.vector).try_normalize(1e-9).ok_or("centroid at the camera")?;
    let RaySplit { along, across } = RaySplit::of(&(e.centre() - c), &ray);
    let s = class_prior(obj.class).axes.x / 3f64.sqrt();
    let m = RaySplit { along, across }.sigmas(((sigma_z * sigma_z + s * s).sqrt(), s));
    if m > sigmas {
        return Err(format!("{m:.1} σ from its stereo points ({along:+.1} m along the ray, {across:.1} m across)"));
    }
    Ok(())
}

/// The stereo rig's depth noise and the part of a box whose points are read: the object's stereo
/// points of the running system and [`ObjectMapper::check_free_space`] read them alike.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoNoise {
    /// Focal length times baseline, pixel metres (depth = this / disparity).
    pub focal_baseline: f64,
    /// Disparity noise σ, pixels.
    pub disparity_sigma_px: f64,
    /// Share of a box, per axis and about its centre, whose points are read (the running system's
    /// `object_core`).
    pub core: f64,
}

impl StereoNoise {
    /// Depth noise σ at depth `z`: `z² σ_d / (f b)`, metres.
    pub fn depth_sigma(&self, z: f64) -> f64 {
        z * z * self.disparity_sigma_px / self.focal_baseline
    }

    /// Whether pixel `(u, v)` lies in the central part (`core` of its width and height) of box `b`.
    pub fn in_core(&self, b: &BBox, u: f64, v: f64) -> bool {
        let [cu, cv] = b.centre();
        (u - cu).abs() <= 0.5 * self.core * b.width() && (v - cv).abs() <= 0.5 * self.core * b.height()
    }
}

/// Fewest stereo rays through an ellipsoid's central part for a free-space vote: with ten, a lone
/// point behind it (a reflection in a window, a mismatch) cannot make a majority.
pub const MIN_FREE_SPACE_RAYS: usize = 10;

/// How the frame's stereo points inside the central part (`noise.core`) of an ellipsoid's projected
/// box `b` relate to it, along each point's ray from `camera`: `(through, on)`, the rays that end
/// beyond its far side by more than 3 σ of their depth noise plus `margin` (free space where it
/// stands), and those that end on it (between its near side less that noise and margin, and that
/// limit). Rays that end in front of it (an occluder) or miss it do not vote.
pub fn free_space_votes(
    e: &Ellipsoid,
    camera: &Camera,
    b: &BBox,
    points: &[FramePoint],
    noise: &StereoNoise,
    margin: f64,
) -> (usize, usize) {
    let from_world = camera.world_from_camera.inverse();
    let centre = (from_world * nalgebra::Point3::from(e.centre())).coords;
    // camera-frame directions into the ellipsoid's own frame, scaled to the unit sphere
    let own_from_camera =
        e.rotation().transpose() * camera.world_from_camera.rotation.to_rotation_matrix().into_inner();
    let to_unit = |v: Vector3<f64>| (own_from_camera * v).component_div(&e.semi_axes);
    let c = -to_unit(centre);
    let (mut through, mut on) = (0, 0);
    for p in points {
        let [u, v, _] = p.observation;
        if !noise.in_core(b, u, v) {
            continue;
        }
        let x = p.camera_point;
        let range = x.norm();
        if !(range > 0.0 && x.z > 0.0) {
            continue;
        }
        // |s·d + c|² = 1 along the ray s·r (r unit), d = to_unit(r)
        let d = to_unit(x / range);
        let (qa, qb, qc) = (d.dot(&d), 2.0 * d.dot(&c), c.dot(&c) - 1.0);
        let disc = qb * qb - 4.0 * qa * qc;
        if disc < 0.0 || qa <= 0.0 {
            continue;
        }
        let (near, far) = ((-qb - disc.sqrt()) / (2.0 * qa), (-qb + disc.sqrt()) / (2.0 * qa));
        let slack = 3.0 * noise.depth_sigma(x.z) * range / x.z + margin;
        if range > far + slack {
            through += 1;
        } else if range >= near - slack {
            on += 1;
        }
    }
    (through, on)
}

/// Standard deviation of where a real object's visible surface lies, as a share of its class's
/// length semi-axis (the longest chord it can have): over the central part of the silhouette the
/// surface of an ellipsoid lies 0.88 chord half-lengths in front of the centre and that of the box
/// around it 1.0–1.27 (any side of a car or van), so a vehicle's lies within about ±0.15 of one.
const SURFACE_SHAPE_SIGMA: f64 = 0.15;

/// The stereo depth of an object's visible surface for its fit ([`MapperConfig::surface_depth`]): the
/// median of its centroids (needs [`MIN_MOTION_CENTROIDS`], so that one centroid on another object
/// cannot move it), seen along the mean direction towards the cameras that measured them; σ combines
/// their median depth noise with [`SURFACE_SHAPE_SIGMA`]. `None` without enough centroids.
pub fn surface_cue(obj: &MappedObject) -> Option<SurfaceCue> {
    let with = with_centroids(obj);
    if with.len() < MIN_MOTION_CENTROIDS {
        return None;
    }
    let (surface, sigma_z) = median_centroid(&with);
    let towards_camera = with
        .iter()
        .filter_map(|o| (o.camera.world_from_camera.translation.vector - surface).try_normalize(1e-9))
        .sum::<Vector3<f64>>();
    let shape = SURFACE_SHAPE_SIGMA * class_prior(obj.class).axes.x;
    let sigma_m = (sigma_z * sigma_z + shape * shape).sqrt();
    (towards_camera.norm() > 1e-9 && sigma_m > 0.0).then_some(SurfaceCue { surface, towards_camera, sigma_m })
}

/// A stereo point of an object followed from the frame before into this one (optical flow): its world
/// positions in both frames and the σ of each along its viewing ray (stereo depth noise) and across it
/// (a pixel of image noise at its depth), metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlowedPoint {
    /// World position in the frame before, metres.
    pub before: Vector3<f64>,
    /// World position in this frame, metres.
    pub now: Vector3<f64>,
    /// σ of the motion along the viewing ray (both frames' depth noise), metres.
    pub sigma_along: f64,
    /// σ of the motion across the ray (a pixel at both depths), metres.
    pub sigma_across: f64,
}

/// Fewest flowed points for a scene-flow reading (as for a centroid: [`MIN_OBJECT_POINTS`] in the
/// pipeline).
pub const MIN_FLOW_POINTS: usize = 5;

/// What every point's motion between two frames shares beyond its own noise, as a σ in metres: the
/// error of the tracker's frame-to-frame step (median 0.027 m on odometry 06 and 0.028 m on drive 0005
/// against the INS, session 11) and a keyframe correction from the mapper applied between the two
/// frames (up to 0.04 m, session 10).
pub const FLOW_POSE_SIGMA_M: f64 = 0.05;

/// The scene flow of an object's points: the median of their world motions between two frames, split
/// along the viewing ray (from the camera to the points' median position now) and across it, with
/// the σ of each (the median of n values with σ has σ ≈ 1.25 σ / √n; the points' noise combined with
/// [`FLOW_POSE_SIGMA_M`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneFlow {
    /// The motion, world frame, metres.
    pub motion: Vector3<f64>,
    /// The viewing ray it is split along (unit, world frame).
    pub ray: Vector3<f64>,
    /// σ of the motion along the ray, metres.
    pub sigma_along: f64,
    /// σ of the motion across the ray, metres.
    pub sigma_across: f64,
    /// Points it was read from.
    pub points: usize,
}

impl SceneFlow {
    /// A reading from a motion (world frame, metres) and its σ along and across `ray` (unit).
    pub fn new(
        motion: Vector3<f64>,
        ray: Vector3<f64>,
        (sigma_along, sigma_across): (f64, f64),
        points: usize,
    ) -> Self {
        Self { motion, ray, sigma_along, sigma_across, points }
    }

    /// The motion over two consecutive readings (`first`, then `then`): their sum along `then`'s ray,
    /// σ combined.
    pub fn over_both(first: &SceneFlow, then: &SceneFlow) -> SceneFlow {
        let s = |a: f64, b: f64| a.hypot(b);
        SceneFlow::new(
            first.motion + then.motion,
            then.ray,
            (s(first.sigma_along, then.sigma_along), s(first.sigma_across, then.sigma_across)),
            first.points.min(then.points),
        )
    }

    /// The motion along the ray (away from the camera positive) and across it, metres.
    pub fn split(&self) -> RaySplit {
        RaySplit::of(&self.motion, &self.ray)
    }

    /// The motion in σ of its noise (Mahalanobis, along and across the ray).
    pub fn sigmas(&self) -> f64 {
        self.split().sigmas((self.sigma_along, self.sigma_across))
    }
}

/// A displacement split along a viewing ray (unit) and across it, metres: how every motion test here
/// reads a displacement, since stereo depth noise lies along the ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RaySplit {
    /// Along the ray (away from the camera positive).
    pub along: f64,
    /// Across it.
    pub across: f64,
}

impl RaySplit {
    /// `v` split along and across `ray`.
    pub fn of(v: &Vector3<f64>, ray: &Vector3<f64>) -> Self {
        let along = v.dot(ray);
        Self { along, across: (v - ray * along).norm() }
    }

    /// In σ of noise with these σ along and across (Mahalanobis, the two independent).
    pub fn sigmas(&self, (sigma_along, sigma_across): (f64, f64)) -> f64 {
        ((self.along / sigma_along).powi(2) + (self.across / sigma_across).powi(2)).sqrt()
    }

    /// Its length, metres.
    pub fn norm(&self) -> f64 {
        self.along.hypot(self.across)
    }
}

/// The scene flow of `points` seen from a camera at `camera` (world position, this frame); `None`
/// below [`MIN_FLOW_POINTS`]. The median per world axis: up to half the points may be followed onto
/// another surface (a flow vector that slid off the object onto the road behind it).
pub fn scene_flow(points: &[FlowedPoint], camera: &Vector3<f64>) -> Option<SceneFlow> {
    let n = points.len();
    if n < MIN_FLOW_POINTS {
        return None;
    }
    let axis_median = |f: &dyn Fn(&FlowedPoint) -> f64| median(&mut points.iter().map(f).collect::<Vec<_>>());
    let motion = Vector3::new(
        axis_median(&|p| p.now.x - p.before.x),
        axis_median(&|p| p.now.y - p.before.y),
        axis_median(&|p| p.now.z - p.before.z),
    );
    let at = Vector3::new(axis_median(&|p| p.now.x), axis_median(&|p| p.now.y), axis_median(&|p| p.now.z));
    let ray = (at - camera).try_normalize(1e-9)?;
    let rms = |f: &dyn Fn(&FlowedPoint) -> f64| (points.iter().map(|p| f(p).powi(2)).sum::<f64>() / n as f64).sqrt();
    let of_median = |s: f64| ((1.2533 * s / (n as f64).sqrt()).powi(2) + FLOW_POSE_SIGMA_M.powi(2)).sqrt();
    Some(SceneFlow::new(motion, ray, (of_median(rms(&|p| p.sigma_along)), of_median(rms(&|p| p.sigma_across))), n))
}

/// Fewest scene-flow readings over a trend's span that can refute it ([`flow_refutes`]).
const MIN_REFUTING_READINGS: usize = 3;

/// Whether the object's scene-flow readings over the frames `span` (at least
/// [`MIN_REFUTING_READINGS`]) refute its centroid trend: their mean rate (motion per frame id, σ from
/// each reading's) stands within `limit` σ of standing still and more than `limit` σ (the two rates'
/// σ combined) away from the trend's rate (`trend`: rate, motion per frame id, and its σ along and
/// across `ray`). The trend reads where the
/// object's points put it frame after frame, so centroids on another object (a box that slid, a track
/// merged into this one) move it; the flow follows the same points from each frame to the next and
/// does not see them. A slow mover whose flow is too noisy to exclude its trend is not refuted.
fn flow_refutes(
    flows: &[(usize, usize, SceneFlow)],
    (from, to): (usize, usize),
    (rate, (rate_along, rate_across)): (Vector3<f64>, (f64, f64)),
    ray: &Vector3<f64>,
    limit: f64,
) -> bool {
    let within: Vec<&(usize, usize, SceneFlow)> =
        flows.iter().filter(|(f, gap, _)| *f > from && *f <= to && *gap > 0).collect();
    let k = within.len();
    if k < MIN_REFUTING_READINGS {
        return false;
    }
    let kf = k as f64;
    let mean = within.iter().map(|(_, gap, r)| r.motion / *gap as f64).sum::<Vector3<f64>>() / kf;
    let var = |s: &dyn Fn(&SceneFlow) -> f64| {
        within.iter().map(|(_, gap, r)| (s(r) / *gap as f64).powi(2)).sum::<f64>() / (kf * kf)
    };
    let (flow_along, flow_across) = (var(&|r| r.sigma_along).sqrt(), var(&|r| r.sigma_across).sqrt());
    let still = RaySplit::of(&mean, ray).sigmas((flow_along, flow_across)) <= limit;
    let combined = (flow_along.hypot(rate_along), flow_across.hypot(rate_across));
    still && RaySplit::of(&(rate - mean), ray).sigmas(combined) > limit
}

/// Centroids at each end of those the motion test reads whose median depth noise it takes for that
/// end (see [`ObjectMapper::add_points`]).
pub const MOTION_WINDOW: usize = 3;

/// Fewest centroids the motion test reads: with four, the repeated median still holds when one of
/// them lies on another object.
const MIN_MOTION_CENTROIDS: usize = 4;

/// Median depth σ of centroids.
fn median_sigma(c: &[(usize, Vector3<f64>, f64)]) -> f64 {
    median(&mut c.iter().map(|p| p.2).collect::<Vec<_>>())
}

/// The displacement of an object over centroids `c` (the latest [`TREND_CENTROIDS`] of its track)
/// that their trend explains: the repeated-median slope (Siegel's estimator, per world axis: for each
/// centroid the median of its slopes to every other, then the median of those) times the frames they
/// span. A robust trend: up to
/// half of the centroids can lie on another object (a box that slid onto a car passing in front)
/// without moving it, and the noise of single frames averages out.
fn trend(c: &[(usize, Vector3<f64>, f64)]) -> Vector3<f64> {
    let span = (c[c.len() - 1].0 - c[0].0) as f64;
    let (mut to_others, mut per_point) = (Vec::with_capacity(c.len()), Vec::with_capacity(c.len()));
    let mut slope = |k: usize| {
        per_point.clear();
        for a in c {
            to_others.clear();
            to_others.extend(c.iter().filter(|b| b.0 != a.0).map(|b| (b.1[k] - a.1[k]) / (b.0 as f64 - a.0 as f64)));
            if !to_others.is_empty() {
                per_point.push(median(&mut to_others));
            }
        }
        if per_point.is_empty() {
            0.0
        } else {
            median(&mut per_point)
        }
    };
    Vector3::new(slope(0), slope(1), slope(2)) * span
}

/// Most centroids the motion test reads (the latest ones): 30 frames, three seconds of KITTI; the
/// slope is the object's motion now, and the pairs of the repeated median stay few.
const TREND_CENTROIDS: usize = 30;

fn box_rms(views: &[BoxView], image: &ImageSize, e: &Ellipsoid, shape: BoxShape) -> Option<f64> {
    let mut sum = 0.0;
    for v in views {
        sum += box_residual(v, image, e, shape)?.norm_squared();
    }
    Some((sum / (4 * views.len().max(1)) as f64).sqrt())
}

/// Version of the object-map JSON.
pub const OBJECT_MAP_VERSION: u32 = 1;

/// An object as the object-map JSON stores it (the map file adds its map points).
#[derive(Serialize)]
struct ObjectJson {
    id: u64,
    class: u16,
    class_name: String,
    center: [f64; 3],
    semi_axes: [f64; 3],
    rotation: [f64; 9],
    frames: Vec<usize>,
    dynamic: bool,
    moving: bool,
}

#[derive(Serialize)]
struct MapJson<'a> {
    version: u32,
    frame: &'a str,
    objects: Vec<ObjectJson>,
}

impl MappedObject {
    /// The stored form (`None` without an ellipsoid): centre, semi-axes, rotation (3×3 row-major, world
    /// from object), frames, dynamic flag and map points.
    pub fn to_map_object(&self) -> Option<crate::map::MapObject> {
        let e = self.ellipsoid.as_ref()?;
        let r = e.rotation();
        Some(crate::map::MapObject {
            id: self.id.0,
            class: self.class.0,
            class_name: self.class.name().to_string(),
            center: [e.centre().x, e.centre().y, e.centre().z],
            semi_axes: [e.semi_axes.x, e.semi_axes.y, e.semi_axes.z],
            rotation: std::array::from_fn(|k| r[(k / 3, k % 3)]),
            frames: self.observations.iter().map(|x| x.frame).collect(),
            dynamic: self.dynamic,
            moving: self.moving,
            points: self.points.iter().copied().collect(),
        })
    }
}

/// Write the object map (objects with an ellipsoid) as JSON, atomically, naming the world frame of the
/// poses the objects were mapped with "world of the input poses" ([`write_object_map_in`]).
pub fn write_object_map(path: &Path, objects: &[&MappedObject]) -> std::io::Result<()> {
    write_object_map_in(path, objects, INPUT_POSES_WORLD)
}

/// The world frame of an object map made from given poses ([`write_object_map`]), in words.
pub const INPUT_POSES_WORLD: &str = "world of the input poses (camera to world of the left camera)";

/// Write the object map (objects with an ellipsoid) as JSON, atomically. Schema (version 1): `frame`
/// (the world frame, in words), `objects` with `id`, `class` (COCO index), `class_name`, `center`
/// `[x, y, z]` and `rotation` (3×3 row-major, world from object) in that world frame, `semi_axes` metres
/// along the object's x (length), y (height), z (width), `frames` (frames of its detections), `dynamic`
/// (flagged dynamic by any test) and `moving` (its map points moved: not a mapped object).
pub fn write_object_map_in(path: &Path, objects: &[&MappedObject], frame: &str) -> std::io::Result<()> {
    slam_core::files::write_atomic(path, object_map_text(objects, frame)?.as_bytes()).map_err(std::io::Error::other)
}

/// The object map's JSON text ([`write_object_map_in`]), for writers that put it in place themselves.
pub fn object_map_text(objects: &[&MappedObject], frame: &str) -> std::io::Result<String> {
    let objects = objects
        .iter()
        .filter_map(|o| o.to_map_object())
        .map(|m| ObjectJson {
            id: m.id,
            class: m.class,
            class_name: m.class_name,
            center: m.center,
            semi_axes: m.semi_axes,
            rotation: m.rotation,
            frames: m.frames,
            dynamic: m.dynamic,
            moving: m.moving,
        })
        .collect();
    serde_json::to_string_pretty(&MapJson { version: OBJECT_MAP_VERSION, frame, objects })
        .map_err(std::io::Error::other)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Centroids of frames `0..n`: `at(i)` each, with a seeded jitter of ±`noise` metres per axis.
    fn centroids(n: usize, noise: f64, at: impl Fn(usize) -> Vector3<f64>) -> Vec<(usize, Vector3<f64>, f64)> {
        let mut rng = slam_core::rng::SimRng::new(7);
        (0..n)
            .map(|i| {
                let jitter =
                    Vector3::new(rng.uniform(-noise, noise), rng.uniform(-noise, noise), rng.uniform(-noise, noise));
                (i, at(i) + jitter, 0.4)
            })
            .collect()
    }

    /// Scene flow: twenty points on a car 15 m ahead, each with its stereo depth noise (σ_z at 15 m,
    /// 0.5 px of disparity, KITTI's rig: 0.29 m) in both frames. Parked, the flow stays within 3 σ;
    /// pulling away by 0.5 m per frame (5 m/s faster than the camera at 10 Hz) it stands above; with a
    /// quarter of thirty points followed onto the static road under it, the median still sees the car's
    /// motion (0.8 m per frame); fewer than five points give no reading.
    #[test]
    fn scene_flow_sees_a_car_pull_away_and_not_a_parked_one() {
        let noise = StereoNoise { focal_baseline: 721.5 * 0.54, disparity_sigma_px: 0.5, core: 0.6 };
        let camera = Vector3::zeros();
        let mut rng = slam_core::rng::SimRng::new(11);
        let mut points = |motion: f64, n: usize, static_share: f64| -> Vec<FlowedPoint> {
            (0..n)
                .map(|k| {
                    let x = Vector3::new(rng.uniform(-0.8, 0.8), rng.uniform(-0.5, 0.5), 15.0 + rng.uniform(0.0, 0.3));
                    let sz = noise.depth_sigma(x.z);
                    let moved = if (k as f64) < static_share * n as f64 { 0.0 } else { motion };
                    let ray = x.normalize();
                    let before = x + ray * (sz * rng.normal());
                    let now = x + Vector3::new(0.0, 0.0, moved) + ray * (sz * rng.normal());
                    FlowedPoint { before, now, sigma_along: sz * 2f64.sqrt(), sigma_across: x.z / 721.5 * 2f64.sqrt() }
                })
                .collect()
        };
        let parked = scene_flow(&points(0.0, 20, 0.0), &camera).expect("a reading");
        assert!(parked.sigmas() < 3.0, "{parked:?}");
        let pulling = scene_flow(&points(0.5, 20, 0.0), &camera).expect("a reading");
        assert!(pulling.sigmas() > 3.0 && pulling.split().along > 0.3, "{pulling:?}");
        let partly_road = scene_flow(&points(0.8, 30, 0.25), &camera).expect("a reading");
        assert!(partly_road.sigmas() > 3.0 && partly_road.split().along > 0.3, "{partly_road:?}");
        assert!(scene_flow(&points(1.0, MIN_FLOW_POINTS - 1, 0.0), &camera).is_none());
    }

    /// The scene flow refutes a centroid trend only when its own readings over the trend's span say
    /// "still" precisely enough to exclude the trend's rate: a parked van whose centroids were pulled
    /// 10 m by another object's (0.33 m per frame over 30 frames) is refuted by readings of 0 ± 0.1 m
    /// per frame; a van pulling away at that rate, read so by its flow, is not; a slow mover (0.05 m per
    /// frame) whose readings are too noisy to tell is not; nor with fewer than three readings in the
    /// span, or readings outside it.
    #[test]
    fn scene_flow_refutes_a_trend_only_when_it_can_exclude_it() {
        let ray = Vector3::new(0.0, 0.0, 1.0);
        let reading = |dz: f64, sigma: f64| SceneFlow::new(Vector3::new(0.0, 0.0, dz), ray, (sigma, 0.05), 20);
        let readings = |dz: f64, sigma: f64, frames: &[usize]| -> Vec<(usize, usize, SceneFlow)> {
            frames.iter().map(|&f| (f, 1, reading(dz, sigma))).collect()
        };
        // the trend's displacement σ (1.3 m along, 1.2 m across) over its 30 frames
        let trend = |rate: f64| (Vector3::new(0.0, 0.0, rate), (1.3 / 30.0, 1.2 / 30.0));
        let span = (10, 40);
        let some: Vec<usize> = vec![12, 20, 27, 33, 38];
        assert!(flow_refutes(&readings(0.02, 0.1, &some), span, trend(10.0 / 30.0), &ray, 3.0), "a parked van");
        assert!(!flow_refutes(&readings(0.33, 0.1, &some), span, trend(10.0 / 30.0), &ray, 3.0), "a van pulling away");
        assert!(!flow_refutes(&readings(0.0, 0.6, &some), span, trend(0.05), &ray, 3.0), "a slow mover, noisy flow");
        assert!(!flow_refutes(&readings(0.02, 0.1, &[12, 20]), span, trend(10.0 / 30.0), &ray, 3.0), "two readings");
        assert!(!flow_refutes(&readings(0.02, 0.1, &[2, 5, 8, 45]), span, trend(10.0 / 30.0), &ray, 3.0), "outside");
    }

    #[test]
    fn trend_sees_a_steady_motion_and_not_centroids_on_another_object() {
        // a van driving ahead: 0.45 m per frame away from the camera, 0.2 m of depth noise
        let moving = centroids(12, 0.2, |i| Vector3::new(-4.0, 1.0, 11.0 + 0.45 * i as f64));
        let d = trend(&moving);
        assert!((d.z - 0.45 * 11.0).abs() < 0.5 && d.x.abs() < 0.5, "{d:?}");
        // a parked van 40 m ahead whose box slid onto a car passing 20 m nearer in the two latest frames
        // (two of five, then two of eight): the trend stays put; a least-squares slope would not
        for n in [5, 8] {
            let parked = centroids(n, 0.3, |i| Vector3::new(-13.3, 1.2, if i + 2 >= n { 21.0 } else { 40.0 }));
            let d = trend(&parked);
            // far inside what the motion test allows a static car (3 σ, over 3.6 m from its size alone)
            assert!(d.norm() < 2.0, "{n} centroids: {d:?}");
            let (t, z): (Vec<f64>, Vec<f64>) = parked.iter().map(|c| (c.0 as f64, c.1.z)).unzip();
            let (tm, zm) = (t.iter().sum::<f64>() / n as f64, z.iter().sum::<f64>() / n as f64);
            let ls = t.iter().zip(&z).map(|(a, b)| (a - tm) * (b - zm)).sum::<f64>()
                / t.iter().map(|a| (a - tm).powi(2)).sum::<f64>();
            assert!((ls * (n - 1) as f64).abs() > 3.0, "least squares is pulled by the other object: {ls}");
        }
        // one centroid and none: no trend
        assert_eq!(trend(&moving[..1]), Vector3::zeros());
    }

    #[test]
    fn one_box_per_object_across_tiles_parts_and_class_groups() {
        let d = |class: u16, score: f64, b: [f64; 4]| {
            Detection::new(ClassId(class), score, BBox::new(b[0], b[1], b[2], b[3]))
        };
        let input = vec![
            d(2, 0.6, [100.0, 100.0, 200.0, 180.0]), // a car
            d(2, 0.9, [105.0, 102.0, 196.0, 178.0]), // the same car from another tile (IoU 0.86)
            d(7, 0.5, [98.0, 95.0, 203.0, 182.0]),   // the same car called a truck: same class group
            d(2, 0.8, [150.0, 120.0, 198.0, 178.0]), // its front half: a part
            d(0, 0.7, [150.0, 110.0, 170.0, 170.0]), // a person in front of it: another group, kept
            d(2, 0.7, [400.0, 100.0, 480.0, 160.0]), // another car
            d(2, 0.7, [470.0, 100.0, 560.0, 160.0]), // its neighbour, overlapping a little: kept
        ];
        let (kept, dropped) = suppress_duplicate_boxes(input.clone());
        assert_eq!(dropped, 3);
        // the largest box of the first car (the "truck") stands for it; input order is kept
        let boxes: Vec<[f64; 2]> = kept.iter().map(|k| [k.bbox.xmin, k.bbox.ymin]).collect();
        assert_eq!(boxes, vec![[98.0, 95.0], [150.0, 110.0], [400.0, 100.0], [470.0, 100.0]]);
        // deterministic whatever the input order
        let mut reversed = input;
        reversed.reverse();
        let (again, n) = suppress_duplicate_boxes(reversed);
        assert_eq!(n, 3);
        let mut a: Vec<[f64; 2]> = again.iter().map(|k| [k.bbox.xmin, k.bbox.ymin]).collect();
        a.reverse();
        assert_eq!(a, boxes);
    }

    #[test]
    fn sizes_no_real_object_has_are_refused_and_real_ones_kept() {
        let v = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        // every class's prior size, and the prior's long axis 3σ off, is a real object
        for c in [0u16, 1, 2, 3, 5, 6, 7] {
            let p = class_prior(ClassId(c));
            assert!(physically_plausible(ClassId(c), &p.axes).is_ok(), "class {c} prior");
            let long = p.axes + Vector3::new(3.0 * p.sigma.x, 0.0, 0.0);
            assert!(physically_plausible(ClassId(c), &long).is_ok(), "class {c} prior + 3 sigma");
        }
        // the parked van of drive 0005 as fitted (semi-axes, m), and an articulated bus
        assert!(physically_plausible(ClassId(2), &v(2.11, 0.80, 0.73)).is_ok());
        assert!(physically_plausible(ClassId(5), &v(9.0, 1.6, 1.27)).is_ok());
        // the bus shelter of drive 0005 fitted as a truck: 12.6 m long, 1.2 m tall, 0.48 m wide
        let shelter = physically_plausible(ClassId(7), &v(6.3, 0.61, 0.24)).unwrap_err();
        assert!(shelter.contains("0.48 m across"), "{shelter}");
        // a 12 m car, a 25 m truck, a 3 m tall person, a 6 m wide bus
        assert!(physically_plausible(ClassId(2), &v(6.0, 0.8, 0.8)).unwrap_err().contains("12.00 m long"));
        assert!(physically_plausible(ClassId(7), &v(12.5, 1.5, 1.25)).is_err());
        assert!(physically_plausible(ClassId(0), &v(0.3, 1.5, 0.3)).is_err());
        assert!(physically_plausible(ClassId(5), &v(6.0, 3.0, 1.5)).unwrap_err().contains("6.00 m wide or tall"));
        // a degenerate fit (NaN axes) is not a real object either
        assert!(physically_plausible(ClassId(2), &v(f64::NAN, 0.8, 0.8)).is_err());
    }

    #[test]
    fn surface_cue_is_the_median_centroid_seen_from_the_cameras_once_four_exist() {
        let k = slam_quadric::Intrinsics { fx: 721.5, fy: 721.5, skew: 0.0, cx: 609.6, cy: 172.9 };
        let observation = |i: usize, centroid: Vector3<f64>| Observation {
            frame: i,
            camera: Camera::new(k, nalgebra::Isometry3::translation(0.0, 0.0, i as f64)),
            bbox: BBox::new(600.0, 150.0, 700.0, 220.0),
            detection: 0,
            centroid: Some(centroid),
            depth_sigma: 0.4,
            reference: None,
        };
        let mut obj = MappedObject::new(TrackId(1), ClassId(2));
        let parked = Vector3::new(-2.0, 1.0, 30.0);
        for i in 0..3 {
            obj.observations.push(observation(i, parked));
        }
        assert!(surface_cue(&obj).is_none(), "three centroids are too few");
        // a fourth on a car passing 10 m nearer, then a fifth on the parked one: the median holds
        obj.observations.push(observation(3, parked - Vector3::new(0.0, 0.0, 10.0)));
        obj.observations.push(observation(4, parked));
        let cue = surface_cue(&obj).expect("five centroids");
        assert!((cue.surface - parked).norm() < 1e-12, "{:?}", cue.surface);
        // towards the cameras (all on the z axis behind it), σ from the depth noise and the car's length
        let dir = cue.towards_camera.normalize();
        assert!(dir.z < -0.99 && dir.x > 0.0, "{dir:?}");
        let shape = SURFACE_SHAPE_SIGMA * class_prior(ClassId(2)).axes.x;
        assert!((cue.sigma_m - (0.4f64.powi(2) + shape * shape).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn free_space_votes_count_rays_through_and_on_an_ellipsoid_and_skip_occluders() {
        let k = slam_quadric::Intrinsics { fx: 721.5, fy: 721.5, skew: 0.0, cx: 609.6, cy: 172.9 };
        let camera = Camera::new(k, nalgebra::Isometry3::identity());
        let e = Ellipsoid::new(nalgebra::Isometry3::translation(0.0, 0.0, 20.0), Vector3::new(2.0, 0.8, 0.85));
        let image = ImageSize::new(1242.0, 375.0);
        let b = project(&e, &camera).and_then(|c| c.clipped_bounds(&image)).expect("in view");
        let noise = StereoNoise { focal_baseline: 721.5 * 0.54, disparity_sigma_px: 0.5, core: 0.6 };
        // points along rays through the box's centre region at a given depth
        let at = |z: f64| -> Vec<FramePoint> {
            [(-0.03, -0.01), (0.0, 0.0), (0.03, 0.01), (0.015, -0.015)]
                .iter()
                .map(|&(x, y)| {
                    let p = Vector3::new(x, y, 1.0) * z;
                    let (u, v) = (k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
                    FramePoint { camera_point: p, observation: [u, v, u - 721.5 * 0.54 / z] }
                })
                .collect()
        };
        // its surface faces the camera at z 19.15; 3 σ at 20 m is 1.5 m, the margin 2 m
        assert_eq!(free_space_votes(&e, &camera, &b, &at(19.2), &noise, 2.0), (0, 4));
        assert_eq!(free_space_votes(&e, &camera, &b, &at(40.0), &noise, 2.0), (4, 0));
        assert_eq!(free_space_votes(&e, &camera, &b, &at(10.0), &noise, 2.0), (0, 0), "an occluder");
        // points outside the box's central part do not vote
        let aside: Vec<FramePoint> =
            at(40.0).into_iter().map(|p| FramePoint { observation: [b.xmin + 1.0, b.ymin + 1.0, 0.0], ..p }).collect();
        assert_eq!(free_space_votes(&e, &camera, &b, &aside, &noise, 2.0), (0, 0));
        // the same scene from a camera elsewhere, turned 0.8 rad (the ellipsoid with it): the same votes.
        // Its far side is 20.85 m away along the view, so a point at 26 m is beyond it by more than
        // 3 σ (2.60 m there) and the 2 m margin; had the car's long axis (2 m) been taken along the
        // view, it would not be.
        let pose = nalgebra::Isometry3::new(Vector3::new(3.0, 0.0, -2.0), Vector3::y() * 0.8);
        let turned = Camera::new(k, pose);
        let e2 = Ellipsoid::new(pose * nalgebra::Isometry3::translation(0.0, 0.0, 20.0), e.semi_axes);
        let b2 = project(&e2, &turned).and_then(|c| c.clipped_bounds(&image)).expect("in view");
        for (cam, ell, bb) in [(&camera, &e, &b), (&turned, &e2, &b2)] {
            assert_eq!(free_space_votes(ell, cam, bb, &at(26.0), &noise, 2.0), (4, 0));
            assert_eq!(free_space_votes(ell, cam, bb, &at(19.2), &noise, 2.0), (0, 4));
        }
    }
}
