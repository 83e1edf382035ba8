//! The map database and the live map of a run ([`slam_core::Map`]): the file's form of a run's map
//! ([`Map::from_live`]), and a live map rebuilt from a file for a later run to track against and
//! extend ([`Map::to_live`]), after checking that the run's camera is the one the map was made with.

use std::sync::Arc;

use nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};
use slam_core::{
    map::{Features, Keyframe, SavedPoint, StereoCamera},
    KeyframeId,
};

use super::{pose_from_array, pose_to_array, Map, MapKeyframe, MapObject, MapPoint, SavedFeatures};

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

impl MapCamera {
    /// The camera of a rig with images of `size` (width, height).
    pub fn of(camera: &StereoCamera, size: (f64, f64)) -> Self {
        let k = &camera.k;
        Self { fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy, baseline: camera.baseline, width: size.0, height: size.1 }
    }

    /// Where this camera differs from `other`, in words (empty: the same camera). Calibration files
    /// give these numbers to 6 or more significant digits; a relative difference above 1e-6 (a
    /// thousandth of a pixel at 1 000 px) is another calibration.
    pub fn differences(&self, other: &MapCamera) -> Vec<String> {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * a.abs().max(b.abs()).max(1.0);
        let mut out = Vec::new();
        for (name, a, b, unit) in [
            ("fx", self.fx, other.fx, "px"),
            ("fy", self.fy, other.fy, "px"),
            ("cx", self.cx, other.cx, "px"),
            ("cy", self.cy, other.cy, "px"),
            ("baseline", self.baseline, other.baseline, "m"),
        ] {
            if !close(a, b) {
                out.push(format!("{name} {a} {unit} in the map, {b} {unit} here"));
            }
        }
        if (self.width, self.height) != (other.width, other.height) {
            out.push(format!(
                "images {}×{} in the map, {}×{} here",
                self.width, self.height, other.width, other.height
            ));
        }
        out
    }
}

/// The run's camera is not the one the map was made with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the map was made with another camera: {}", .0.join("; "))]
pub struct CameraMismatch(pub Vec<String>);

/// A map file rebuilt as a live map for a run to track against.
#[derive(Debug, Clone)]
pub struct LoadedMap {
    /// The live map: keyframes with their features, points, covisibility.
    pub map: slam_core::Map,
    /// The objects, as stored.
    pub objects: Vec<MapObject>,
    /// The keyframes' keypoints were re-expressed in the run's camera (another calibration of a
    /// rectified rig, accepted for localisation only).
    pub reexpressed: bool,
}

