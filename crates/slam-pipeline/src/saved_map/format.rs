//! The saved map's file format: the serde structs of `map.json` and the versions they read.
//!
//! Poses are stored as `[qx, qy, qz, qw, tx, ty, tz]` (world from camera) and points as `[x, y, z]`,
//! so that the file reads without nalgebra. Field names here are the JSON's: renaming a field renames
//! it in every file written from then on.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use slam_core::{KeyframeId, PointId};

use super::{FeaturesRef, SavedFeatures};

/// Format name written into every map file.
pub const MAP_FORMAT: &str = "quadric-slam-map";
/// The world frame of a map written by the running system (docs/system.md, "Conventions").
pub const MAP_WORLD: &str =
    "world = the left camera of the first frame: x right, y down, z forward, metres; poses world from camera";
/// Version of the map file format. Version 2 added left-only observations (`u_right` written as
/// `null`) of triangulated points; version 3 the keyframes culled from the map (`culled`, kept with their
/// pose as anchors of the frames tracked against them); version 4 the camera the map was made with
/// (`camera`), the keyframes' features in a binary file beside it (`features`: keypoints, descriptors
/// and which point each keypoint observes, [`features`](super::features)) and frames without a pose in the map
/// (`trajectory[i].keyframe` `null`). Earlier versions read unchanged (without features: inspected,
/// exported, not tracked against).
pub const MAP_VERSION: u32 = 4;

/// A pose as stored: quaternion `[qx, qy, qz, qw]` then translation `[tx, ty, tz]`, world from camera.
pub type PoseArray = [f64; 7];

/// Convert a pose to its stored form.
pub fn pose_to_array(p: &Isometry3<f64>) -> PoseArray {
    let q = p.rotation.quaternion();
    let t = p.translation.vector;
    [q.i, q.j, q.k, q.w, t.x, t.y, t.z]
}

/// Convert a stored pose back (the quaternion is re-normalised).
pub fn pose_from_array(a: &PoseArray) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(a[4], a[5], a[6]),
        UnitQuaternion::from_quaternion(Quaternion::new(a[3], a[0], a[1], a[2])),
    )
}

/// A keyframe of the map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedKeyframe {
    /// Frame index in the sequence.
    pub frame: usize,
    /// Pose (world from left camera).
    pub pose: PoseArray,
    /// Parent keyframe (the one it was tracked from); `None` starts a map segment.
    pub parent: Option<KeyframeId>,
    /// Observations `(point, [u_left, v, u_right])`; `u_right` is NaN (`null` in the file) for a
    /// left-only observation of a triangulated point.
    #[serde(with = "observation_list")]
    pub observations: Vec<(PointId, [f64; 3])>,
    /// Culled as redundant: it observes nothing and stays for the frames tracked against it (its pose
    /// follows its parent's). Absent in older files: `false`.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub culled: bool,
}

/// Observations with a NaN right column written as `null` (JSON has no NaN) and read back as NaN.
mod observation_list {
    use super::PointId;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    /// As written: `[point, [u_left, v, u_right or null]]`.
    type Stored = (PointId, (f64, f64, Option<f64>));

    pub fn serialize<S: Serializer>(obs: &[(PointId, [f64; 3])], s: S) -> Result<S::Ok, S::Error> {
        let out: Vec<Stored> =
            obs.iter().map(|(id, o)| (*id, (o[0], o[1], o[2].is_finite().then_some(o[2])))).collect();
        out.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<(PointId, [f64; 3])>, D::Error> {
        let read: Vec<Stored> = Vec::deserialize(d)?;
        Ok(read.into_iter().map(|(id, (u, v, r))| (id, [u, v, r.unwrap_or(f64::NAN)])).collect())
    }
}

/// A JSON object read as a map by id, refusing an id written twice (JSON allows it, and a plain map
/// would keep the last copy in silence: a hand edit that adds a keyframe under an id in use replaced
/// the other one).
mod unique_keys {
    use std::{collections::BTreeMap, fmt, marker::PhantomData};

    use serde::{
        de::{MapAccess, Visitor},
        Deserialize, Deserializer,
    };

    pub fn deserialize<'de, D: Deserializer<'de>, T: Deserialize<'de>>(d: D) -> Result<BTreeMap<u64, T>, D::Error> {
        struct Unique<T>(PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for Unique<T> {
            type Value = BTreeMap<u64, T>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an object of ids")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut access: A) -> Result<Self::Value, A::Error> {
                let mut out = BTreeMap::new();
                while let Some((id, value)) = access.next_entry::<u64, T>()? {
                    if out.insert(id, value).is_some() {
                        return Err(serde::de::Error::custom(format!(
                            "id {id} appears twice (each id is written once; a second copy would replace the first)"
                        )));
                    }
                }
                Ok(out)
            }
        }
        d.deserialize_map(Unique(PhantomData))
    }
}

/// A map point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedMapPoint {
    /// World position, metres.
    pub position: [f64; 3],
    /// Keyframes observing it.
    pub observed_by: Vec<KeyframeId>,
}

