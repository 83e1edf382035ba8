//! The map database: keyframes, map points, objects and the per-frame trajectory, with a versioned
//! JSON file format written atomically.
//!
//! One owner (the local-mapping thread) mutates the map; other threads get snapshots (`Clone`). Poses
//! are stored as `[qx, qy, qz, qw, tx, ty, tz]` (world from camera), points as `[x, y, z]`, so the file
//! reads without nalgebra.

use std::{
    collections::BTreeMap,
    path::{Path, PathBuf},
};

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use slam_core::{KeyframeId, PointId};

pub mod features;
mod live;

pub use features::{FeaturesRef, SavedFeatures};
pub use live::{CameraMismatch, LoadedMap, MapCamera, ToLiveError};

/// Format name written into every map file.
pub const MAP_FORMAT: &str = "quadric-slam-map";
/// The world frame of a map written by the running system (docs/system.md, "Conventions").
pub const MAP_WORLD: &str =
    "world = the left camera of the first frame: x right, y down, z forward, metres; poses world from camera";
/// Version of the map file format. Version 2 added left-only observations (`u_right` written as
/// `null`) of triangulated points; version 3 the keyframes culled from the map (`culled`, kept with their
/// pose as anchors of the frames tracked against them); version 4 the camera the map was made with
/// (`camera`), the keyframes' features in a binary file beside it (`features`: keypoints, descriptors
/// and which point each keypoint observes, [`features`]) and frames without a pose in the map
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
pub struct MapKeyframe {
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
pub struct MapPoint {
    /// World position, metres.
    pub position: [f64; 3],
    /// Keyframes observing it.
    pub observed_by: Vec<KeyframeId>,
}

/// An object (ellipsoid landmark) of the map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapObject {
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

/// The map database.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Map {
    /// Always [`MAP_FORMAT`].
    pub format: String,
    /// Always [`MAP_VERSION`] when written by this version.
    pub version: u32,
    /// The world frame, in words ([`MAP_WORLD`]; absent in older files).
    #[serde(default)]
    pub frame: String,
    /// Keyframes by id (an id written twice is refused, not the last one taken).
    #[serde(deserialize_with = "unique_keys::deserialize")]
    pub keyframes: BTreeMap<KeyframeId, MapKeyframe>,
    /// Map points by id (as `keyframes`).
    #[serde(deserialize_with = "unique_keys::deserialize")]
    pub points: BTreeMap<PointId, MapPoint>,
    /// Objects, by id.
    pub objects: Vec<MapObject>,
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
    /// The keyframes' features (from the features file; written there by [`Map::save`]).
    #[serde(skip)]
    pub keyframe_features: BTreeMap<KeyframeId, SavedFeatures>,
}

impl Default for Map {
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

/// Why a map could not be saved or loaded.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// File system error.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Not a regular file, or larger than a map file may be ([`slam_core::files`]).
    #[error(transparent)]
    Read(#[from] slam_core::files::ReadError),
    /// The file could not be written (atomically, [`slam_core::files`]).
    #[error(transparent)]
    Write(#[from] slam_core::files::WriteError),
    /// Not a map file, or malformed.
    #[error("{path}: not a readable map file: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong (with line and column for JSON syntax errors).
        message: String,
    },
    /// A value that cannot be right: not finite, a zero or non-unit quaternion, an id that refers to
    /// nothing.
    #[error("{path}: {field}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Where, e.g. `keyframes.12.pose`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A map of another version.
    #[error("{path}: map format version {found}, this build reads versions 1 to {MAP_VERSION}")]
    Version {
        /// The file.
        path: PathBuf,
        /// Version found.
        found: u32,
    },
}

/// Counts describing a map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapStats {
    /// Keyframes.
    pub keyframes: usize,
    /// Map segments (keyframes without a parent).
    pub segments: usize,
    /// Map points.
    pub points: usize,
    /// Stereo observations.
    pub observations: usize,
    /// Objects (with an ellipsoid).
    pub objects: usize,
    /// Objects flagged dynamic.
    pub dynamic_objects: usize,
    /// Frames.
    pub frames: usize,
    /// Length of the keyframe path (the spanning tree: each keyframe's distance from its parent),
    /// metres.
    pub keyframe_path_m: f64,
}

impl Map {
    /// The frame whose camera is the map's world: its first keyframe's (the lowest id; a map's first
    /// keyframe sits at the origin), `None` for a map without keyframes.
    pub fn first_frame(&self) -> Option<usize> {
        self.keyframes.values().next().map(|k| k.frame)
    }

    /// Pose of a keyframe.
    pub fn keyframe_pose(&self, id: KeyframeId) -> Option<Isometry3<f64>> {
        self.keyframes.get(&id).map(|k| pose_from_array(&k.pose))
    }

    /// World position of a point.
    pub fn point(&self, id: PointId) -> Option<Vector3<f64>> {
        self.points.get(&id).map(|p| Vector3::from(p.position))
    }

    /// Pose of every frame (keyframe pose composed with the frame's relative pose); `None` for a frame
    /// whose keyframe is missing.
    pub fn frame_poses(&self) -> Vec<Option<Isometry3<f64>>> {
        self.trajectory
            .iter()
            .map(|f| f.keyframe.and_then(|k| self.keyframe_pose(k)).map(|k| k * pose_from_array(&f.relative)))
            .collect()
    }

    /// Counts. The keyframe path is the length of the keyframes' spanning tree: each keyframe's
    /// distance from its parent (the keyframe it was tracked from), summed, so that keyframes a later
    /// run added over the same road count by where they were tracked from, not by their ids (ids follow
    /// the runs, and summing in id order hopped back across the road at each run).
    pub fn stats(&self) -> MapStats {
        let live = |id: &KeyframeId| self.keyframes.get(id).filter(|k| !k.culled);
        let centre = |k: &MapKeyframe| Vector3::new(k.pose[4], k.pose[5], k.pose[6]);
        let keyframe_path_m = self
            .keyframes
            .values()
            .filter(|k| !k.culled)
            .filter_map(|k| Some((centre(k) - centre(live(&k.parent?)?)).norm()))
            .fold(0.0, |a, d| a + d);
        MapStats {
            keyframes: self.keyframes.values().filter(|k| !k.culled).count(),
            segments: self.keyframes.values().filter(|k| k.parent.is_none()).count(),
            points: self.points.len(),
            observations: self.keyframes.values().map(|k| k.observations.len()).sum(),
            objects: self.objects.len(),
            dynamic_objects: self.objects.iter().filter(|o| o.dynamic).count(),
            frames: self.trajectory.len(),
            keyframe_path_m,
        }
    }

