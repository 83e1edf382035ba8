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

/// Format name written into every map file.
pub const MAP_FORMAT: &str = "quadric-slam-map";
/// Version of the map file format. Version 2 added left-only observations (`u_right` written as
/// `null`) of triangulated points; version 1 files read unchanged.
pub const MAP_VERSION: u32 = 2;

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

/// A map point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapPoint {
    /// World position, metres.
    pub position: [f64; 3],
    /// Keyframes observing it.
    pub observed_by: Vec<KeyframeId>,
}

/// An object (ellipsoid landmark) of the map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapObject {
    /// Object id.
    pub id: u64,
    /// Class (COCO index).
    pub class: u16,
    /// Centre, world frame, metres.
    pub center: [f64; 3],
    /// Semi-axes along the object's x (length), y (height), z (width), metres.
    pub semi_axes: [f64; 3],
    /// Rotation, world from object, 3×3 row-major.
    pub rotation: [f64; 9],
    /// Frames of its associated detections.
    pub frames: Vec<usize>,
    /// Flagged as moving.
    pub dynamic: bool,
    /// Map points on the object (used for its texture planes).
    pub points: Vec<PointId>,
}

/// The pose of one input frame, relative to a keyframe (so it follows the keyframe's refinement).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FramePose {
    /// Frame index.
    pub frame: usize,
    /// Reference keyframe.
    pub keyframe: KeyframeId,
    /// Pose of the frame in the keyframe (keyframe from frame).
    pub relative: PoseArray,
    /// Tracking state as text (`tracked`, `lost`, `relocalised`, `initialised`, `unreadable`).
    pub state: String,
}

/// The map database.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Map {
    /// Always [`MAP_FORMAT`].
    pub format: String,
    /// Always [`MAP_VERSION`] when written by this version.
    pub version: u32,
    /// Keyframes by id.
    pub keyframes: BTreeMap<KeyframeId, MapKeyframe>,
    /// Map points by id.
    pub points: BTreeMap<PointId, MapPoint>,
    /// Objects, by id.
    pub objects: Vec<MapObject>,
    /// One entry per input frame, in order.
    pub trajectory: Vec<FramePose>,
}

