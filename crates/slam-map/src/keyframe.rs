//! Keyframes: a frame kept in the map, with its ORB features (fixed once measured, shared between the
//! live map and its snapshots) and the map point each keypoint observes.

use std::sync::Arc;

use nalgebra::{Isometry3, Vector3};

use crate::{camera::StereoCamera, descriptor::Descriptor, grid::KeypointGrid, KeyframeId, PointId};

/// A left-image keypoint: its position (level-0 pixels), pyramid level, orientation (degrees), and the
/// column of its stereo match in the right image (NaN: no stereo match).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keypoint {
    /// Column, pixels.
    pub u: f64,
    /// Row, pixels.
    pub v: f64,
    /// Column of the stereo match in the right image, pixels (NaN when there is none).
    pub u_right: f64,
    /// Pyramid level it was detected on.
    pub level: u8,
    /// Orientation, degrees.
    pub angle: f32,
}

impl Keypoint {
    /// Whether it has a stereo match.
    pub fn is_stereo(&self) -> bool {
        self.u_right.is_finite()
    }

    /// Its observation `[u_l, v, u_r]` (`u_r` NaN without a stereo match).
    pub fn observation(&self) -> [f64; 3] {
        [self.u, self.v, self.u_right]
    }

    /// Its stereo depth, metres, when it has a stereo match with a positive disparity.
    pub fn depth(&self, camera: &StereoCamera) -> Option<f64> {
        let d = self.u - self.u_right;
        (d.is_finite() && d > 0.0).then(|| camera.focal_baseline() / d)
    }

    /// Its stereo point in the camera frame.
    pub fn stereo_point(&self, camera: &StereoCamera) -> Option<Vector3<f64>> {
        let d = self.u - self.u_right;
        (d.is_finite() && d > 0.0).then(|| camera.point(self.u, self.v, d))
    }
}

/// The features of a keyframe's left image: every keypoint with its descriptor, and a grid over them
/// for projection searches. Never changed once measured.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Features {
    /// The keypoints.
    pub keypoints: Vec<Keypoint>,
    /// Their descriptors (one per keypoint).
    pub descriptors: Vec<Descriptor>,
    /// The keypoints in cells.
    pub grid: KeypointGrid,
    /// Size of the image, pixels (width, height).
    pub size: (f64, f64),
}

impl Features {
    /// Features of an image of `size` (width, height) from keypoints and their descriptors (the grid
    /// is built here); `None` when the two lists differ in length.
    pub fn new(keypoints: Vec<Keypoint>, descriptors: Vec<Descriptor>, size: (f64, f64)) -> Option<Self> {
        if keypoints.len() != descriptors.len() {
            return None;
        }
        let at: Vec<(f64, f64)> = keypoints.iter().map(|k| (k.u, k.v)).collect();
        Some(Self { grid: KeypointGrid::new(&at), keypoints, descriptors, size })
    }

    /// Whether `(u, v)` lies inside the image.
    pub fn in_image(&self, u: f64, v: f64) -> bool {
        u >= 0.0 && v >= 0.0 && u < self.size.0 && v < self.size.1
    }

    /// Number of keypoints.
    pub fn len(&self) -> usize {
        self.keypoints.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.keypoints.is_empty()
    }
}

/// A keyframe of the map.
#[derive(Debug, Clone)]
pub struct Keyframe {
    /// Its id (unique within a map, never reused).
    pub id: KeyframeId,
    /// The input frame it was made from.
    pub frame: usize,
    /// Pose of its left camera, world from camera.
    pub pose: Isometry3<f64>,
    /// The keyframe it was tracked from (its parent in the spanning tree); `None` starts a map
    /// segment.
    pub parent: Option<KeyframeId>,
    /// Its features.
    pub features: Arc<Features>,
    /// The map point each keypoint observes.
    pub points: Vec<Option<PointId>>,
}

impl Keyframe {
    /// A keyframe observing no map point yet.
    pub fn new(
        id: KeyframeId,
        frame: usize,
        pose: Isometry3<f64>,
        parent: Option<KeyframeId>,
        features: Arc<Features>,
    ) -> Self {
        let points = vec![None; features.len()];
        Self { id, frame, pose, parent, features, points }
    }

    /// Centre of its camera, world frame.
    pub fn centre(&self) -> Vector3<f64> {
        self.pose.translation.vector
    }

    /// Number of keypoints observing a map point.
    pub fn observed(&self) -> usize {
        self.points.iter().filter(|p| p.is_some()).count()
    }

    /// The map points it observes with their keypoints, in keypoint order.
    pub fn observations(&self) -> impl Iterator<Item = (usize, PointId)> + '_ {
        self.points.iter().enumerate().filter_map(|(i, p)| p.map(|p| (i, p)))
    }

    /// The median depth of the map points it observes (`positions` gives a point's world position), or
    /// `None` when it observes none.
    pub fn median_depth(&self, positions: impl Fn(PointId) -> Option<Vector3<f64>>) -> Option<f64> {
        let from_world = self.pose.inverse();
        let mut z: Vec<f64> = self
            .observations()
            .filter_map(|(_, p)| positions(p))
            .map(|x| (from_world * nalgebra::Point3::from(x)).z)
            .collect();
        if z.is_empty() {
            return None;
        }
        z.sort_by(f64::total_cmp);
        Some(z[z.len() / 2])
    }
}
