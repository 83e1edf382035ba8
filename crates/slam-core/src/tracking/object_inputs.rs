//! What the object side reads from the stereo tracker, apart from the pose tracking it rides on.
//!
//! Tracking a frame is about the camera: its pose, the keyframe it hands over, the map points it saw
//! ([`TrackedFrame`](super::TrackedFrame)). The objects need more of the same images: the frame's stereo
//! points for their depth in every frame ([`ObjectInputs`], handed over with each tracked frame), and
//! answers about the last frame that only they ask for: optical flow out of the boxes of the frame
//! before, the flow of its stereo points (scene flow) and dense stereo inside given boxes
//! ([`ObjectMeasurements`]). In the other direction the objects tell the tracker where the moving ones
//! are expected ([`MovingRegion`]), so that tracking keeps their keypoints out.
//!
//! [`ObjectMeasurements`] is a trait of its own that every [`StereoTracker`](super::StereoTracker) also
//! implements (a supertrait), rather than a second object the pipeline would hold: its answers are
//! about the tracker's own last frame (its images, keypoints and stereo matches), so one value answers
//! both, and the pipeline keeps a single `Box<dyn StereoTracker>`. Every method has a default that
//! measures nothing, so a tracker with nothing to offer the objects writes an empty `impl`.

use slam_quadric::{nalgebra::Vector3, BBox};

use super::TrackError;
use crate::assoc::PointPair;

/// A stereo point of a tracked frame: where the stereo match puts it and where it was seen. Unlike a
/// [`KeyframePoint`](super::KeyframePoint) it has no map identity (most points of a frame that is not a
/// keyframe never become map points); the pipeline uses them for per-frame object depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FramePoint {
    /// Position in the frame's left-camera frame, metres (from the stereo disparity).
    pub camera_point: Vector3<f64>,
    /// Observation `[u_left, v, u_right]`, pixels.
    pub observation: [f64; 3],
}

/// The part of a tracked frame that only the object side reads
/// ([`TrackedFrame::object_inputs`](super::TrackedFrame::object_inputs)): the frame's stereo points,
/// split by the moving regions the tracker was told about. Both lists are empty from a tracker that
/// does not hand them over.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObjectInputs {
    /// The frame's stereo points off the moving regions: the pipeline reads the depth of detected
    /// objects from them in every frame, not only on keyframes.
    pub points: Vec<FramePoint>,
    /// The stereo points on those moving regions, kept out of tracking, the map and `points`: only the
    /// scene flow reads them, so that an object masked as moving goes on being measured.
    pub masked_points: Vec<FramePoint>,
}

impl ObjectInputs {
    /// Every stereo point of the frame, masked or not: `points`, then `masked_points`.
    pub fn all_points(&self) -> impl Iterator<Item = &FramePoint> {
        self.points.iter().chain(&self.masked_points)
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
/// ([`ObjectMeasurements::box_points`]): where it is and the depths its object can lie at (from the
/// class's sizes and the box's height), so that the search covers only the disparities that depth range
/// allows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxQuery {
    /// The box, left image, pixels.
    pub bbox: BBox,
    /// Nearest and farthest depth of the object, metres (`near` may be 0: no near limit).
    pub depth: (f64, f64),
}

/// What the object side asks a stereo tracker about the last frame it tracked. Each method has a
/// default that measures nothing (empty lists).
pub trait ObjectMeasurements {
    /// Keypoints of the last tracked frame's predecessor followed into the last frame by optical flow
    /// (for the associator's semantic-inlier cue), restricted to `regions` of the predecessor. Trackers
    /// without flow return an empty list (the default).
    fn flow(&mut self, regions: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        let _ = regions;
        Ok(Vec::new())
    }

    /// As [`ObjectMeasurements::flow`], from the keypoints that have a stereo point in the predecessor
    /// (the 3-D motion of objects, scene flow, is read from them). Trackers without stereo points or
    /// flow return an empty list (the default).
    fn stereo_flow(&mut self, regions: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        let _ = regions;
        Ok(Vec::new())
    }

    /// Dense stereo points inside each box of the last tracked frame (one list per query, in the
    /// queries' order): the objects' own points, measured where the object is, whatever the features
    /// tracking chose (which are spread over the image for the pose and leave a distant car a handful).
    /// The points of a list lie inside its box, at the query's depths; each has its observation
    /// `[u_left, v, u_right]`. A tracker without dense stereo returns empty lists (the default): the
    /// objects then read the frame's own stereo points ([`ObjectInputs::points`]).
    fn box_points(&mut self, queries: &[BoxQuery]) -> Result<Vec<Vec<FramePoint>>, TrackError> {
        Ok(vec![Vec::new(); queries.len()])
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