    /// Write the map as JSON, atomically (a temporary file beside it, then a rename).
    /// The keyframes' features go to a binary file beside it ([`features`], `map.features` for
    /// `map.json`), also atomically, and the JSON names that file with its length and checksum. Both
    /// are made in memory first and written one right after the other (features, then JSON), so only
    /// a stop between the two renames leaves a new features file beside the old JSON: a pair that
    /// [`Map::load`] refuses rather than mixes. (A run writes into a new output folder that replaces
    /// the old one whole, so a stopped run leaves the old pair as it was.)
    pub fn save(&self, path: &Path) -> Result<(), MapError> {
        let invalid =
            |message: String| MapError::Invalid { path: path.to_path_buf(), field: "features".into(), message };
        let side = if self.keyframe_features.is_empty() {
            None
        } else {
            let bytes = features::encode(&self.keyframe_features).map_err(invalid)?;
            let side = features_path(path);
            let file = side.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            let sum = format!("{:016x}", features::fnv1a64(&bytes));
            let r = FeaturesRef { file, bytes: bytes.len() as u64, fnv1a64: sum };
            Some((side, bytes, r))
        };
        let fmt = |e: serde_json::Error| MapError::Format { path: path.to_path_buf(), message: e.to_string() };
        let reference = side.as_ref().map(|s| s.2.clone());
        let text = if reference == self.features {
            serde_json::to_string(self).map_err(fmt)?
        } else {
            let head = Map { features: reference, keyframe_features: BTreeMap::new(), ..self.clone() };
            serde_json::to_string(&head).map_err(fmt)?
        };
        if let Some((side, bytes, _)) = side {
            slam_core::files::write_atomic(&side, &bytes)?;
        }
        Ok(slam_core::files::write_atomic(path, text.as_bytes())?)
    }

    /// Read a map file and its features file ([`Map::load_without_features`], then the features file
    /// it names, its length and checksum checked, its keyframes and points those of the map): what a
    /// run tracks against.
    pub fn load(path: &Path) -> Result<Self, MapError> {
        let mut map = Self::load_without_features(path)?;
        if let Some(r) = &map.features {
            map.keyframe_features = read_features(path, r)?;
            map.check_features().map_err(|(field, message)| MapError::Invalid {
                path: path.to_path_buf(),
                field,
                message,
            })?;
        }
        Ok(map)
    }

    /// Read a map file alone (not its features file: `keyframe_features` stays empty), checking its
    /// format name, version and values ([`Map::check`]): enough to inspect and export it.
    pub fn load_without_features(path: &Path) -> Result<Self, MapError> {
        if path.extension().is_some_and(|e| e == "features") {
            return Err(MapError::Format {
                path: path.to_path_buf(),
                message: "this is a map's features file; give the map's JSON file beside it (map.json)".into(),
            });
        }
        let text = slam_core::files::read_text(path, &slam_core::files::DOCUMENT).map_err(|e| match e {
            slam_core::files::ReadError::Io { path, source } => MapError::Io { path, source },
            other => MapError::Read(other),
        })?;
        #[derive(Deserialize)]
        struct Header {
            format: String,
            version: u32,
        }
        // serde says where (line, column); the path of keys says what (`objects[0]: missing field ...`)
        let fmt = |e: serde_json::Error| {
            let at = slam_core::files::json_path_at(&text, e.line(), e.column());
            let message = if at.is_empty() { e.to_string() } else { format!("{at}: {e}") };
            MapError::Format { path: path.to_path_buf(), message }
        };
        let header: Header = serde_json::from_str(&text).map_err(|e| {
            // an object map (objects.json) has "objects" but no "format": say which file to give
            let objects_only = serde_json::from_str::<serde_json::Value>(&text)
                .is_ok_and(|v| v.get("objects").is_some() && v.get("format").is_none());
            if objects_only {
                MapError::Format {
                    path: path.to_path_buf(),
                    message: "this is an object map (a run's objects.json), not a map; give the run's map.json".into(),
                }
            } else {
                fmt(e)
            }
        })?;
        if header.format != MAP_FORMAT {
            return Err(MapError::Format {
                path: path.to_path_buf(),
                message: format!("format is {:?}, expected {MAP_FORMAT:?}", header.format),
            });
        }
        if !(1..=MAP_VERSION).contains(&header.version) {
            return Err(MapError::Version { path: path.to_path_buf(), found: header.version });
        }
        let map: Self = serde_json::from_str(&text).map_err(fmt)?;
        map.check().map_err(|(field, message)| MapError::Invalid { path: path.to_path_buf(), field, message })?;
        Ok(map)
    }

    /// The features refer to keyframes of the map that are not culled, and to points that exist; every
    /// keyframe that is not culled has its features; each keyframe's observations are the same in the
    /// JSON and in the features file (the same points, at the keypoints' positions).
    fn check_features(&self) -> Result<(), (String, String)> {
        for (id, f) in &self.keyframe_features {
            let field = || format!("features (keyframe {id})");
            match self.keyframes.get(id) {
                Some(k) if !k.culled => {}
                Some(_) => return Err((field(), "a culled keyframe has no features".into())),
                None => return Err((field(), "no such keyframe in the map".into())),
            }
            if let Some((k, p)) = f.observations.iter().find(|(_, p)| !self.points.contains_key(p)) {
                return Err((field(), format!("keypoint {k} observes point {p}, which does not exist")));
            }
        }
        for (id, k) in self.keyframes.iter().filter(|(_, k)| !k.culled) {
            let field = || format!("keyframes.{id}.observations");
            let Some(f) = self.keyframe_features.get(id) else {
                return Err((
                    format!("keyframes.{id}"),
                    "not culled, but the features file holds no features of it (every keyframe a run tracks \
                     against keeps its keypoints there)"
                        .into(),
                ));
            };
            let json: BTreeMap<PointId, [f64; 3]> = k.observations.iter().copied().collect();
            let saved: BTreeMap<PointId, u32> = f.observations.iter().map(|&(kp, p)| (p, kp)).collect();
            if let Some(p) = json.keys().find(|p| !saved.contains_key(p)) {
                return Err((field(), format!("point {p} is observed here but not in the features file")));
            }
            if let Some(p) = saved.keys().find(|p| !json.contains_key(p)) {
                return Err((
                    field(),
                    format!("the features file has keyframe {id} observe point {p}, the JSON does not"),
                ));
            }
            for (p, kp) in &saved {
                let o = json[p];
                let Some(key) = f.keypoints.get(*kp as usize) else {
                    return Err((field(), format!("point {p}: keypoint {kp} is not in the features file")));
                };
                // the features file keeps 32-bit floats: a keypoint of 2 000 px is kept to 1e-4 px
                let same = |a: f64, b: f64| (a.is_nan() && b.is_nan()) || (a - b).abs() <= 1e-3;
                if !(same(o[0], key.u) && same(o[1], key.v) && same(o[2], key.u_right)) {
                    return Err((
                        field(),
                        format!(
                            "point {p} is observed at {o:?} in the JSON, at keypoint {kp} ({}, {}, right {}) in the features file",
                            key.u, key.v, key.u_right
                        ),
                    ));
                }
            }
        }
        self.check_geometry()
    }

