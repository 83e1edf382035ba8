//! Saving and loading a saved map: `map.json` and the keyframes' features file beside it, each written
//! atomically, and read back with their format, version, checksum and values checked.

use std::{
    collections::BTreeMap,
    path::{Path, PathBuf},
};

use serde::Deserialize;
use slam_core::KeyframeId;

use super::{features, FeaturesRef, SavedFeatures, SavedMap, MAP_FORMAT, MAP_VERSION};

/// Why a map could not be saved or loaded.
#[derive(Debug, thiserror::Error)]
pub enum SavedMapError {
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

impl SavedMap {
    /// Write the map as JSON, atomically (a temporary file beside it, then a rename).
    /// The keyframes' features go to a binary file beside it ([`features`], `map.features` for
    /// `map.json`), also atomically, and the JSON names that file with its length and checksum. Both
    /// are made in memory first and written one right after the other (features, then JSON), so only
    /// a stop between the two renames leaves a new features file beside the old JSON: a pair that
    /// [`SavedMap::load`] refuses rather than mixes. (A run writes into a new output folder that replaces
    /// the old one whole, so a stopped run leaves the old pair as it was.)
    pub fn save(&self, path: &Path) -> Result<(), SavedMapError> {
        let invalid =
            |message: String| SavedMapError::Invalid { path: path.to_path_buf(), field: "features".into(), message };
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
        let fmt = |e: serde_json::Error| SavedMapError::Format { path: path.to_path_buf(), message: e.to_string() };
        let reference = side.as_ref().map(|s| s.2.clone());
        let text = if reference == self.features {
            serde_json::to_string(self).map_err(fmt)?
        } else {
            let head = SavedMap { features: reference, keyframe_features: BTreeMap::new(), ..self.clone() };
            serde_json::to_string(&head).map_err(fmt)?
        };
        if let Some((side, bytes, _)) = side {
            slam_core::files::write_atomic(&side, &bytes)?;
        }
        Ok(slam_core::files::write_atomic(path, text.as_bytes())?)
    }

    /// Read a map file and its features file ([`SavedMap::load_without_features`], then the features file
    /// it names, its length and checksum checked, its keyframes and points those of the map): what a
    /// run tracks against.
    pub fn load(path: &Path) -> Result<Self, SavedMapError> {
        let mut map = Self::load_without_features(path)?;
        if let Some(r) = &map.features {
            map.keyframe_features = read_features(path, r)?;
            map.check_features().map_err(|(field, message)| SavedMapError::Invalid {
                path: path.to_path_buf(),
                field,
                message,
            })?;
        }
        Ok(map)
    }

    /// Read a map file alone (not its features file: `keyframe_features` stays empty), checking its
    /// format name, version and values ([`SavedMap::check`]): enough to inspect and export it.
    pub fn load_without_features(path: &Path) -> Result<Self, SavedMapError> {
        if path.extension().is_some_and(|e| e == "features") {
            return Err(SavedMapError::Format {
                path: path.to_path_buf(),
                message: "this is a map's features file; give the map's JSON file beside it (map.json)".into(),
            });
        }
        let text = slam_core::files::read_text(path, &slam_core::files::DOCUMENT).map_err(|e| match e {
            slam_core::files::ReadError::Io { path, source } => SavedMapError::Io { path, source },
            other => SavedMapError::Read(other),
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
            SavedMapError::Format { path: path.to_path_buf(), message }
        };
        let header: Header = serde_json::from_str(&text).map_err(|e| {
            // an object map (objects.json) has "objects" but no "format": say which file to give
            let objects_only = serde_json::from_str::<serde_json::Value>(&text)
                .is_ok_and(|v| v.get("objects").is_some() && v.get("format").is_none());
            if objects_only {
                SavedMapError::Format {
                    path: path.to_path_buf(),
                    message: "this is an object map (a run's objects.json), not a map; give the run's map.json".into(),
                }
            } else {
                fmt(e)
            }
        })?;
        if header.format != MAP_FORMAT {
            return Err(SavedMapError::Format {
                path: path.to_path_buf(),
                message: format!("format is {:?}, expected {MAP_FORMAT:?}", header.format),
            });
        }
        if !(1..=MAP_VERSION).contains(&header.version) {
            return Err(SavedMapError::Version { path: path.to_path_buf(), found: header.version });
        }
        let map: Self = serde_json::from_str(&text).map_err(fmt)?;
        map.check().map_err(|(field, message)| SavedMapError::Invalid { path: path.to_path_buf(), field, message })?;
        Ok(map)
    }
}

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
fn read_features(path: &Path, r: &FeaturesRef) -> Result<BTreeMap<KeyframeId, SavedFeatures>, SavedMapError> {
    let invalid =
        |message: String| SavedMapError::Invalid { path: path.to_path_buf(), field: "features".into(), message };
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::saved_map::sample::sample;

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
        let back = SavedMap::load(&path).expect("loads");
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
        let e = SavedMap::load(&path).expect_err("not a map").to_string();
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
        let m = SavedMap::load(&path).expect("a version-1 map loads");
        assert_eq!(m.version, 1);
        assert_eq!(m.keyframes[&0].observations, vec![(7, [1.0, 2.0, 0.5]), (8, [10.0, 20.0, 4.25])]);
        assert_eq!(m.keyframes[&1].parent, Some(0));
        assert_eq!(m.points[&7].observed_by, vec![0, 1]);
        assert_eq!((m.objects.len(), m.objects[0].class, m.objects[0].points.clone()), (1, 2, vec![8]));
        let s = m.stats();
        assert_eq!((s.keyframes, s.segments, s.points, s.observations, s.frames), (2, 1, 2, 3, 1));
        let again = SavedMap { version: MAP_VERSION, ..m.clone() };
        again.save(&dir.join("v2.json")).expect("saves");
        let back = SavedMap::load(&dir.join("v2.json")).expect("loads");
        assert_eq!((back.version, back.keyframes, back.points), (MAP_VERSION, m.keyframes, m.points));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn load_rejects_other_files_with_their_path() {
        let dir = std::env::temp_dir().join(format!("map-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let wrong = dir.join("wrong.json");
        std::fs::write(&wrong, r#"{"format": "something-else", "version": 1}"#).expect("write");
        let e = SavedMap::load(&wrong).expect_err("wrong format").to_string();
        assert!(e.contains("wrong.json") && e.contains("something-else"), "{e}");
        let newer = dir.join("newer.json");
        std::fs::write(&newer, format!(r#"{{"format": "{MAP_FORMAT}", "version": 99}}"#)).expect("write");
        let e = SavedMap::load(&newer).expect_err("version").to_string();
        assert!(e.contains("version 99"), "{e}");
        let broken = dir.join("broken.json");
        std::fs::write(&broken, "{\n  \"format\": ").expect("write");
        let e = SavedMap::load(&broken).expect_err("syntax").to_string();
        assert!(e.contains("broken.json") && e.contains("line 2"), "{e}");
        let e = SavedMap::load(&dir.join("missing.json")).expect_err("missing").to_string();
        assert!(e.contains("missing.json"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// JSON has no NaN: a non-number where a number belongs is a format error with its line.
    #[test]
    fn load_refuses_a_nan_naming_file_and_line() {
        let dir = std::env::temp_dir().join(format!("map-nan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let path = dir.join("nan.json");
        let text = serde_json::to_string_pretty(&sample()).expect("json").replacen("0.5,", "NaN,", 1);
        std::fs::write(&path, text).expect("write");
        let e = SavedMap::load(&path).expect_err("NaN").to_string();
        assert!(e.contains("nan.json") && e.contains("line"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
