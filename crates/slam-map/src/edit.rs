//! Edits: the changes a snapshot of the map records, replayed on the live map by [`crate::Map::apply`].
//! Each names its keyframes and points by id, so it means the same on the snapshot and on the map.

use nalgebra::{Isometry3, Vector3};

use crate::{KeyframeId, PointId};

/// One change to the map.
#[derive(Debug, Clone, PartialEq)]
pub enum Edit {
    /// A new point (observations follow as [`Edit::Observe`]).
    AddPoint {
        /// Its id (the snapshot takes ids after the live map's, which makes none in between).
        point: PointId,
        /// World position.
        position: Vector3<f64>,
        /// The keyframe that made it.
        keyframe: KeyframeId,
    },
    /// A keypoint observes a point.
    Observe {
        /// The point.
        point: PointId,
        /// The keyframe.
        keyframe: KeyframeId,
        /// The keypoint.
        keypoint: u32,
    },
    /// An observation removed (an outlier).
    Unobserve {
        /// The point.
        point: PointId,
        /// The keyframe.
        keyframe: KeyframeId,
    },
    /// A point culled.
    RemovePoint {
        /// The point.
        point: PointId,
    },
    /// Two points fused.
    Merge {
        /// The point removed.
        from: PointId,
        /// The point kept.
        into: PointId,
    },
    /// A keyframe moved (bundle adjustment).
    SetPose {
        /// The keyframe.
        keyframe: KeyframeId,
        /// Its pose, world from camera.
        pose: Isometry3<f64>,
    },
    /// A point moved (bundle adjustment).
    SetPosition {
        /// The point.
        point: PointId,
        /// Its position, world frame.
        position: Vector3<f64>,
    },
    /// A keyframe culled.
    RemoveKeyframe {
        /// The keyframe.
        keyframe: KeyframeId,
    },
}
