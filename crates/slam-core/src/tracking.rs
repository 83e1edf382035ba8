//! The tracking contract: the visual front end as the pipeline sees it.
//!
//! A [`StereoTracker`] turns rectified stereo pairs into camera poses against the map it is shown
//! ([`slam_map::Map`], which the pipeline owns and changes), and on keyframes hands over the new
//! keyframe (its features and the map points its keypoints matched) for the pipeline to insert. The
//! pipeline (`slam-pipeline`) depends on this trait only; the OpenCV implementation lives in
//! `slam-frontend`.
//!
//! This module is the pose tracking: [`StereoTracker::track`] and what it returns for the map side
//! ([`TrackedFrame`]: pose, reference, state, keyframe, sightings, times). What the object side reads
//! of the same frames is in [`object_inputs`]: the frame's stereo points handed over with each frame
//! ([`ObjectInputs`], the one field [`TrackedFrame::object_inputs`]), the questions about the last
//! frame ([`ObjectMeasurements`], a supertrait of [`StereoTracker`]) and the moving regions tracking is
//! told to keep out ([`MovingRegion`]).

use slam_quadric::nalgebra::{Isometry3, Vector3};

use crate::source::Image;

pub mod object_inputs;

pub use object_inputs::{BoxQuery, FramePoint, MovingRegion, ObjectInputs, ObjectMeasurements};
pub use slam_map::{KeyframeId, Map, NewKeyframe, PointId};

/// One observation of a map point in a keyframe: stereo, or left image only for a point triangulated
/// from two keyframes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeyframePoint {
    /// The map point.
    pub id: PointId,
    /// Position in the keyframe's left-camera frame, metres (from the stereo disparity, or triangulated).
    pub camera_point: Vector3<f64>,
    /// Observation `[u_left, v, u_right]`, pixels; `u_right` is NaN for a left-only observation.
    pub observation: [f64; 3],
}

impl KeyframePoint {
    /// Whether the observation has a right-image column (a stereo observation).
    pub fn is_stereo(&self) -> bool {
        self.observation[2].is_finite()
    }
}

/// Tracking outcome of a frame.
///
/// Only [`Initialised`](Self::Initialised), [`Tracked`](Self::Tracked), [`Weak`](Self::Weak) and
/// [`Relocalised`](Self::Relocalised) frames carry a measured pose ([`TrackState::is_measured`]); a
/// [`Predicted`](Self::Predicted) or [`Lost`](Self::Lost) frame's pose is the motion model's prediction,
/// written so that every input frame has a pose, and marked as such.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackState {
    /// First frame of a map segment (the world origin for the first segment).
    Initialised,
    /// Tracked against the local map with full support.
    Tracked {
        /// Inliers of the final pose refinement.
        inliers: usize,
    },
    /// Tracked and accepted, but with less support than a tracked frame (fewer inliers, or inliers
    /// crowded into a small part of the image): the pose is used, and a keyframe is taken.
    Weak {
        /// Inliers of the final pose refinement.
        inliers: usize,
    },
    /// A pose was measured but failed the sanity checks (support or consistency with the motion model),
    /// so it was rejected: the pose is the motion-model prediction.
    Predicted,
    /// Tracking and relocalisation failed: the pose is the motion-model prediction.
    Lost,
    /// Tracking failed on the previous frame(s) and was recovered by relocalisation against the map's
    /// keyframes.
    Relocalised {
        /// Inliers of the final pose refinement.
        inliers: usize,
    },
}

impl TrackState {
    /// Name used in `tracking.csv` and the map's trajectory.
    pub fn name(&self) -> &'static str {
        match self {
            TrackState::Initialised => "initialised",
            TrackState::Tracked { .. } => "tracked",
            TrackState::Weak { .. } => "weak",
            TrackState::Predicted => "predicted",
            TrackState::Lost => "lost",
            TrackState::Relocalised { .. } => "relocalised",
        }
    }

    /// Whether the pose was measured from the images (and accepted), rather than predicted.
    pub fn is_measured(&self) -> bool {
        !matches!(self, TrackState::Predicted | TrackState::Lost)
    }

    /// Inliers of the accepted pose (0 when none was accepted).
    pub fn inliers(&self) -> usize {
        match self {
            TrackState::Tracked { inliers } | TrackState::Weak { inliers } | TrackState::Relocalised { inliers } => {
                *inliers
            }
            _ => 0,
        }
    }
}

/// Per-stage time of one frame, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageTimes {
    /// Feature extraction (both images).
    pub extraction: f64,
    /// Stereo matching.
    pub stereo: f64,
    /// Frame tracking (matching, PnP, pose refinement).
    pub tracking: f64,
}

