//! Map points: a place in the world seen by one or more keyframes, with what a search needs to find it
//! again from another view (a representative descriptor, the mean viewing direction, the distances
//! over which its scale can be detected) and the counts that decide whether a young point stays.

use nalgebra::Vector3;

use crate::{descriptor::Descriptor, KeyframeId};

/// One observation of a map point: the keyframe, its keypoint, and the keypoint's pyramid level.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Observation {
    /// The observing keyframe.
    pub keyframe: KeyframeId,
    /// Index of the keypoint in the keyframe's features.
    pub keypoint: u32,
    /// The keypoint's pyramid level.
    pub level: u8,
}

/// A map point.
#[derive(Debug, Clone, PartialEq)]
pub struct MapPoint {
    /// Position, world frame, metres.
    pub position: Vector3<f64>,
    /// Its representative descriptor (the medoid of its observations' descriptors).
    pub descriptor: Descriptor,
    /// Mean unit direction from the observing cameras to the point.
    pub normal: Vector3<f64>,
    /// Nearest and farthest distance at which its scale can be detected, metres.
    pub distance: (f64, f64),
    /// Its observations, by keyframe id (at most one per keyframe).
    pub observations: Vec<Observation>,
    /// The keyframe that made it.
    pub first_keyframe: KeyframeId,
    /// How many keyframes had been inserted into the map when it was made (its age is counted in
    /// keyframes inserted since).
    pub born: u64,
    /// Tracked frames whose view it lay in (projected inside the image, within its distance range and
    /// viewing angle).
    pub visible: u32,
    /// Tracked frames in which it was matched and kept by the pose refinement.
    pub found: u32,
}

impl MapPoint {
    /// A point at `position` made by `keyframe`, no observation yet (descriptor, normal and range are
    /// set when it is refreshed).
    pub fn new(position: Vector3<f64>, keyframe: KeyframeId, born: u64) -> Self {
        Self {
            position,
            descriptor: [0; 32],
            normal: Vector3::zeros(),
            distance: (0.0, f64::INFINITY),
            observations: Vec::new(),
            first_keyframe: keyframe,
            born,
            visible: 1,
            found: 1,
        }
    }

    /// Its observation in `keyframe`, if any.
    pub fn observation(&self, keyframe: KeyframeId) -> Option<&Observation> {
        self.observations.binary_search_by_key(&keyframe, |o| o.keyframe).ok().map(|i| &self.observations[i])
    }

    /// Number of keyframes observing it.
    pub fn seen_by(&self) -> usize {
        self.observations.len()
    }

    /// Share of the frames whose view it lay in that matched it (`found / visible`).
    pub fn found_ratio(&self) -> f64 {
        self.found as f64 / self.visible.max(1) as f64
    }

    /// Whether a camera at `centre` looks at it within its detectable distance range (widened by
    /// `slack` on both sides) and within `max_angle_cos` of its mean viewing direction; returns the
    /// distance when it does.
    pub fn viewable_from(&self, centre: &Vector3<f64>, slack: f64, max_angle_cos: f64) -> Option<f64> {
        let ray = self.position - centre;
        let distance = ray.norm();
        let (min, max) = self.distance;
        if distance < min / slack || distance > max * slack || distance <= 0.0 {
            return None;
        }
        let cos = ray.dot(&self.normal) / distance;
        (self.normal.norm_squared() == 0.0 || cos >= max_angle_cos).then_some(distance)
    }
}
