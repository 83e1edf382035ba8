//! The object mapper's settings ([`MapperConfig`], the `[objects]` table of a settings file).

use serde::Serialize;
use slam_assoc::TrackerConfig;
use slam_optim::object::BoxShape;
use slam_quadric::ImageSize;

/// Settings of the [`ObjectMapper`] (the `[objects]` table of `slam-app run --config`; `image` and
/// `tracker` are set by the caller, not by the file; the fitting method is given to the mapper
/// ([`ObjectMapper::with_method`])).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize, documented::DocumentedFieldsOpt)]
#[serde(default, deny_unknown_fields)]
pub struct MapperConfig {
    /// What a box bounds in the object optimisation: "cuboid" (the cuboid circumscribing the
    /// ellipsoid: a vehicle is box-shaped, and its box bounds its corners; default, with the object's
    /// stereo points on the cuboid's visible sides in the running system), "ellipse" (the ellipsoid's
    /// projected ellipse, the paper's model, which turns and grows an ellipsoid until it fills the box)
    /// or "two-stage" (yaw from the cuboid model, then the ellipse model with that yaw held);
    /// docs/objects.md.
    #[serde(with = "crate::serde_forms::box_shape")]
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
    #[serde(with = "crate::serde_forms::zero_is_off_usize")]
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
    #[serde(with = "crate::serde_forms::zero_is_off")]
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
    /// projected box inside the image, no farther than the farthest it was detected at (a small detector
    /// misses distant cars that it finds nearer), not overlapped by another box, in a frame with detections) and
    /// was not in this many frames in a row is removed (refitted when boxes come again). Default 5: a
    /// detector that finds a visible car 3 times in 4 misses it 5 times running about once in a
    /// thousand. `None`: off.
    #[serde(with = "crate::serde_forms::zero_is_off_usize")]
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
    #[serde(with = "crate::serde_forms::zero_is_off_usize")]
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
            box_shape: BoxShape::Cuboid,
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

//SUPER