/// Result of tracking one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackedFrame {
    /// Pose of the left camera, world from camera.
    pub world_from_camera: Isometry3<f64>,
    /// The reference keyframe the pose was computed against, and the pose relative to it (so that the
    /// final trajectory can follow keyframe corrections).
    pub reference: (KeyframeId, Isometry3<f64>),
    /// What happened.
    pub state: TrackState,
    /// Stereo points found in this frame.
    pub stereo_points: usize,
    /// Those stereo points as the object side reads them (nothing of the pose tracking uses them).
    pub object_inputs: ObjectInputs,
    /// Map points matched in this frame and kept by the pose refinement (reference keyframe and local
    /// map together; 0 when no pose was accepted).
    pub tracked_map_points: usize,
    /// RMS reprojection error of those points in the left image at the accepted pose, pixels (NaN when
    /// no pose was accepted).
    pub reprojection_rms_px: f64,
    /// Set when this frame becomes a keyframe: the keyframe for the pipeline to insert into the map
    /// (its id is the map's next one).
    pub keyframe: Option<NewKeyframe>,
    /// Map points that lay in the frame's view at its accepted pose (inside the image, within their
    /// distance range and viewing angle) and those of them matched and kept: the counts that decide
    /// whether a young map point stays ([`slam_map::Map::count_sightings`]). Empty when no pose was
    /// accepted.
    pub sightings: Sightings,
    /// Stage timings.
    pub times: StageTimes,
    /// The frame has a pose in the map. False only in a map loaded from an earlier run until the
    /// frame is placed there (relocalised with a verified pose): its `world_from_camera` and
    /// `reference` are then not a pose, and the frame is written without one (its state is
    /// [`TrackState::Lost`]).
    pub placed: bool,
    /// A frame not placed but tracked in a map segment of its own frame (started beside a loaded map
    /// before any frame was placed there): that segment's first keyframe. Its `reference` is then a
    /// pose in the segment, which becomes one in the map's frame when the segment joins the map
    /// ([`TrackedFrame::joined`]).
    pub segment: Option<KeyframeId>,
    /// This frame, tracked in such a segment, was placed in the map: the segment joins it
    /// ([`SegmentJoin`]). The frame itself is placed (its pose in the map's frame).
    pub joined: Option<SegmentJoin>,
}

/// A map segment tracked in a frame of its own joins the map: a frame tracked in it was placed in the
/// map (verified by retrieval, as a run's first frame in a loaded map is), so the two poses of that
/// frame give the transform between the two frames (as ORB-SLAM3's atlas merges a map into another
/// where a place of both is recognised). The map's owner moves the segment's keyframes and points
/// into the map's frame ([`slam_map::Map::join_segment`]), and the frames tracked in the segment get
/// their poses there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentJoin {
    /// The segment's first keyframe (the segment: the keyframes from it on).
    pub root: KeyframeId,
    /// The segment's frame in the map's: map world from segment world.
    pub map_from_segment: Isometry3<f64>,
    /// The keyframe of the map the frame was placed against (the segment's first keyframe's parent
    /// from now on).
    pub anchor: KeyframeId,
}

/// The map points a frame's view held and those it found ([`TrackedFrame::sightings`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Sightings {
    /// In the view.
    pub visible: Vec<PointId>,
    /// Matched and kept.
    pub found: Vec<PointId>,
}

/// Errors a tracker reports (a failed frame is not an error but [`TrackState::Lost`]). Marked
/// non-exhaustive so that failure kinds can be added without breaking callers' matches.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TrackError {
    /// The tracker's backend (image library, optimiser) failed; the cause is the error's source.
    #[error("{0}")]
    Backend(#[source] Box<dyn std::error::Error + Send + Sync>),
}

impl TrackError {
    /// A backend failure.
    pub fn backend(e: impl std::error::Error + Send + Sync + 'static) -> Self {
        TrackError::Backend(Box::new(e))
    }
}

/// A stereo visual front end: pose tracking against the map. The questions the object side asks about
/// the last tracked frame come with it ([`ObjectMeasurements`], a supertrait).
pub trait StereoTracker: ObjectMeasurements + Send {
    /// Track one rectified stereo pair against `map`. Keypoints on the `exclude` regions (moving
    /// objects) are not used for the pose, the map or [`ObjectInputs::points`]. The map changes only
    /// between calls, by its owner (a keyframe handed over is inserted before the next call, local
    /// mapping's edits are applied at moments that do not depend on thread timing), so runs are
    /// reproducible.
    fn track(
        &mut self,
        frame: usize,
        left: &Image,
        right: &Image,
        exclude: &[MovingRegion],
        map: &Map,
    ) -> Result<TrackedFrame, TrackError>;

    /// The run starts in `map`, loaded from an earlier run: get ready to localise in it before the
    /// first frame (e.g. index its keyframes for retrieval), so that loading, not the first frame,
    /// pays for it. Called once, before [`StereoTracker::track`]; trackers that need nothing do
    /// nothing (the default).
    fn load_map(&mut self, map: &Map) {
        let _ = map;
    }
}
