//! An object of the map ([`MappedObject`]) and its observations ([`Observation`]): the record every
//! other part of the mapper reads and updates.

use nalgebra::Vector3;
use slam_core::{geometry::BBox, ClassId, KeyframeId, PointId, TrackId};
use slam_quadric::{Camera, Ellipsoid};

use super::flow::SceneFlow;

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
    /// The detected class (a track takes boxes of its class group: car, bus and truck are one group).
    pub class: ClassId,
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
    /// Class: the most frequent of its boxes' classes (the earliest on a tie).
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
    pub(super) fitted_at: usize,
    /// Consecutive measured frames whose centroid trend failed the motion test.
    pub(super) motion_strikes: usize,
    /// Its scene-flow readings ([`ObjectMapper::add_flow`]): frame id, frame ids since the frame the
    /// flow started in, the reading.
    pub(super) flows: Vec<(usize, usize, SceneFlow)>,
    /// Consecutive detector frames in which its ellipsoid should have been seen and was not.
    pub(super) misses: usize,
    /// Consecutive tracked frames whose stereo points see free space through its ellipsoid.
    pub(super) free_frames: usize,
    /// Set when the centroid trend flagged it moving: what the trend read, so that its own scene flow
    /// can refute it afterwards ([`ObjectMapper::add_flow`]).
    pub(super) trend_flag: Option<TrendFlag>,
    /// A sample of its stereo points in the frames that measured them (frame id → points in that
    /// frame's left camera, each with its depth σ): the surface cue of its fits. Not kept in a saved map.
    pub(super) surface: std::collections::BTreeMap<usize, Vec<(Vector3<f64>, f64)>>,
    /// How many of its observations come from a map loaded from an earlier run (the first ones).
    pub earlier: usize,
    /// How many times its observations were dropped (a refuted trend flag): a fit job made before
    /// that, answered after, is discarded.
    pub(super) generation: u32,
}

/// What flagged an object moving by its centroid trend: the frame, the trend's rate (world motion per
/// frame id) and that rate's σ along and across `ray`, and whether the object was flagged dynamic
/// before.
#[derive(Debug, Clone, Copy)]
pub(super) struct TrendFlag {
    pub(super) frame: usize,
    pub(super) rate: Vector3<f64>,
    pub(super) rate_sigma: (f64, f64),
    pub(super) ray: Vector3<f64>,
    pub(super) was_dynamic: bool,
}

impl MappedObject {
    /// The most frequent class of its boxes, the earliest seen on a tie (its class when it has none).
    pub fn majority_class(&self) -> ClassId {
        let mut counts: Vec<(ClassId, usize)> = Vec::new();
        for o in &self.observations {
            match counts.iter_mut().find(|c| c.0 == o.class) {
                Some(c) => c.1 += 1,
                None => counts.push((o.class, 1)),
            }
        }
        // max_by_key keeps the last maximum: reversed, the first seen wins a tie
        counts.into_iter().rev().max_by_key(|c| c.1).map_or(self.class, |c| c.0)
    }

    /// A new object of the map: no observation, no ellipsoid, not flagged.
    pub(super) fn new(id: TrackId, class: ClassId) -> Self {
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
            surface: Default::default(),
            earlier: 0,
            generation: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_quadric::Intrinsics;

    #[test]
    fn an_object_takes_the_most_frequent_class_of_its_boxes() {
        let k = Intrinsics::new(721.5, 721.5, 609.6, 172.9);
        let seen = |frame: usize, class: u16| Observation {
            frame,
            camera: Camera::new(k, nalgebra::Isometry3::identity()),
            bbox: BBox::new(600.0, 150.0, 700.0, 220.0),
            class: ClassId(class),
            detection: 0,
            centroid: None,
            depth_sigma: 0.0,
            reference: None,
        };
        let mut van = MappedObject::new(TrackId(4), ClassId(5));
        assert_eq!(van.majority_class(), ClassId(5), "no box yet: its own class");
        // a van called bus first, then car three times and truck twice: a car
        for (f, c) in [(0, 5), (1, 2), (2, 7), (3, 2), (4, 7), (5, 2)] {
            van.observations.push(seen(f, c));
        }
        assert_eq!(van.majority_class(), ClassId(2));
        // a tie goes to the class seen first
        van.observations.push(seen(6, 7));
        assert_eq!(van.majority_class(), ClassId(2));
        van.observations.truncate(2);
        assert_eq!(van.majority_class(), ClassId(5), "bus and car once each: bus came first");
    }
}
