//! The tracking contract: the visual front end as the pipeline sees it.
//!
//! A [`StereoTracker`] turns rectified stereo pairs into camera poses against the map it is shown
//! ([`slam_map::Map`], which the pipeline owns and changes), and on keyframes hands over the new
//! keyframe (its features and the map points its keypoints matched) for the pipeline to insert. The
//! pipeline (`slam-pipeline`) depends on this trait only; the OpenCV implementation lives in
//! `slam-frontend`.

use slam_quadric::{
    nalgebra::{Isometry3, Vector3},
    BBox,
};

use crate::{assoc::PointPair, source::Image};

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

/// A stereo point of a tracked frame: where the stereo match puts it and where it was seen. Unlike a
/// [`KeyframePoint`] it has no map identity (most points of a frame that is not a keyframe never
/// become map points); the pipeline uses them for per-frame object depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FramePoint {
    /// Position in the frame's left-camera frame, metres (from the stereo disparity).
    pub camera_point: Vector3<f64>,
    /// Observation `[u_left, v, u_right]`, pixels.
    pub observation: [f64; 3],
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
    /// Those stereo points (empty from a tracker that does not hand them over): the pipeline reads the
    /// depth of detected objects from them in every frame, not only on keyframes. Without the points on
    /// the moving regions the tracker was told about.
    pub points: Vec<FramePoint>,
    /// The stereo points on those moving regions, kept out of tracking, the map and `points` (empty
    /// from a tracker that does not hand them over): only the scene flow reads them, so that an object
    /// masked as moving goes on being measured.
    pub masked_points: Vec<FramePoint>,
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

/// Where a moving object is expected in a frame: its box (left image) and, when its stereo points
/// measured it, the depths it spans. A keypoint inside the box belongs to the object unless its
/// stereo depth lies outside `depth` (the background seen around the object or through an oversized
/// box stays usable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovingRegion {
    /// The box, pixels.
    pub bbox: BBox,
    /// Nearest and farthest depth of the object, metres (`None`: unknown, the whole box is the object).
    pub depth: Option<(f64, f64)>,
}

impl MovingRegion {
    /// Whether a keypoint at `(u, v)` with stereo depth `z` (if any) belongs to the object.
    pub fn covers(&self, u: f64, v: f64, z: Option<f64>) -> bool {
        self.bbox.contains_point(u, v)
            && match (self.depth, z) {
                (Some((near, far)), Some(z)) => (near..=far).contains(&z),
                _ => true,
            }
    }
}

/// A box of the last tracked frame whose own stereo points are asked for
/// ([`StereoTracker::box_points`]): where it is and the depths its object can lie at (from the class's
/// sizes and the box's height), so that the search covers only the disparities that depth range allows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxQuery {
    /// The box, left image, pixels.
    pub bbox: BBox,
    /// Nearest and farthest depth of the object, metres (`near` may be 0: no near limit).
    pub depth: (f64, f64),
}

/// A stereo visual front end.
pub trait StereoTracker: Send {
    /// Track one rectified stereo pair against `map`. Keypoints on the `exclude` regions (moving
    /// objects) are not used for the pose, the map or [`TrackedFrame::points`]. The map changes only
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

    /// Keypoints of the last tracked frame's predecessor followed into the last frame by optical flow
    /// (for the associator's semantic-inlier cue), restricted to `regions` of the predecessor. Trackers
    /// without flow return an empty list.
    fn flow(&mut self, regions: &[BBox]) -> Result<Vec<PointPair>, TrackError>;

    /// As [`StereoTracker::flow`], from the keypoints that have a stereo point in the predecessor (the
    /// 3-D motion of objects, scene flow, is read from them). Trackers without stereo points or flow
    /// return an empty list (the default).
    fn stereo_flow(&mut self, regions: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        let _ = regions;
        Ok(Vec::new())
    }

    /// Dense stereo points inside each box of the last tracked frame (one list per query, in the
    /// queries' order): the objects' own points, measured where the object is, whatever the features
    /// tracking chose (which are spread over the image for the pose and leave a distant car a handful).
    /// The points of a list lie inside its box, at the query's depths; each has its observation
    /// `[u_left, v, u_right]`. A tracker without dense stereo returns empty lists (the default): the
    /// objects then read the frame's own stereo points ([`TrackedFrame::points`]).
    fn box_points(&mut self, queries: &[BoxQuery]) -> Result<Vec<Vec<FramePoint>>, TrackError> {
        Ok(vec![Vec::new(); queries.len()])
    }
    /// The run starts in `map`, loaded from an earlier run: get ready to localise in it before the
    /// first frame (e.g. index its keyframes for retrieval), so that loading, not the first frame,
    /// pays for it. Called once, before [`StereoTracker::track`]; trackers that need nothing do
    /// nothing (the default).
    fn load_map(&mut self, map: &Map) {
        let _ = map;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A moving region covers keypoints inside its box at the object's depths, and those without a
    /// stereo depth; the background seen around the object (same box, other depth) stays usable; with
    /// no depth known the whole box is the object.
    #[test]
    fn a_moving_region_covers_its_object_and_not_the_background_in_its_box() {
        let b = BBox::new(100.0, 50.0, 300.0, 200.0);
        let r = MovingRegion { bbox: b, depth: Some((10.0, 16.0)) };
        assert!(r.covers(150.0, 100.0, Some(12.0)));
        assert!(r.covers(150.0, 100.0, None));
        assert!(!r.covers(150.0, 100.0, Some(35.0)), "the street behind the car");
        assert!(!r.covers(150.0, 100.0, Some(5.0)), "a post in front of it");
        assert!(!r.covers(350.0, 100.0, Some(12.0)), "outside the box");
        let whole = MovingRegion { bbox: b, depth: None };
        assert!(whole.covers(150.0, 100.0, Some(35.0)));
    }
}