/// Why a map file cannot be tracked against.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ToLiveError {
    /// A file without features (written before version 4).
    #[error("the map has no keyframe features to track against (format version {0}; version 4 and later keep them): make the map again with this build")]
    NoFeatures(u32),
    /// A file without the camera it was made with.
    #[error("the map does not say which camera it was made with (format version {0})")]
    NoCamera(u32),
    /// Another camera.
    #[error(transparent)]
    Camera(#[from] CameraMismatch),
    /// The saved keyframes and points do not make a consistent map.
    #[error("{0}")]
    Inconsistent(#[from] slam_core::map::RestoreError),
}

impl Map {
    /// The database of a run's live map (`slam_core::Map`): its keyframes with their observations and
    /// features, the keyframes culled from it (at their poses, without observations, marked culled),
    /// its points, its camera; no objects and no trajectory yet.
    pub fn from_live(live: &slam_core::Map) -> Self {
        let mut m = Map::default();
        for k in live.keyframes() {
            let observations = k.observations().map(|(kp, p)| (p, k.features.keypoints[kp].observation())).collect();
            let stored = MapKeyframe {
                frame: k.frame,
                pose: pose_to_array(&k.pose),
                parent: k.parent,
                observations,
                culled: false,
            };
            m.keyframes.insert(k.id, stored);
            let f = &k.features;
            let saved = SavedFeatures {
                size: f.size,
                keypoints: f.keypoints.clone(),
                descriptors: f.descriptors.clone(),
                observations: k.observations().map(|(kp, p)| (kp as u32, p)).collect(),
            };
            m.camera.get_or_insert(MapCamera::of(live.camera(), f.size));
            m.keyframe_features.insert(k.id, saved);
        }
        for (&id, r) in live.retired() {
            let pose = live.keyframe_pose(id).unwrap_or_else(Isometry3::identity);
            let stored = MapKeyframe {
                frame: r.frame,
                pose: pose_to_array(&pose),
                parent: Some(r.parent),
                observations: Vec::new(),
                culled: true,
            };
            m.keyframes.insert(id, stored);
        }
        for (id, p) in live.points() {
            let observed_by: Vec<KeyframeId> =
                p.observations.iter().map(|o| o.keyframe).filter(|k| live.keyframe(*k).is_some()).collect();
            m.points.insert(id, MapPoint { position: [p.position.x, p.position.y, p.position.z], observed_by });
        }
        m
    }

    /// The live map a run with `camera` tracks against: the keyframes that are not culled, with their
    /// features and observations, and the points (their descriptors, viewing directions and distance
    /// ranges recomputed, [`slam_core::Map::restore`]); the culled keyframes and the trajectory stay
    /// behind (they anchor the earlier run's frames, not this run's). With `reexpress`, a map made
    /// with another calibration of a rectified stereo rig is accepted: each keypoint is moved to where
    /// the run's camera sees the same ray (and its right-image position to the disparity the run's
    /// focal length and baseline give the same depth), exact for rectified pinhole images.
    pub fn to_live(&self, run: &MapCamera, reexpress: bool) -> Result<LoadedMap, ToLiveError> {
        if self.keyframe_features.is_empty() {
            return Err(ToLiveError::NoFeatures(self.version));
        }
        let made = self.camera.ok_or(ToLiveError::NoCamera(self.version))?;
        let differences = made.differences(run);
        if !(differences.is_empty() || reexpress) {
            return Err(CameraMismatch(differences).into());
        }
        let moved = !differences.is_empty();
        let (sx, sy) = (run.fx / made.fx, run.fy / made.fy);
        let disparity = (run.fx * run.baseline) / (made.fx * made.baseline);
        let mut keyframes = Vec::with_capacity(self.keyframe_features.len());
        for (&id, f) in &self.keyframe_features {
            let Some(k) = self.keyframes.get(&id) else { continue };
            let mut keypoints = f.keypoints.clone();
            if moved {
                for kp in &mut keypoints {
                    let d = kp.u - kp.u_right;
                    kp.u = sx * (kp.u - made.cx) + run.cx;
                    kp.v = sy * (kp.v - made.cy) + run.cy;
                    kp.u_right = kp.u - d * disparity;
                }
            }
            let size = if moved { (run.width, run.height) } else { f.size };
            let features = Features::new(keypoints, f.descriptors.clone(), size).ok_or_else(|| {
                slam_core::map::RestoreError::Keyframe { id, why: "keypoints and descriptors differ in number".into() }
            })?;
            let mut kf = Keyframe::new(id, k.frame, pose_from_array(&k.pose), k.parent, Arc::new(features));
            for &(kp, p) in &f.observations {
                if let Some(slot) = kf.points.get_mut(kp as usize) {
                    *slot = Some(p);
                }
            }
            keyframes.push(kf);
        }
        let points: Vec<SavedPoint> = self
            .points
            .iter()
            .map(|(&id, p)| SavedPoint {
                id,
                position: Vector3::from(p.position),
                first_keyframe: p.observed_by.iter().copied().min().unwrap_or(0),
            })
            .collect();
        let camera = StereoCamera { k: slam_core::geometry::Intrinsics::new(run.fx, run.fy, run.cx, run.cy), baseline: run.baseline };
        let map = slam_core::Map::restore(camera, slam_core::map::ScalePyramid::default(), keyframes, &points)?;
        Ok(LoadedMap { map, objects: self.objects.clone(), reexpressed: moved })
    }
}