/// An object (ellipsoid landmark) of the map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedObject {
    /// Object id.
    pub id: u64,
    /// Class (COCO index).
    pub class: u16,
    /// Its COCO name (written for readers; ignored when read).
    #[serde(default)]
    pub class_name: String,
    /// Centre, world frame, metres.
    pub center: [f64; 3],
    /// Semi-axes along the object's x (length), y (height), z (width), metres.
    pub semi_axes: [f64; 3],
    /// Rotation, world from object, 3×3 row-major.
    pub rotation: [f64; 9],
    /// Frames of its associated detections.
    pub frames: Vec<usize>,
    /// Flagged dynamic (box misfit, size unlike its class, or moving map points).
    pub dynamic: bool,
    /// Its map points moved: a moving object, not mapped (its ellipsoid is the last fit before that was
    /// seen, kept for inspection only). Absent in older files: `false`.
    #[serde(default)]
    pub moving: bool,
    /// Map points on the object (used for its texture planes).
    pub points: Vec<PointId>,
    /// Its detections (earlier runs' first), so that a run that loads the map fits it from both runs'
    /// boxes. Absent in files before version 4.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub views: Vec<ObjectView>,
    /// How many of `views` come from runs before the one that wrote the file (their frames are not in
    /// its trajectory; `frames` lists only that run's).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub earlier_views: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// One detection of an object as stored: the frame, the camera's pose (world from camera), the box
/// `[xmin, ymin, xmax, ymax]` in pixels, the detected class, and the frame's reference keyframe with
/// the frame's pose in it (the fit follows that keyframe's refinement).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectView {
    /// Frame id.
    pub frame: usize,
    /// Camera pose, world from camera.
    pub pose: PoseArray,
    /// The box, pixels.
    pub bbox: [f64; 4],
    /// Detected class (COCO index).
    pub class: u16,
    /// Reference keyframe and the frame's pose in it.
    pub reference: Option<(KeyframeId, PoseArray)>,
}

/// Where a map's world lies in a ground truth: the frame whose left camera is the map's world (its
/// first keyframe's frame) and that camera's pose in the ground truth (its world from the camera), as
/// the run that made the map read them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundTruthWorld {
    /// The frame id.
    pub frame: usize,
    /// Its camera's ground-truth pose, `[qx, qy, qz, qw, tx, ty, tz]`.
    pub pose: PoseArray,
}

/// The pose of one input frame, relative to a keyframe (so it follows the keyframe's refinement).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FramePose {
    /// Frame index.
    pub frame: usize,
    /// Reference keyframe; `None` for a frame not placed in the map (a run in a loaded map before it
    /// localised there: no pose is guessed).
    pub keyframe: Option<KeyframeId>,
    /// Pose of the frame in the keyframe (keyframe from frame; the identity when not placed).
    pub relative: PoseArray,
    /// Tracking state as text (`tracked`, `lost`, `relocalised`, `initialised`, `unreadable`).
    pub state: String,
}

/// The stereo camera a map was made with: the left camera's intrinsics, the baseline and the image
/// size.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapCamera {
    /// Focal lengths and principal point, pixels.
    pub fx: f64,
    /// See `fx`.
    pub fy: f64,
    /// See `fx`.
    pub cx: f64,
    /// See `fx`.
    pub cy: f64,
    /// Baseline, metres.
    pub baseline: f64,
    /// Image width, pixels.
    pub width: f64,
    /// Image height, pixels.
    pub height: f64,
}

/// A saved map: its keyframes, points, objects and per-frame trajectory as the file holds them (the
/// keyframes' features come from the features file beside it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedMap {
    /// Always [`MAP_FORMAT`].
    pub format: String,
    /// Always [`MAP_VERSION`] when written by this version.
    pub version: u32,
    /// The world frame, in words ([`MAP_WORLD`]; absent in older files).
    #[serde(default)]
    pub frame: String,
    /// Keyframes by id (an id written twice is refused, not the last one taken).
    #[serde(deserialize_with = "unique_keys::deserialize")]
    pub keyframes: BTreeMap<KeyframeId, SavedKeyframe>,
    /// Map points by id (as `keyframes`).
    #[serde(deserialize_with = "unique_keys::deserialize")]
    pub points: BTreeMap<PointId, SavedMapPoint>,
    /// Objects, by id.
    pub objects: Vec<SavedObject>,
    /// One entry per input frame, in order.
    pub trajectory: Vec<FramePose>,
    /// The stereo camera the map was made with (absent in files before version 4).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<MapCamera>,
    /// The keyframes' features file beside this one (absent before version 4, or without keyframes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub features: Option<FeaturesRef>,
    /// The map's world in the ground truth of the run that made it (absent when that run had none, and
    /// in files written before issue 46): figures of later runs in the map's frame compare against
    /// the ground truth expressed in this world.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_truth_world: Option<GroundTruthWorld>,
    /// The keyframes' features (from the features file; written there by [`SavedMap::save`]).
    #[serde(skip)]
    pub keyframe_features: BTreeMap<KeyframeId, SavedFeatures>,
}

impl Default for SavedMap {
    fn default() -> Self {
        Self {
            format: MAP_FORMAT.to_string(),
            version: MAP_VERSION,
            frame: MAP_WORLD.to_string(),
            keyframes: BTreeMap::new(),
            points: BTreeMap::new(),
            objects: Vec::new(),
            trajectory: Vec::new(),
            camera: None,
            features: None,
            ground_truth_world: None,
            keyframe_features: BTreeMap::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_arrays_round_trip() {
        let p =
            Isometry3::from_parts(Translation3::new(-1.0, 0.5, 2.0), UnitQuaternion::from_euler_angles(0.4, 0.2, -1.0));
        let q = pose_from_array(&pose_to_array(&p));
        assert!((p.to_homogeneous() - q.to_homogeneous()).abs().max() < 1e-12);
    }
}
