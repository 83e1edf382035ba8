//! The running system: the paper's threads, talking through `crossbeam-channel` messages.
//!
//! ```text
//!  reader ──frames──▶ detection ──frames+boxes──▶ tracking ──window snapshots + fit jobs──▶ local mapping
//!                                                    ▲                                          │
//!                                                    └─────────── map edits + fitted objects ───┘
//! ```
//! - **reader**: decodes the stereo pairs (the caller's iterator) ahead of time.
//! - **detection**: runs the [`DetectionSource`] on every `detect_every`-th left image.
//! - **tracking** (the calling thread): owns the live map ([`slam_core::Map`]); the [`StereoTracker`]
//!   tracks against it, the keyframes it hands over are inserted, optical flow in the boxes, object
//!   association ([`ObjectMapper::associate`]), the moving-object test, and on keyframes the job of
//!   local mapping (a snapshot of the keyframe's window) and the fit jobs.
//! - **local mapping**: works on the snapshot (point culling, triangulation, fusion, local bundle
//!   adjustment, keyframe culling: [`crate::mapping`]) and the object fits, and replies with the
//!   snapshot's edits, which the tracking thread applies to the live map. `on_frame` observers get
//!   per-frame views ([`FrameView`]: the record, the pose, the left image, the live map, the objects).
//!   No locks are shared.
//!
//! Determinism: the tracking thread applies local mapping's reply for a keyframe made at the `k`-th
//! input frame just before it tracks the `(k + correction_lag)`-th, or before it inserts the next
//! keyframe if that comes first (waiting for it if need be), never "whenever it arrives": every
//! snapshot holds all earlier work, and a run gives the same output however the threads are
//! scheduled. [`RunOutput::map`] is the saved form of the live map ([`SavedMap::from_live`]), made
//! once in [`System::finish`]; the caller writes it ([`SavedMap::save`]).
//!
//! Frame identity: [`FrameInput::index`] is the frame's id in its sequence (the number in the file
//! names), not its position: records, the map's trajectory and keyframes, and the detector's `frame`
//! argument all carry that id, so a run over a subset or a sequence with gaps stays aligned with
//! ground truth, labels and detection files.

mod builder;
mod threads;
mod tracking_thread;

pub use builder::{FrameSource, System, SystemBuilder};
use nalgebra::Isometry3;
use slam_core::{
    geometry::Intrinsics, Detection, DetectionSource, Image, KeyframeId, StereoTracker, TrackError, TrackId, TrackState,
};
use slam_optim::SharedOptimizer;
pub use threads::MapperRequest;
pub use tracking_thread::TrackingThread;

use crate::{
    mapping::MappingConfig,
    objects::{MappedObject, MapperConfig, ObjectMapper},
    saved_map::SavedMap,
    texture::TextureConfig,
};

/// The box misfit (RMS, pixels) that flags an object dynamic in the running system, where boxes come
/// from a detector: detector boxes are partial and jitter from frame to frame, so a parked car's fitted
/// ellipsoid misses them by 3 to 22 px RMS on KITTI odometry 06 (9 objects whose map points stayed put)
/// and up to about 25 px on raw drive 0005; the object mapper's own default (12 px) is for label-quality
/// boxes and flagged 5 of those 9 parked cars on 06 dynamic. Moving objects are caught by their map
/// points' motion in the running system (docs/system.md, "Settings").
pub const DETECTOR_DYNAMIC_RMS_PX: f64 = 25.0;