impl Default for Map {
    fn default() -> Self {
        Self {
            format: MAP_FORMAT.to_string(),
            version: MAP_VERSION,
            keyframes: BTreeMap::new(),
            points: BTreeMap::new(),
            objects: Vec::new(),
            trajectory: Vec::new(),
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
    /// Length of the keyframe path, metres.
    pub keyframe_path_m: f64,
}

impl Map {
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
            .map(|f| self.keyframe_pose(f.keyframe).map(|k| k * pose_from_array(&f.relative)))
            .collect()
    }

    /// Counts.
    pub fn stats(&self) -> MapStats {
        let poses: Vec<Isometry3<f64>> = self.keyframes.values().map(|k| pose_from_array(&k.pose)).collect();
        MapStats {
            keyframes: self.keyframes.len(),
            segments: self.keyframes.values().filter(|k| k.parent.is_none()).count(),
            points: self.points.len(),
            observations: self.keyframes.values().map(|k| k.observations.len()).sum(),
            objects: self.objects.len(),
            dynamic_objects: self.objects.iter().filter(|o| o.dynamic).count(),
            frames: self.trajectory.len(),
            keyframe_path_m: poses.windows(2).map(|w| (w[1].translation.vector - w[0].translation.vector).norm()).sum(),
        }
    }

    /// Write the map as JSON, atomically (a temporary file beside it, then a rename).
    pub fn save(&self, path: &Path) -> Result<(), MapError> {
        let io = |source| MapError::Io { path: path.to_path_buf(), source };
        let text = serde_json::to_string(self)
            .map_err(|e| MapError::Format { path: path.to_path_buf(), message: e.to_string() })?;
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        std::fs::write(&tmp, text).map_err(io)?;
        std::fs::rename(&tmp, path).map_err(io)
    }

    /// Read a map file, checking its format name and version.
    pub fn load(path: &Path) -> Result<Self, MapError> {
        let text = std::fs::read_to_string(path).map_err(|source| MapError::Io { path: path.to_path_buf(), source })?;
        #[derive(Deserialize)]
        struct Header {
            format: String,
            version: u32,
        }
        let fmt = |e: serde_json::Error| MapError::Format { path: path.to_path_buf(), message: e.to_string() };
        let header: Header = serde_json::from_str(&text).map_err(fmt)?;
        if header.format != MAP_FORMAT {
            return Err(MapError::Format {
                path: path.to_path_buf(),
                message: format!("format is {:?}, expected {MAP_FORMAT:?}", header.format),
            });
        }
        if header.version != MAP_VERSION && header.version != 1 {
            return Err(MapError::Version { path: path.to_path_buf(), found: header.version });
        }
        let map: Self = serde_json::from_str(&text).map_err(fmt)?;
        map.check().map_err(|(field, message)| MapError::Invalid { path: path.to_path_buf(), field, message })?;
        Ok(map)
    }

    /// Consistency of a map: every number finite (a right column may be absent), quaternions of unit
    /// length, rotations orthonormal, semi-axes positive, every id referring to something, frames in
    /// increasing order. Returns the first offending field and what is wrong with it.
    pub fn check(&self) -> Result<(), (String, String)> {
        fn pose(field: String, p: &PoseArray) -> Result<(), (String, String)> {
            if !p.iter().all(|v| v.is_finite()) {
                return Err((field, format!("not finite: {p:?}")));
            }
            let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]).sqrt();
            // written maps hold unit quaternions to 1e-15; 1e-3 allows values rounded by hand
            if (n - 1.0).abs() > 1e-3 {
                let what = if n == 0.0 { "zero quaternion".to_string() } else { format!("quaternion of length {n}") };
                return Err((field, format!("{what} (expected unit length)")));
            }
            Ok(())
        }
        for (id, k) in &self.keyframes {
            pose(format!("keyframes.{id}.pose"), &k.pose)?;
            if let Some(p) = k.parent {
                if !self.keyframes.contains_key(&p) {
                    return Err((format!("keyframes.{id}.parent"), format!("keyframe {p} does not exist")));
                }
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
        for (id, p) in &self.points {
            if !p.position.iter().all(|v| v.is_finite()) {
                return Err((format!("points.{id}.position"), format!("not finite: {:?}", p.position)));
            }
            if let Some(k) = p.observed_by.iter().find(|k| !self.keyframes.contains_key(k)) {
                return Err((format!("points.{id}.observed_by"), format!("keyframe {k} does not exist")));
            }
        }
        let mut ids = std::collections::BTreeSet::new();
        for (i, o) in self.objects.iter().enumerate() {
            let at = |f: &str| format!("objects[{i}].{f}");
            if !ids.insert(o.id) {
                return Err((at("id"), format!("id {} appears twice", o.id)));
            }
            if !o.center.iter().chain(&o.rotation).all(|v| v.is_finite()) {
                return Err((at("center/rotation"), "not finite".into()));
            }
            if !o.semi_axes.iter().all(|a| a.is_finite() && *a > 0.0) {
                return Err((at("semi_axes"), format!("must be positive and finite: {:?}", o.semi_axes)));
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
        let mut last = None;
        for (i, f) in self.trajectory.iter().enumerate() {
            if !self.keyframes.contains_key(&f.keyframe) {
                return Err((format!("trajectory[{i}].keyframe"), format!("keyframe {} does not exist", f.keyframe)));
            }
            pose(format!("trajectory[{i}].relative"), &f.relative)?;
            if last.is_some_and(|l| f.frame <= l) {
                return Err((
                    format!("trajectory[{i}].frame"),
                    format!("frame {} after frame {}", f.frame, last.unwrap_or(0)),
                ));
            }
            last = Some(f.frame);
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
        for p in self.points.values() {
            let _ = writeln!(s, "{} {} {}", p.position[0], p.position[1], p.position[2]);
        }
        let io = |source| MapError::Io { path: path.to_path_buf(), source };
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        std::fs::write(&tmp, s).map_err(io)?;
        std::fs::rename(&tmp, path).map_err(io)
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
            },
        );
        m.keyframes
            .insert(1, MapKeyframe { frame: 3, pose: pose_to_array(&pose), parent: Some(0), observations: vec![] });
        m.points.insert(7, MapPoint { position: [0.5, 0.1, 9.0], observed_by: vec![0] });
        m.trajectory.push(FramePose {
            frame: 0,
            keyframe: 0,
            relative: pose_to_array(&Isometry3::identity()),
            state: "initialised".into(),
        });
        m.trajectory.push(FramePose {
            frame: 1,
            keyframe: 1,
            relative: pose_to_array(&pose.inverse()),
            state: "tracked".into(),
        });
        m
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
        assert!(!dir.join("map.json.tmp").exists(), "temporary file renamed away");
        let back = Map::load(&path).expect("loads");
        assert_eq!(back, m);
        let poses = back.frame_poses();
        // frame 1 = keyframe 1 ∘ keyframe-1-from-frame-1 = identity
        let p1 = poses[1].expect("pose");
        assert!(p1.translation.vector.norm() < 1e-12 && p1.rotation.angle() < 1e-12);
        let s = back.stats();
        assert_eq!((s.keyframes, s.segments, s.points, s.observations, s.frames), (2, 1, 1, 1, 2));
        assert!((s.keyframe_path_m - 14f64.sqrt()).abs() < 1e-12);
        m.export_ply(&dir.join("points.ply")).expect("ply");
        let ply = std::fs::read_to_string(dir.join("points.ply")).expect("ply text");
        assert!(ply.contains("element vertex 1") && ply.trim_end().ends_with("0.5 0.1 9"));
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

    /// Bad-input suite, map files: each corruption is refused on load with the file and the field named.
    #[test]
    fn load_refuses_inconsistent_maps_naming_file_and_field() {
        let dir = std::env::temp_dir().join(format!("map-invalid-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        type Corrupt = fn(&mut Map);
        let cases: [(&str, Corrupt, &str, &str); 12] = [
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
                "trajectory-keyframe",
                |m| m.trajectory[1].keyframe = 4,
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
            ("object-axes", |m| m.objects[0].semi_axes[1] = -1.0, "objects[0].semi_axes", "must be positive"),
            ("object-rotation", |m| m.objects[0].rotation[0] = 3.0, "objects[0].rotation", "not a rotation"),
            (
                "object-twice",
                |m| {
                    let o = m.objects[0].clone();
                    m.objects.push(o)
                },
                "objects[1].id",
                "appears twice",
            ),
            ("object-mirror", |m| m.objects[0].rotation[0] = -1.0, "objects[0].rotation", "det -1"),
        ];
        for (name, corrupt, field, what) in cases {
            let mut m = sample();
            m.objects.push(MapObject {
                id: 3,
                class: 2,
                center: [1.0, 0.0, 9.0],
                semi_axes: [2.0, 0.8, 1.0],
                rotation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                frames: vec![0, 1],
                dynamic: false,
                points: vec![7],
            });
            m.check().expect("the sample is consistent");
            corrupt(&mut m);
            let path = dir.join(format!("{name}.json"));
            std::fs::write(&path, serde_json::to_string(&m).expect("json")).expect("write");
            let e = Map::load(&path).expect_err(name).to_string();
            assert!(e.contains(&format!("{name}.json: {field}: ")) && e.contains(what), "{name}: {e}");
        }
        // JSON has no NaN: a non-number where a number belongs is a format error with its line
        let path = dir.join("nan.json");
        let text = serde_json::to_string_pretty(&sample()).expect("json").replacen("0.5,", "NaN,", 1);
        std::fs::write(&path, text).expect("write");
        let e = Map::load(&path).expect_err("NaN").to_string();
        assert!(e.contains("nan.json") && e.contains("line"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