    /// Observations on both sides: a keyframe observes each point once, and a point's `observed_by`
    /// lists exactly the keyframes whose observations name it.
    fn check_both_sides(&self) -> Result<(), (String, String)> {
        let mut observers: BTreeMap<PointId, Vec<KeyframeId>> = BTreeMap::new();
        for (id, k) in &self.keyframes {
            let mut seen = std::collections::BTreeSet::new();
            for (i, (p, _)) in k.observations.iter().enumerate() {
                if !seen.insert(*p) {
                    return Err((format!("keyframes.{id}.observations[{i}]"), format!("point {p} is observed twice")));
                }
                observers.entry(*p).or_default().push(*id);
            }
        }
        for (id, p) in &self.points {
            let mut listed = p.observed_by.clone();
            listed.sort_unstable();
            let observing = observers.remove(id).unwrap_or_default();
            if listed != observing {
                return Err((
                    format!("points.{id}.observed_by"),
                    format!(
                        "{:?}, but the keyframes observing it are {observing:?} (each side must name the other)",
                        p.observed_by
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Keyframe poses and points agree with their observations (with the map's camera, when it names
    /// one): every observed point lies in front of its keyframe and is seen within the image's larger
    /// side of its keypoint ([`observation_error`]), and no keyframe has most of its observations
    /// beyond the 99.9 % χ² bound of a keypoint's noise at its level.
    ///
    /// Why these bounds: local bundle adjustment leaves observations within their 95 % χ² bound when it
    /// culls (σ = 1 px × the level's scale), and later adjustments of neighbouring keyframes move some
    /// of them a little beyond it: in the maps of odometry 06 and drive 0005 at most 0.9 % of a
    /// keyframe's observations lie beyond the 99.9 % bound, and no observation 41 px or more from its
    /// point's projection. A pose or point edited by hand (a keyframe 100 m off, a point at 1e5 m)
    /// puts the point behind the camera, or farther from its keypoint than the image is wide, where the
    /// camera never saw it; a keyframe pose whose own observations mostly disagree with it beyond the
    /// noise is not the pose they were adjusted with (a least-squares pose explains most of its data).
    fn check_geometry(&self) -> Result<(), (String, String)> {
        let Some(c) = &self.camera else { return Ok(()) };
        let pyramid = slam_core::map::ScalePyramid::default();
        let largest = c.width.max(c.height);
        for (id, k) in self.keyframes.iter().filter(|(_, k)| !k.culled) {
            let Some(f) = self.keyframe_features.get(id) else { continue };
            let levels: BTreeMap<PointId, u8> =
                f.observations.iter().filter_map(|&(kp, p)| Some((p, f.keypoints.get(kp as usize)?.level))).collect();
            let from_world = pose_from_array(&k.pose).inverse();
            let mut beyond = 0;
            for (i, (p, o)) in k.observations.iter().enumerate() {
                let Some(x) = self.points.get(p) else { continue };
                let field = || format!("keyframes.{id}.observations[{i}]");
                let in_camera = from_world * nalgebra::Point3::from(x.position);
                let Some((e2, chi2)) = observation_error(c, &in_camera.coords, o) else {
                    return Err((
                        field(),
                        format!("point {p} at {:?} lies behind keyframe {id}, which observes it", x.position),
                    ));
                };
                if e2.sqrt() > largest {
                    return Err((
                        field(),
                        format!(
                            "point {p} at {:?} is seen {:.0} px from the keypoint that observes it, farther than the \
                             image is wide ({largest} px): the point or the keyframe's pose was moved",
                            x.position,
                            e2.sqrt()
                        ),
                    ));
                }
                let sigma = pyramid.scale(levels.get(p).copied().unwrap_or(0));
                beyond += usize::from(e2 > chi2 * sigma * sigma);
            }
            if 2 * beyond > k.observations.len() {
                return Err((
                    format!("keyframes.{id}.pose"),
                    format!(
                        "{beyond} of its {} observations lie beyond the 99.9 % bound of a keypoint's noise: the pose \
                         is not the one they were adjusted with",
                        k.observations.len()
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Consistency of a map: every number finite (a right column may be absent), quaternions of unit
    /// length, rotations orthonormal, semi-axes positive, every id referring to something, frames in
    /// increasing order. Returns the first offending field and what is wrong with it.
    pub fn check(&self) -> Result<(), (String, String)> {
        // ids are counted up from 0; one near the top of the range is a corrupt number, and the next
        // id after it would wrap around
        let ids = self.keyframes.keys().chain(self.points.keys()).chain(self.objects.iter().map(|o| &o.id));
        if let Some(id) = ids.copied().find(|&id| id >= MAX_ID) {
            return Err(("id".into(), format!("{id} is not an id of a map (at most {MAX_ID})")));
        }
        self.check_keyframes()?;
        for (id, p) in &self.points {
            check_position(format!("points.{id}.position"), &p.position)?;
            if let Some(k) = p.observed_by.iter().find(|k| !self.keyframes.contains_key(k)) {
                return Err((format!("points.{id}.observed_by"), format!("keyframe {k} does not exist")));
            }
        }
        self.check_both_sides()?;
        if let Some(c) = &self.camera {
            slam_core::check::stereo_camera([c.fx, c.fy, c.cx, c.cy], c.baseline, (c.width, c.height))
                .map_err(|e| (format!("camera.{}", e.key), format!("{}: must be {}", e.value, e.valid)))?;
        }
        self.check_objects()?;
        if let Some(w) = &self.ground_truth_world {
            check_pose("ground_truth_world.pose".into(), &w.pose)?;
        }
        self.check_trajectory()
    }

    /// The keyframes of [`Map::check`]: poses, parents that exist and lead back without a cycle,
    /// observations of points that exist.
    fn check_keyframes(&self) -> Result<(), (String, String)> {
        for (id, k) in &self.keyframes {
            check_pose(format!("keyframes.{id}.pose"), &k.pose)?;
            if let Some(p) = k.parent {
                if !self.keyframes.contains_key(&p) {
                    return Err((format!("keyframes.{id}.parent"), format!("keyframe {p} does not exist")));
                }
            }
            // parents lead back to a segment's first keyframe: a chain that meets itself is a cycle
            let mut seen = std::collections::BTreeSet::from([*id]);
            let mut at = k.parent;
            while let Some(p) = at {
                if !seen.insert(p) {
                    return Err((
                        format!("keyframes.{id}.parent"),
                        format!("keyframe {p} is its own ancestor (a cycle of parents)"),
                    ));
                }
                at = self.keyframes.get(&p).and_then(|q| q.parent);
            }
            for (i, (pid, o)) in k.observations.iter().enumerate() {
                let field = format!("keyframes.{id}.observations[{i}]");
                if !self.points.contains_key(pid) {
                    return Err((field, format!("point {pid} does not exist")));
                }
                if !(o[0].is_finite() && o[1].is_finite() && !o[2].is_infinite()) {
                    return Err((field, format!("not finite: {o:?}")));
                }
            }
        }
        Ok(())
    }

    /// The objects of [`Map::check`]: unique ids, finite centres inside the map, positive bounded
    /// semi-axes, points that exist, views with poses and boxes, rotations.
    fn check_objects(&self) -> Result<(), (String, String)> {
        let mut ids = std::collections::BTreeSet::new();
        for (i, o) in self.objects.iter().enumerate() {
            let at = |f: &str| format!("objects[{i}].{f}");
            if !ids.insert(o.id) {
                return Err((at("id"), format!("id {} appears twice", o.id)));
            }
            if !o.center.iter().chain(&o.rotation).all(|v| v.is_finite()) {
                return Err((at("center/rotation"), "not finite".into()));
            }
            check_position(at("center"), &o.center)?;
            // no object a map holds is a kilometre long: larger is a corrupt number or other units
            if !o.semi_axes.iter().all(|a| a.is_finite() && *a > 0.0 && *a <= 1e3) {
                return Err((
                    at("semi_axes"),
                    format!("must be positive, finite and at most 1000 m: {:?}", o.semi_axes),
                ));
            }
            if let Some(p) = o.points.iter().find(|p| !self.points.contains_key(p)) {
                return Err((at("points"), format!("point {p} does not exist")));
            }
            if o.earlier_views > o.views.len() {
                return Err((at("earlier_views"), format!("{} of {} views", o.earlier_views, o.views.len())));
            }
            for (j, v) in o.views.iter().enumerate() {
                let at = |f: &str| format!("objects[{i}].views[{j}].{f}");
                check_pose(at("pose"), &v.pose)?;
                let [x0, y0, x1, y1] = v.bbox;
                if !(v.bbox.iter().all(|x| x.is_finite()) && x0 < x1 && y0 < y1) {
                    return Err((at("bbox"), format!("not a box: {:?}", v.bbox)));
                }
                if let Some((k, rel)) = &v.reference {
                    if !self.keyframes.contains_key(k) {
                        return Err((at("reference"), format!("keyframe {k} does not exist")));
                    }
                    check_pose(at("reference"), rel)?;
                }
            }
            let r = nalgebra::Matrix3::from_row_slice(&o.rotation);
            let err = (r * r.transpose() - nalgebra::Matrix3::identity()).abs().max();
            if err > 1e-3 || r.determinant() < 0.0 {
                return Err((
                    at("rotation"),
                    format!("not a rotation (|R Rᵀ − I| = {err:.2e}, det {:.3})", r.determinant()),
                ));
            }
        }
        Ok(())
    }

    /// The trajectory of [`Map::check`]: keyframes that exist, poses, known states, frames in
    /// increasing order; and every object's frames among them.
    fn check_trajectory(&self) -> Result<(), (String, String)> {
        let mut last = None;
        for (i, f) in self.trajectory.iter().enumerate() {
            if let Some(k) = f.keyframe.filter(|k| !self.keyframes.contains_key(k)) {
                return Err((format!("trajectory[{i}].keyframe"), format!("keyframe {k} does not exist")));
            }
            check_pose(format!("trajectory[{i}].relative"), &f.relative)?;
            if !crate::tracking_states::STATE_NAMES.contains(&f.state.as_str()) {
                return Err((
                    format!("trajectory[{i}].state"),
                    format!(
                        "'{}' is not a tracking state ({})",
                        f.state,
                        crate::tracking_states::STATE_NAMES.join(", ")
                    ),
                ));
            }
            if last.is_some_and(|l| f.frame <= l) {
                return Err((
                    format!("trajectory[{i}].frame"),
                    format!("frame {} after frame {}", f.frame, last.unwrap_or(0)),
                ));
            }
            last = Some(f.frame);
        }
        // an object's frames are frames of its detections, each one a frame of the trajectory
        let frames: std::collections::BTreeSet<usize> = self.trajectory.iter().map(|f| f.frame).collect();
        for (i, o) in self.objects.iter().enumerate() {
            if let Some(f) = o.frames.iter().find(|f| !self.trajectory.is_empty() && !frames.contains(f)) {
                return Err((format!("objects[{i}].frames"), format!("frame {f} is not in the trajectory")));
            }
        }
        Ok(())
    }

    /// Export the map points as an ASCII PLY point cloud (atomically).
    pub fn export_ply(&self, path: &Path) -> Result<(), MapError> {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = write!(
            s,
            "ply\nformat ascii 1.0\ncomment quadric-slam map points\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
            self.points.len()
        );
        for (id, p) in &self.points {
            ply_float(path, &format!("points.{id}.position"), &p.position)?;
            let _ = writeln!(s, "{} {} {}", p.position[0], p.position[1], p.position[2]);
        }
        Ok(slam_core::files::write_atomic(path, s.as_bytes())?)
    }
}

/// A position in a map: finite and within [`MAX_COORDINATE_M`] of its origin.
fn check_position(field: String, p: &[f64]) -> Result<(), (String, String)> {
    if !p.iter().all(|v| v.is_finite()) {
        return Err((field, format!("not finite: {p:?}")));
    }
    if let Some(v) = p.iter().find(|v| v.abs() > MAX_COORDINATE_M) {
        return Err((
            field,
            format!(
                "coordinate {v:.3e} m: a map stays within {MAX_COORDINATE_M:.1e} m of its origin (the Earth's diameter)"
            ),
        ));
    }
    Ok(())
}
/// A pose in a map: finite, its position a [`check_position`], its quaternion of unit length.
fn check_pose(field: String, p: &PoseArray) -> Result<(), (String, String)> {
    if !p.iter().all(|v| v.is_finite()) {
        return Err((field, format!("not finite: {p:?}")));
    }
    check_position(field.clone(), &p[4..])?;
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]).sqrt();
    // written maps hold unit quaternions to 1e-15; 1e-3 allows values rounded by hand
    if (n - 1.0).abs() > 1e-3 {
        let what = if n == 0.0 { "zero quaternion".to_string() } else { format!("quaternion of length {n}") };
        return Err((field, format!("{what} (expected unit length)")));
    }
    Ok(())
}

/// Ids of keyframes, points and objects stay below 2⁴⁸: a map made at 10 Hz for a century, with a
/// thousand points a frame, counts to about 3·10¹³.
pub const MAX_ID: u64 = 1 << 48;

/// The features file of a map file: `map.features` beside `map.json`.
pub fn features_path(map: &Path) -> PathBuf {
    map.with_extension("features")
}

/// Where the features file of the map file at `path` may be, in the order tried: beside the file the
/// path leads to (through symbolic links) under the name the JSON gives (`named`), beside the path
/// itself under that name, then under the map file's own name with `.features` (a pair copied under
/// another name: `06.json` with `06.features`), beside the path and beside the file it leads to. The
/// length and checksum in the JSON tell whether the file found is the right one.
pub fn features_places(path: &Path, named: &str) -> Vec<PathBuf> {
    let real = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    let beside = |p: &Path| p.parent().unwrap_or(Path::new(".")).join(named);
    let mut places = vec![beside(&real), beside(path), features_path(path), features_path(&real)];
    let mut seen = std::collections::BTreeSet::new();
    places.retain(|p| seen.insert(p.clone()));
    places
}

/// Read the features file a map file names, checking its length and checksum.
fn read_features(path: &Path, r: &FeaturesRef) -> Result<BTreeMap<KeyframeId, SavedFeatures>, MapError> {
    let invalid = |message: String| MapError::Invalid { path: path.to_path_buf(), field: "features".into(), message };
    // a bare file name, in the map file's folder: a map never points elsewhere
    if Path::new(&r.file).file_name().map(|n| n.to_string_lossy()) != Some(r.file.as_str().into()) {
        return Err(invalid(format!("{:?} is not a file name", r.file)));
    }
    let places = features_places(path, &r.file);
    let Some(side) = places.iter().find(|p| p.exists()).cloned() else {
        let looked: Vec<String> = places.iter().map(|p| p.display().to_string()).collect();
        return Err(invalid(format!(
            "the keyframes' features file it names (features.file {:?}) is in none of: {}",
            r.file,
            looked.join(", ")
        )));
    };
    let bytes = slam_core::files::read_bytes(&side, &slam_core::files::DOCUMENT)
        .map_err(|e| invalid(format!("the keyframes' features file it names: {e}")))?;
    let sum = format!("{:016x}", features::fnv1a64(&bytes));
    if bytes.len() as u64 != r.bytes || sum != r.fnv1a64 {
        return Err(invalid(format!(
            "{} is {} bytes with checksum {sum}, the map was written with {} bytes and checksum {}: \
             damaged, or not the features file of this map",
            side.display(),
            bytes.len(),
            r.bytes,
            r.fnv1a64
        )));
    }
    features::decode(&bytes).map_err(|m| invalid(format!("{}: {m}", side.display())))
}

/// The squared reprojection error of an observation `[u, v, u_right]` (`u_right` NaN: left only) of a
/// point at `x` (camera frame) through `camera`, with the 99.9 % χ² bound of unit noise for its degrees
/// of freedom (13.82 for two, 16.27 for three); `None` when the point is not in front of the camera.
fn observation_error(camera: &MapCamera, x: &Vector3<f64>, o: &[f64; 3]) -> Option<(f64, f64)> {
    // NaN is not in front either
    if x.z.is_nan() || x.z <= 0.0 {
        return None;
    }
    let u = camera.fx * x.x / x.z + camera.cx;
    let v = camera.fy * x.y / x.z + camera.cy;
    let left = (u - o[0]).powi(2) + (v - o[1]).powi(2);
    Some(if o[2].is_nan() {
        (left, 13.82)
    } else {
        let u_right = u - camera.fx * camera.baseline / x.z;
        (left + (u_right - o[2]).powi(2), 16.27)
    })
}

/// Largest coordinate a map may hold, metres: the Earth's diameter (1.3e7 m), the bound the dataset
/// readers put on poses (a larger number is a corrupt value or other units).
pub const MAX_COORDINATE_M: f64 = 1.3e7;

/// A PLY vertex's coordinates must fit the file's 32-bit floats (a larger value would be written as
/// a number the reader turns into infinity).
fn ply_float(path: &Path, what: &str, v: &[f64; 3]) -> Result<(), MapError> {
    if v.iter().all(|x| x.is_finite() && x.abs() <= f64::from(f32::MAX)) {
        return Ok(());
    }
    Err(MapError::Invalid {
        path: path.to_path_buf(),
        field: what.to_string(),
        message: format!("{v:?} does not fit the PLY file's 32-bit floats (at most {:.3e})", f32::MAX),
    })
}

/// What [`Map::export_scene_ply`] wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SceneCounts {
    /// Ellipsoid meshes (static and dynamic objects; moving ones are not mapped and not written).
    pub ellipsoids: usize,
    /// Keyframe camera frusta.
    pub cameras: usize,
    /// Trajectory vertices (one per frame with a pose).
    pub trajectory: usize,
    /// Map points.
    pub points: usize,
    /// Vertices, faces and edges in the file.
    pub vertices: usize,
    /// Triangles.
    pub faces: usize,
    /// Edges.
    pub edges: usize,
}

/// Colours of the 3-D scene (RGB): static objects green, dynamic orange, cameras blue, trajectory black,
/// points grey; the same as the pictures' (docs/system.md).
const SCENE_STATIC: [u8; 3] = [40, 170, 60];
const SCENE_DYNAMIC: [u8; 3] = [240, 140, 20];
const SCENE_CAMERA: [u8; 3] = [31, 119, 180];
const SCENE_TRAJECTORY: [u8; 3] = [0, 0, 0];
const SCENE_POINT: [u8; 3] = [150, 150, 150];

impl Map {
    /// Export the scene as an ASCII PLY mesh (atomically) that MeshLab, Blender and CloudCompare open:
    /// each mapped object's ellipsoid as a triangle mesh (12 × 24 facets, coloured by state), each
    /// keyframe's camera as a frustum of four triangles (1 m deep, looking along its z), the frame
    /// trajectory as edges, and the map points as vertices; world frame of the map ([`MAP_WORLD`]).
    pub fn export_scene_ply(&self, path: &Path) -> Result<SceneCounts, MapError> {
        let mut mesh = SceneMesh::default();
        let mut counts = SceneCounts::default();
        for o in self.objects.iter().filter(|o| !o.moving) {
            mesh.add_ellipsoid(o);
            counts.ellipsoids += 1;
        }
        for k in self.keyframes.values() {
            mesh.add_frustum(&pose_from_array(&k.pose));
            counts.cameras += 1;
        }
        let first = mesh.vertices.len();
        for p in self.frame_poses().into_iter().flatten() {
            let t = p.translation.vector;
            mesh.vertices.push(([t.x, t.y, t.z], SCENE_TRAJECTORY));
        }
        counts.trajectory = mesh.vertices.len() - first;
        for i in first + 1..mesh.vertices.len() {
            mesh.edges.push([i - 1, i]);
        }
        for p in self.points.values() {
            mesh.vertices.push((p.position, SCENE_POINT));
        }
        counts.points = self.points.len();
        (counts.vertices, counts.faces, counts.edges) = (mesh.vertices.len(), mesh.faces.len(), mesh.edges.len());
        for (i, (v, _)) in mesh.vertices.iter().enumerate() {
            ply_float(path, &format!("vertex {i}"), v)?;
        }
        slam_core::files::write_atomic(path, mesh.to_ply().as_bytes())?;
        Ok(counts)
    }
}

/// Coloured vertices, triangles and edges of an exported scene.
#[derive(Default)]
struct SceneMesh {
    vertices: Vec<([f64; 3], [u8; 3])>,
    faces: Vec<[usize; 3]>,
    edges: Vec<[usize; 2]>,
}

impl SceneMesh {
    /// An ellipsoid as 12 rings × 24 segments between two poles, coloured by its state.
    fn add_ellipsoid(&mut self, o: &MapObject) {
        let (rings, segments) = (12usize, 24usize);
        let colour = if o.dynamic { SCENE_DYNAMIC } else { SCENE_STATIC };
        let r = nalgebra::Matrix3::from_row_slice(&o.rotation);
        let base = self.vertices.len();
        // poles, then rings × segments
        for z in [-1.0, 1.0] {
            let p = r * Vector3::new(0.0, 0.0, z * o.semi_axes[2]) + Vector3::from(o.center);
            self.vertices.push(([p.x, p.y, p.z], colour));
        }
        for i in 1..rings {
            let theta = std::f64::consts::PI * i as f64 / rings as f64 - std::f64::consts::FRAC_PI_2;
            for j in 0..segments {
                let phi = std::f64::consts::TAU * j as f64 / segments as f64;
                let u = Vector3::new(
                    o.semi_axes[0] * theta.cos() * phi.cos(),
                    o.semi_axes[1] * theta.cos() * phi.sin(),
                    o.semi_axes[2] * theta.sin(),
                );
                let p = r * u + Vector3::from(o.center);
                self.vertices.push(([p.x, p.y, p.z], colour));
            }
        }
        let at = |i: usize, j: usize| base + 2 + (i - 1) * segments + j % segments;
        for j in 0..segments {
            self.faces.push([base, at(1, j + 1), at(1, j)]);
            self.faces.push([base + 1, at(rings - 1, j), at(rings - 1, j + 1)]);
            for i in 1..rings - 1 {
                self.faces.push([at(i, j), at(i, j + 1), at(i + 1, j + 1)]);
                self.faces.push([at(i, j), at(i + 1, j + 1), at(i + 1, j)]);
            }
        }
    }

    /// A camera as a frustum of four triangles, 1 m deep along its z.
    fn add_frustum(&mut self, pose: &Isometry3<f64>) {
        let base = self.vertices.len();
        let apex = pose.translation.vector;
        self.vertices.push(([apex.x, apex.y, apex.z], SCENE_CAMERA));
        for (x, y) in [(-0.6, -0.2), (0.6, -0.2), (0.6, 0.2), (-0.6, 0.2)] {
            let p = pose * nalgebra::Point3::new(x, y, 1.0);
            self.vertices.push(([p.x, p.y, p.z], SCENE_CAMERA));
        }
        for c in 0..4 {
            self.faces.push([base, base + 1 + c, base + 1 + (c + 1) % 4]);
        }
    }

    /// The ASCII PLY text.
    fn to_ply(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        // writing into a String cannot fail
        let _ = write!(
            s,
            "ply\nformat ascii 1.0\ncomment quadric-slam scene: ellipsoids (green static, orange dynamic), camera \
             frusta (blue), trajectory (black edges), map points (grey)\ncomment {MAP_WORLD}\nelement vertex {}\n\
             property float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\n\
             property uchar blue\nelement face {}\nproperty list uchar int vertex_indices\nelement edge {}\n\
             property int vertex1\nproperty int vertex2\nend_header\n",
            self.vertices.len(),
            self.faces.len(),
            self.edges.len()
        );
        for (p, c) in &self.vertices {
            let _ = writeln!(s, "{:.4} {:.4} {:.4} {} {} {}", p[0], p[1], p[2], c[0], c[1], c[2]);
        }
        for f in &self.faces {
            let _ = writeln!(s, "3 {} {} {}", f[0], f[1], f[2]);
        }
        for e in &self.edges {
            let _ = writeln!(s, "{} {}", e[0], e[1]);
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Map {
        let mut m = Map::default();
        let pose =
            Isometry3::from_parts(Translation3::new(1.0, 2.0, 3.0), UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3));
        m.keyframes.insert(
            0,
            MapKeyframe {
                frame: 0,
                pose: pose_to_array(&Isometry3::identity()),
                parent: None,
                observations: vec![(7, [1.0, 2.0, 0.5])],
                culled: false,
            },
        );
        m.keyframes.insert(
            1,
            MapKeyframe { frame: 3, pose: pose_to_array(&pose), parent: Some(0), observations: vec![], culled: true },
        );
        m.points.insert(7, MapPoint { position: [0.5, 0.1, 9.0], observed_by: vec![0] });
        m.trajectory.push(FramePose {
            frame: 0,
            keyframe: Some(0),
            relative: pose_to_array(&Isometry3::identity()),
            state: "initialised".into(),
        });
        m.trajectory.push(FramePose {
            frame: 1,
            keyframe: Some(1),
            relative: pose_to_array(&pose.inverse()),
            state: "tracked".into(),
        });
        m
    }

    #[test]
    fn coordinates_beyond_the_earth_or_a_float32_are_refused() {
        let dir = std::env::temp_dir().join(format!("map-far-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let mut m = sample();
        m.points.insert(9, MapPoint { position: [0.0, 1e300, 0.0], observed_by: vec![0] });
        // the PLY writer refuses what its 32-bit floats cannot hold, and writes nothing
        let e = m.export_ply(&dir.join("p.ply")).expect_err("1e300").to_string();
        assert!(e.contains("points.9.position") && e.contains("32-bit floats"), "{e}");
        let e = m.export_scene_ply(&dir.join("s.ply")).expect_err("1e300").to_string();
        assert!(e.contains("32-bit floats"), "{e}");
        // a map file holding it is refused when loaded (a map stays within the Earth's diameter)
        m.save(&dir.join("far.json")).expect("saves");
        let e = Map::load(&dir.join("far.json")).expect_err("far").to_string();
        assert!(e.contains("points.9.position") && e.contains("Earth's diameter"), "{e}");
        m.points.get_mut(&9).expect("point").position = [0.0, 1.2e7, 0.0];
        m.export_ply(&dir.join("p.ply")).expect("within both bounds");
        let names: Vec<String> = std::fs::read_dir(&dir)
            .expect("list")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names.len(), 2, "far.json and p.ply, no temporary: {names:?}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// The keyframe path follows the spanning tree: a second run's keyframes over the same road add
    /// their distance from the keyframe each was tracked from, not the hop back from the first run's
    /// last keyframe (24 m here, 48 m in id order); a map of one keyframe has a path of 0 m, not -0.
    #[test]
    fn the_keyframe_path_follows_the_spanning_tree() {
        let kf = |z: f64, parent: Option<KeyframeId>| MapKeyframe {
            frame: 0,
            pose: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, z],
            parent,
            observations: vec![],
            culled: false,
        };
        let mut m = Map::default();
        m.keyframes.insert(0, kf(0.0, None));
        assert_eq!(format!("{:.1}", m.stats().keyframe_path_m), "0.0");
        m.keyframes.insert(1, kf(10.0, Some(0)));
        m.keyframes.insert(2, kf(20.0, Some(1)));
        assert_eq!(m.stats().keyframe_path_m, 20.0);
        m.keyframes.insert(3, kf(2.0, Some(0)));
        m.keyframes.insert(4, kf(12.0, Some(1)));
        assert_eq!(m.stats().keyframe_path_m, 24.0);
    }

    #[test]
    fn pose_arrays_round_trip() {
        let p =
            Isometry3::from_parts(Translation3::new(-1.0, 0.5, 2.0), UnitQuaternion::from_euler_angles(0.4, 0.2, -1.0));
        let q = pose_from_array(&pose_to_array(&p));
        assert!((p.to_homogeneous() - q.to_homogeneous()).abs().max() < 1e-12);
    }

    #[test]
    fn save_and_load_round_trip_and_frame_poses_compose() {
        let dir = std::env::temp_dir().join(format!("map-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let path = dir.join("map.json");
        let m = sample();
        m.save(&path).expect("saves");
        let names: Vec<String> = std::fs::read_dir(&dir)
            .expect("list")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["map.json"], "temporary file renamed away");
        let back = Map::load(&path).expect("loads");
        assert_eq!(back, m);
        let poses = back.frame_poses();
        // frame 1 = keyframe 1 ∘ keyframe-1-from-frame-1 = identity
        let p1 = poses[1].expect("pose");
        assert!(p1.translation.vector.norm() < 1e-12 && p1.rotation.angle() < 1e-12);
        // keyframe 1 was culled: the statistics count the keyframes in the map only
        let s = back.stats();
        assert_eq!((s.keyframes, s.segments, s.points, s.observations, s.frames), (1, 1, 1, 1, 2));
        assert_eq!(s.keyframe_path_m, 0.0);
        let mut kept = back.clone();
        kept.keyframes.get_mut(&1).expect("keyframe 1").culled = false;
        let s = kept.stats();
        assert_eq!((s.keyframes, s.segments, s.points, s.observations, s.frames), (2, 1, 1, 1, 2));
        assert!((s.keyframe_path_m - 14f64.sqrt()).abs() < 1e-12);
        m.export_ply(&dir.join("points.ply")).expect("ply");
        let ply = std::fs::read_to_string(dir.join("points.ply")).expect("ply text");
        assert!(ply.contains("element vertex 1") && ply.trim_end().ends_with("0.5 0.1 9"));
        // the scene: one ellipsoid (a moving one is left out), two frusta, two trajectory vertices, a point
        let mut m = m;
        let object = MapObject {
            id: 4,
            class: 2,
            class_name: "car".into(),
            center: [1.0, 0.0, 10.0],
            semi_axes: [2.0, 0.8, 0.9],
            rotation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            frames: vec![0, 1],
            dynamic: false,
            moving: false,
            points: vec![],
            views: vec![],
            earlier_views: 0,
        };
        m.objects.push(object.clone());
        m.objects.push(MapObject { id: 5, moving: true, dynamic: true, ..object });
        let c = m.export_scene_ply(&dir.join("scene.ply")).expect("scene");
        assert_eq!((c.ellipsoids, c.cameras, c.trajectory, c.points), (1, 2, 2, 1));
        let ellipsoid_vertices = 2 + 11 * 24;
        assert_eq!(c.vertices, ellipsoid_vertices + 2 * 5 + 2 + 1);
        assert_eq!((c.faces, c.edges), (2 * 24 + 2 * 24 * 10 + 2 * 4, 1));
        let scene = std::fs::read_to_string(dir.join("scene.ply")).expect("scene text");
        let body: Vec<&str> = scene.split("end_header\n").nth(1).expect("body").lines().collect();
        assert_eq!(body.len(), c.vertices + c.faces + c.edges, "header counts match the body");
        // every ellipsoid vertex lies on the ellipsoid ((x−c)ᵀ A⁻² (x−c) = 1)
        for line in &body[..ellipsoid_vertices] {
            let v: Vec<f64> = line.split_whitespace().take(3).map(|x| x.parse().expect("number")).collect();
            let q = ((v[0] - 1.0) / 2.0).powi(2) + (v[1] / 0.8).powi(2) + ((v[2] - 10.0) / 0.9).powi(2);
            assert!((q - 1.0).abs() < 1e-3, "{line}: {q}");
        }
        assert!(body[..ellipsoid_vertices].iter().all(|l| l.ends_with(" 40 170 60")), "static: green");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// An object map (a run's objects.json) given where a map is expected: the error says which file to
    /// give.
    #[test]
    fn an_object_map_given_as_a_map_names_the_file_to_give() {
        let dir = std::env::temp_dir().join(format!("map-objects-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let path = dir.join("objects.json");
        std::fs::write(&path, r#"{"version": 1, "frame": "world", "objects": []}"#).expect("write");
        let e = Map::load(&path).expect_err("not a map").to_string();
        assert!(e.contains("objects.json") && e.contains("give the run's map.json"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A version-1 file, as builds before left-only observations wrote it (every observation has its
    /// right column as a number), loads unchanged: same keyframes, points, objects and trajectory, and
    /// saving it again writes the current version.
    #[test]
    fn loads_a_version_1_map() {
        let dir = std::env::temp_dir().join(format!("map-v1-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let path = dir.join("v1.json");
        let v1 = format!(
            r#"{{"format": "{MAP_FORMAT}", "version": 1,
  "keyframes": {{"0": {{"frame": 0, "pose": [0, 0, 0, 1, 0, 0, 0], "parent": null,
                       "observations": [[7, [1.0, 2.0, 0.5]], [8, [10.0, 20.0, 4.25]]]}},
                "1": {{"frame": 3, "pose": [0, 0, 0, 1, 0, 0, 1.5], "parent": 0, "observations": [[7, [3.0, 2.5, 2.0]]]}}}},
  "points": {{"7": {{"position": [0.5, 0.1, 9.0], "observed_by": [0, 1]}},
             "8": {{"position": [-1.0, 0.2, 12.0], "observed_by": [0]}}}},
  "objects": [{{"id": 4, "class": 2, "center": [1, 0.8, 15], "semi_axes": [2.1, 0.8, 0.85],
               "rotation": [1, 0, 0, 0, 1, 0, 0, 0, 1], "frames": [0], "dynamic": false, "points": [8]}}],
  "trajectory": [{{"frame": 0, "keyframe": 0, "relative": [0, 0, 0, 1, 0, 0, 0], "state": "initialised"}}]}}"#
        );
        std::fs::write(&path, v1).expect("write");
        let m = Map::load(&path).expect("a version-1 map loads");
        assert_eq!(m.version, 1);
        assert_eq!(m.keyframes[&0].observations, vec![(7, [1.0, 2.0, 0.5]), (8, [10.0, 20.0, 4.25])]);
        assert_eq!(m.keyframes[&1].parent, Some(0));
        assert_eq!(m.points[&7].observed_by, vec![0, 1]);
        assert_eq!((m.objects.len(), m.objects[0].class, m.objects[0].points.clone()), (1, 2, vec![8]));
        let s = m.stats();
        assert_eq!((s.keyframes, s.segments, s.points, s.observations, s.frames), (2, 1, 2, 3, 1));
        let again = Map { version: MAP_VERSION, ..m.clone() };
        again.save(&dir.join("v2.json")).expect("saves");
        let back = Map::load(&dir.join("v2.json")).expect("loads");
        assert_eq!((back.version, back.keyframes, back.points), (MAP_VERSION, m.keyframes, m.points));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn load_rejects_other_files_with_their_path() {
        let dir = std::env::temp_dir().join(format!("map-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let wrong = dir.join("wrong.json");
        std::fs::write(&wrong, r#"{"format": "something-else", "version": 1}"#).expect("write");
        let e = Map::load(&wrong).expect_err("wrong format").to_string();
        assert!(e.contains("wrong.json") && e.contains("something-else"), "{e}");
        let newer = dir.join("newer.json");
        std::fs::write(&newer, format!(r#"{{"format": "{MAP_FORMAT}", "version": 99}}"#)).expect("write");
        let e = Map::load(&newer).expect_err("version").to_string();
        assert!(e.contains("version 99"), "{e}");
        let broken = dir.join("broken.json");
        std::fs::write(&broken, "{\n  \"format\": ").expect("write");
        let e = Map::load(&broken).expect_err("syntax").to_string();
        assert!(e.contains("broken.json") && e.contains("line 2"), "{e}");
        let e = Map::load(&dir.join("missing.json")).expect_err("missing").to_string();
        assert!(e.contains("missing.json"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A corruption of a consistent map: its name (the file's), the change, the field the error must
    /// name and a phrase the message must hold.
    type Corruption = (&'static str, fn(&mut Map), &'static str, &'static str);

    /// The sample map with one object (id 3, car, texture point 7), consistent.
    fn sample_with_object() -> Map {
        let mut m = sample();
        m.objects.push(MapObject {
            id: 3,
            class: 2,
            class_name: "car".into(),
            center: [1.0, 0.0, 9.0],
            semi_axes: [2.0, 0.8, 1.0],
            rotation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            frames: vec![0, 1],
            dynamic: false,
            moving: false,
            points: vec![7],
            views: vec![],
            earlier_views: 0,
        });
        m.check().expect("the sample is consistent");
        m
    }

    /// Bad-input suite, map files: each corruption, saved, is refused on load with the file and the field
    /// named.
    fn assert_refused(tag: &str, cases: &[Corruption]) {
        let dir = std::env::temp_dir().join(format!("map-invalid-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        for &(name, corrupt, field, what) in cases {
            let mut m = sample_with_object();
            corrupt(&mut m);
            let path = dir.join(format!("{name}.json"));
            std::fs::write(&path, serde_json::to_string(&m).expect("json")).expect("write");
            let e = Map::load(&path).expect_err(name).to_string();
            assert!(e.contains(&format!("{name}.json: {field}: ")) && e.contains(what), "{name}: {e}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn load_refuses_bad_keyframes_and_points_naming_file_and_field() {
        assert_refused(
            "graph",
            &[
                (
                    "zero-quaternion",
                    |m| m.keyframes.get_mut(&1).expect("kf").pose[..4].fill(0.0),
                    "keyframes.1.pose",
                    "zero quaternion",
                ),
                (
                    "long-quaternion",
                    |m| m.keyframes.get_mut(&1).expect("kf").pose[3] = 2.0,
                    "keyframes.1.pose",
                    "quaternion of length",
                ),
                (
                    "missing-parent",
                    |m| m.keyframes.get_mut(&1).expect("kf").parent = Some(9),
                    "keyframes.1.parent",
                    "keyframe 9 does not exist",
                ),
                (
                    "missing-point",
                    |m| m.keyframes.get_mut(&0).expect("kf").observations[0].0 = 8,
                    "keyframes.0.observations[0]",
                    "point 8 does not exist",
                ),
                (
                    "point-observer",
                    |m| m.points.get_mut(&7).expect("pt").observed_by.push(5),
                    "points.7.observed_by",
                    "keyframe 5 does not exist",
                ),
                (
                    "own-parent",
                    |m| m.keyframes.get_mut(&1).expect("kf").parent = Some(1),
                    "keyframes.1.parent",
                    "keyframe 1 is its own ancestor",
                ),
                (
                    "parent-cycle",
                    |m| m.keyframes.get_mut(&0).expect("kf").parent = Some(1),
                    "keyframes.0.parent",
                    "is its own ancestor",
                ),
            ],
        );
    }

    #[test]
    fn load_refuses_a_bad_trajectory_naming_file_and_field() {
        assert_refused(
            "trajectory",
            &[
                (
                    "trajectory-keyframe",
                    |m| m.trajectory[1].keyframe = Some(4),
                    "trajectory[1].keyframe",
                    "keyframe 4 does not exist",
                ),
                ("trajectory-order", |m| m.trajectory[1].frame = 0, "trajectory[1].frame", "frame 0 after frame 0"),
                (
                    "trajectory-quaternion",
                    |m| m.trajectory[0].relative[..4].fill(0.0),
                    "trajectory[0].relative",
                    "zero quaternion",
                ),
                (
                    "trajectory-state",
                    |m| m.trajectory[0].state = "flying".into(),
                    "trajectory[0].state",
                    "'flying' is not a tracking state",
                ),
            ],
        );
    }

    #[test]
    fn load_refuses_bad_objects_naming_file_and_field() {
        assert_refused(
            "objects",
            &[
                ("object-axes", |m| m.objects[0].semi_axes[1] = -1.0, "objects[0].semi_axes", "must be positive"),
                ("object-huge", |m| m.objects[0].semi_axes[0] = 1e200, "objects[0].semi_axes", "at most 1000 m"),
                ("object-rotation", |m| m.objects[0].rotation[0] = 3.0, "objects[0].rotation", "not a rotation"),
                ("object-twice", |m| m.objects.push(m.objects[0].clone()), "objects[1].id", "appears twice"),
                ("object-mirror", |m| m.objects[0].rotation[0] = -1.0, "objects[0].rotation", "det -1"),
                ("object-point", |m| m.objects[0].points.push(99), "objects[0].points", "point 99 does not exist"),
                (
                    "object-frame",
                    |m| m.objects[0].frames.push(99999),
                    "objects[0].frames",
                    "frame 99999 is not in the trajectory",
                ),
                ("object-earlier", |m| m.objects[0].earlier_views = 1, "objects[0].earlier_views", "1 of 0 views"),
                (
                    "object-view-box",
                    |m| m.objects[0].views.push(view([5.0, 0.0, 4.0, 9.0], None)),
                    "objects[0].views[0].bbox",
                    "not a box",
                ),
                (
                    "object-view-reference",
                    |m| m.objects[0].views.push(view([0.0, 0.0, 4.0, 9.0], Some(42))),
                    "objects[0].views[0].reference",
                    "keyframe 42 does not exist",
                ),
                ("object-id", |m| m.objects[0].id = u64::MAX, "id", "is not an id of a map"),
            ],
        );
    }

    /// A detection of an object as stored, at the identity pose.
    fn view(bbox: [f64; 4], reference: Option<KeyframeId>) -> ObjectView {
        let identity = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
        ObjectView { frame: 0, pose: identity, bbox, class: 2, reference: reference.map(|k| (k, identity)) }
    }

    /// JSON has no NaN: a non-number where a number belongs is a format error with its line.
    #[test]
    fn load_refuses_a_nan_naming_file_and_line() {
        let dir = std::env::temp_dir().join(format!("map-nan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let path = dir.join("nan.json");
        let text = serde_json::to_string_pretty(&sample()).expect("json").replacen("0.5,", "NaN,", 1);
        std::fs::write(&path, text).expect("write");
        let e = Map::load(&path).expect_err("NaN").to_string();
        assert!(e.contains("nan.json") && e.contains("line"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