/// Settings of the system (its own keys are the `[system]` table of `slam-app run --config`; the stages'
/// settings are tables of their own there, `[mapping]`, `[objects]`, `[texture]`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, documented::DocumentedFieldsOpt)]
#[serde(default, deny_unknown_fields)]
pub struct SystemConfig {
    /// Local mapping.
    #[serde(skip)]
    pub mapping: MappingConfig,
    /// Object mapping. Default: the mapper's defaults with `dynamic_rms_px` at
    /// [`DETECTOR_DYNAMIC_RMS_PX`] and `stereo_evidence` on (the tracker's stereo points are there).
    #[serde(skip)]
    pub objects: MapperConfig,
    /// Texture planes.
    #[serde(skip)]
    pub texture: TextureConfig,
    /// Input frames between a keyframe and the application of the mapper's reply to it. Default 2.
    pub correction_lag: usize,
    /// Run the detector on every n-th frame played (the first, the (n+1)-th, ...; the others get no
    /// boxes), whatever the frame ids. Default 1.
    pub detect_every: usize,
    /// Keep keypoints of moving objects out of tracking: inside the object's last box, at the depths its
    /// stereo points span (`slam_core::MovingRegion`). Default on.
    pub exclude_moving: bool,
    /// Find moving objects from frame to frame too: the 3-D motion (scene flow) of their stereo points
    /// followed by optical flow from the frame before ([`crate::objects::ObjectMapper::add_flow`]), next
    /// to the trend of their centroids. Default on; no effect without stereo points (image-free).
    pub scene_flow: bool,
    /// Map points inside the central part of a box (this fraction of its width and height) belong to
    /// the object. Default 0.6.
    pub object_core: f64,
    /// Standard deviation of a stereo disparity, pixels: the depth noise `σ_z = z² σ_d / (f b)` of the
    /// objects' points in the moving-object test. Default 0.5 (ORB keypoints from pyramid levels up
    /// to 1.2⁴ coarser, matched with sub-pixel refinement).
    pub disparity_sigma_px: f64,
    /// Suppress duplicate and part boxes (same class group, IoU above 0.45 or nested) before
    /// association. Default on.
    pub suppress_duplicates: bool,
    /// ODA gate: a detection is never given to an object whose projected ellipsoid overlaps it by less
    /// than this IoU. Default `Some(0.1)`; `None` (0 in a settings file) is the paper's cost alone.
    #[serde(with = "crate::serde_forms::zero_is_off")]
    pub projected_gate: Option<f64>,
    /// Localise only in a loaded map (`slam-app run --map FILE --localise-only`): no object is added
    /// or refined (the tracker makes no keyframe). Not a settings-file key.
    #[serde(skip)]
    pub localise_only: bool,
    /// Most detections kept per frame (the highest scores; the rest are dropped and counted). The busiest
    /// labelled frame of the KITTI tracking fixtures has 25 boxes; association cost grows with the cube of
    /// the count (1,000 boxes per frame once took 297 s for 51 frames). Default 100.
    pub max_detections: usize,
}

impl Default for SystemConfig {
    fn default() -> Self {
        Self {
            mapping: MappingConfig::default(),
            objects: MapperConfig {
                dynamic_rms_px: DETECTOR_DYNAMIC_RMS_PX,
                stereo_evidence: true,
                ..MapperConfig::default()
            },
            texture: TextureConfig::default(),
            correction_lag: 2,
            detect_every: 1,
            exclude_moving: true,
            scene_flow: true,
            object_core: 0.6,
            disparity_sigma_px: 0.5,
            suppress_duplicates: true,
            projected_gate: Some(0.1),
            max_detections: 100,
            localise_only: false,
        }
    }
}

/// One input frame: its stereo pair, or why it could not be read.
#[derive(Debug)]
pub struct FrameInput {
    /// Frame id in the sequence (the number in the file names), increasing; not a position.
    pub index: usize,
    /// Left and right images, or the reason they are missing.
    pub images: Result<(Image, Image), String>,
}

/// What happened in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameRecord {
    /// Frame index.
    pub index: usize,
    /// Tracking state; `None` for an unreadable frame.
    pub state: Option<TrackState>,
    /// The frame became a keyframe.
    pub keyframe: bool,
    /// Map points tracked in the frame (0 when no pose was measured or the frame was unreadable).
    pub tracked_map_points: usize,
    /// RMS reprojection error of the tracked map points, pixels (NaN when none).
    pub reprojection_rms_px: f64,
    /// Detections used.
    pub detections: Vec<Detection>,
    /// Object of each detection.
    pub tracks: Vec<Option<TrackId>>,
    /// Stage times, milliseconds.
    pub times: FrameTimes,
}

/// What an observer of [`System::run`] sees of one frame as soon as it is tracked (a live view, a
/// recording): its record and borrowed views of the state behind it, valid during the call. Nothing
/// is copied for it: the image and the map are the ones tracking used.
pub struct FrameView<'a> {
    /// The frame's record.
    pub record: &'a FrameRecord,
    /// Pose of the left camera at tracking time, world from camera (the final trajectory follows local
    /// mapping's later corrections of the keyframes); `None` for an unreadable frame.
    pub world_from_camera: Option<Isometry3<f64>>,
    /// The left image; `None` for an unreadable frame.
    pub left: Option<&'a Image>,
    /// The live map as the frame left it (its keyframe, if it made one, inserted).
    pub map: &'a slam_core::Map,
    /// The keyframes whose local mapping (refined poses and points, new and culled points) reached the
    /// map just before this frame was tracked, oldest first.
    pub mapped: &'a [KeyframeId],
    /// The objects so far (their ellipsoids as last fitted).
    pub objects: &'a ObjectMapper,
}

/// Per-frame stage times, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameTimes {
    /// Wall time from the end of the previous frame's tracking to the end of this one's: the
    /// system's throughput, all threads included (the first frame: from the start of the run).
    pub interval: f64,
    /// Detection (its own thread).
    pub detection: f64,
    /// The detector network's forward passes, part of `detection` (0 for a source that runs no network).
    pub detector_forward: f64,
    /// Feature extraction.
    pub extraction: f64,
    /// Stereo matching.
    pub stereo: f64,
    /// Frame tracking.
    pub tracking: f64,
    /// Optical flow for the association.
    pub flow: f64,
    /// Object association.
    pub association: f64,
    /// Local bundle adjustment (keyframes; mapping thread).
    pub bundle_adjustment: f64,
    /// The rest of local mapping: point culling, triangulation, fusion, keyframe culling (keyframes;
    /// mapping thread).
    pub map_maintenance: f64,
    /// Object initialisation and optimisation (keyframes; mapping thread).
    pub objects: f64,
}

/// Counts of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RunCounts {
    /// Frames.
    pub frames: usize,
    /// Keyframes.
    pub keyframes: usize,
    /// Frames whose images could not be read (pose held).
    pub unreadable: usize,
    /// Frames tracked with full support.
    pub tracked: usize,
    /// Frames tracked with less support (pose used, marked weak).
    pub weak: usize,
    /// Frames where tracking failed (the first frame of a failure; pose predicted).
    pub lost: usize,
    /// Frames after a lost one that were not recovered either (pose predicted).
    pub predicted: usize,
    /// Frames recovered by relocalisation.
    pub relocalised: usize,
    /// Map segments started after a failure (the first one not counted).
    pub new_segments: usize,
    /// Map segments tracked in a frame of their own that joined the loaded map once a frame of them
    /// was placed there.
    pub joined_segments: usize,
    /// Detection failures (counted and logged, the frame goes on without boxes).
    pub detector_errors: usize,
    /// Observations culled by local mapping.
    pub culled_observations: usize,
    /// Young points culled (not found again, or seen by too few keyframes).
    pub culled_points: usize,
    /// Points triangulated between keyframes.
    pub triangulated_points: usize,
    /// Points merged into another by fusion.
    pub fused_points: usize,
    /// Keyframes culled as redundant.
    pub culled_keyframes: usize,
    /// Detector boxes suppressed as duplicates or parts of another box of the same class group.
    pub suppressed_boxes: usize,
    /// Fitted ellipsoids refused for a size no real object of their class has
    /// ([`crate::objects::physically_plausible`]).
    pub implausible_fits: usize,
    /// Ellipsoids removed because the stereo points saw free space through them
    /// ([`crate::objects::ObjectMapper::check_free_space`]).
    pub free_space_removals: usize,
}

/// Everything a run produced.
pub struct RunOutput {
    /// The saved map (made from the live map when the run ended): keyframes, points, objects,
    /// per-frame trajectory.
    pub map: SavedMap,
    /// Pose of every input frame (left camera, world from camera), following the refined keyframes
    /// (the identity for a frame not placed in a loaded map: see `placed`).
    pub poses: Vec<Isometry3<f64>>,
    /// Whether each frame has a pose in the map: false only for frames before the first one placed in
    /// a map loaded from an earlier run.
    pub placed: Vec<bool>,
    /// The objects with their observations.
    pub objects: Vec<MappedObject>,
    /// Per-frame records.
    pub frames: Vec<FrameRecord>,
    /// Counts.
    pub counts: RunCounts,
}

/// Failures of the system itself (not of the data: bad frames are counted and logged).
#[derive(Debug, thiserror::Error)]
pub enum SystemError {
    /// The tracker failed in a way it could not turn into a lost frame.
    #[error("frame {frame}: {source}")]
    Tracker {
        /// Frame index.
        frame: usize,
        /// The tracker's error.
        source: TrackError,
    },
    /// A thread stopped unexpectedly.
    #[error("the {0} thread stopped unexpectedly")]
    Thread(&'static str),
    /// A part the system cannot run without was not given to the [`SystemBuilder`].
    #[error("no {0} given to the system builder")]
    Missing(&'static str),
}

/// Run the whole system over `frames`: a [`SystemBuilder`] with these parts, the default associator
/// (ODA) and ellipsoid method (Tri+Yaw+refine), played to the end with [`System::run`].
///
/// `detector` is `None` for a run without objects. `optimizer` solves the local bundle adjustments and
/// the object fits. `on_frame` sees each frame's record as soon as it is tracked (progress output).
#[allow(clippy::too_many_arguments)]
pub fn run(
    frames: FrameSource,
    tracker: Box<dyn StereoTracker>,
    detector: Option<Box<dyn DetectionSource>>,
    intrinsics: Intrinsics,
    baseline: f64,
    config: &SystemConfig,
    optimizer: SharedOptimizer,
    on_frame: &mut dyn FnMut(&FrameRecord),
) -> Result<RunOutput, SystemError> {
    SystemBuilder::new(intrinsics, baseline)
        .config(*config)
        .source(frames)
        .tracker(tracker)
        .detector(detector)
        .optimizer(optimizer)
        .build()?
        .run(&mut |view| on_frame(view.record))
}
