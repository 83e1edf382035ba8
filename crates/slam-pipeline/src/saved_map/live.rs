//! Live map to file and back: the saved form of a run's live map ([`slam_core::Map`], which the
//! tracking thread owns), made when the run ends ([`SavedMap::from_live`]), and a live map rebuilt from
//! a saved map for a later run to track against and extend ([`SavedMap::to_live`]), after checking
//! that the run's camera is the one the map was made with.

use std::sync::Arc;

use nalgebra::{Isometry3, Vector3};
use slam_core::{
    map::{Features, Keyframe, SavedPoint, StereoCamera},
    KeyframeId,
};

use super::{
    pose_from_array, pose_to_array, MapCamera, SavedFeatures, SavedKeyframe, SavedMap, SavedMapPoint, SavedObject,
};

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
    pub objects: Vec<SavedObject>,
    /// The keyframes' keypoints were re-expressed in the run's camera (another calibration of a
    /// rectified rig, accepted for localisation only).
    pub reexpressed: bool,
    /// The frame whose camera is the map's world ([`SavedMap::first_frame`]).
    pub first_frame: Option<usize>,
    /// The map's world in the ground truth of the run that made it, when it says.
    pub ground_truth_world: Option<super::GroundTruthWorld>,
}

/// Why a map file cannot be tracked against.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ToLiveError {
    /// A file without features (written before version 4).
    #[error("the map has no keyframe features to track against (format version {0}; version 4 and later keep them): make the map again with this build")]
    NoFeatures(u32),
    /// A map without a keyframe (nothing was tracked when it was made).
    #[error("the map holds no keyframe: there is nothing to localise in")]
    Empty,
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

impl SavedMap {
    /// The saved form of a run's live map (`slam_core::Map`): its keyframes with their observations and
    /// features, the keyframes culled from it (at their poses, without observations, marked culled),
    /// its points, its camera; no objects and no trajectory yet.
    pub fn from_live(live: &slam_core::Map) -> Self {
        let mut m = SavedMap::default();
        for k in live.keyframes() {
            let observations = k.observations().map(|(kp, p)| (p, k.features.keypoints[kp].observation())).collect();
            let stored = SavedKeyframe {
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
            let stored = SavedKeyframe {
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
            m.points.insert(id, SavedMapPoint { position: [p.position.x, p.position.y, p.position.z], observed_by });
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
        if self.keyframes.values().all(|k| k.culled) {
            return Err(ToLiveError::Empty);
        }
        if self.keyframe_features.is_empty() {
            return Err(ToLiveError::NoFeatures(self.version));
        }
        let made = self.camera.ok_or(ToLiveError::NoCamera(self.version))?;
        let differences = made.differences(run);
        if !(differences.is_empty() || reexpress) {
            return Err(CameraMismatch(differences).into());
        }
        let moved = !differences.is_empty();
        let pyramid = slam_core::map::ScalePyramid::default();
        let mut keyframes = Vec::with_capacity(self.keyframe_features.len());
        for (&id, f) in &self.keyframe_features {
            let Some(k) = self.keyframes.get(&id) else { continue };
            keyframes.push(live_keyframe(id, k, f, &made, moved.then_some(run), pyramid.levels)?);
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
        let camera = StereoCamera {
            k: slam_core::geometry::Intrinsics::new(run.fx, run.fy, run.cx, run.cy),
            baseline: run.baseline,
        };
        let mut map = slam_core::Map::restore(camera, pyramid, keyframes, &points)?;
        // a culled keyframe's id is never given again (an object's detection may name it)
        if let Some(&last) = self.keyframes.keys().next_back() {
            map.reserve_keyframe_ids(last.saturating_add(1));
        }
        Ok(LoadedMap {
            map,
            objects: self.objects.clone(),
            reexpressed: moved,
            first_frame: self.first_frame(),
            ground_truth_world: self.ground_truth_world,
        })
    }
}

/// One keyframe of the live map, from its saved pose and features: checked against the camera the map
/// was made with (`made`: the image size) and the pyramid's `levels`, its keypoints re-expressed for
/// the run's camera `to` when it differs ([`SavedMap::to_live`]), its observations put in their
/// keypoints' slots.
fn live_keyframe(
    id: KeyframeId,
    k: &SavedKeyframe,
    f: &SavedFeatures,
    made: &MapCamera,
    to: Option<&MapCamera>,
    levels: u8,
) -> Result<Keyframe, ToLiveError> {
    let bad = |why: String| slam_core::map::RestoreError::Keyframe { id, why };
    if f.size != (made.width, made.height) {
        return Err(bad(format!(
            "features of a {}×{} image, the map's camera {}×{}",
            f.size.0, f.size.1, made.width, made.height
        ))
        .into());
    }
    if let Some(kp) = f.keypoints.iter().find(|kp| kp.level >= levels) {
        return Err(bad(format!("a keypoint of pyramid level {}, the map has {} levels", kp.level, levels)).into());
    }
    let mut keypoints = f.keypoints.clone();
    if let Some(run) = to {
        let (sx, sy) = (run.fx / made.fx, run.fy / made.fy);
        let disparity = (run.fx * run.baseline) / (made.fx * made.baseline);
        for kp in &mut keypoints {
            let d = kp.u - kp.u_right;
            kp.u = sx * (kp.u - made.cx) + run.cx;
            kp.v = sy * (kp.v - made.cy) + run.cy;
            kp.u_right = kp.u - d * disparity;
        }
    }
    let size = to.map_or(f.size, |run| (run.width, run.height));
    let features = Features::new(keypoints, f.descriptors.clone(), size)
        .ok_or_else(|| bad("keypoints and descriptors differ in number".into()))?;
    let mut kf = Keyframe::new(id, k.frame, pose_from_array(&k.pose), k.parent, Arc::new(features));
    for &(kp, p) in &f.observations {
        if let Some(slot) = kf.points.get_mut(kp as usize) {
            *slot = Some(p);
        }
    }
    Ok(kf)
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use slam_core::{
        geometry::Intrinsics,
        map::{CreationPolicy, Keypoint, NewKeyframe, ScalePyramid},
    };

    use super::*;

    fn camera() -> StereoCamera {
        StereoCamera { k: Intrinsics::new(707.0, 707.0, 601.9, 183.1), baseline: 0.54 }
    }

    /// Two keyframes 1 m apart seeing the same 60 points (the second matched to the first's).
    fn live() -> slam_core::Map {
        let cam = camera();
        let mut m = slam_core::Map::new(cam, ScalePyramid::default());
        let points: Vec<Vector3<f64>> = (0..60)
            .map(|i| Vector3::new(f64::from(i % 10) - 4.5, f64::from(i / 10) * 0.5 - 1.5, 8.0 + f64::from(i % 7)))
            .collect();
        for n in 0..2u64 {
            let pose = Isometry3::translation(0.0, 0.0, n as f64);
            let keypoints = points
                .iter()
                .map(|p| {
                    let o = cam.observe(&(p - pose.translation.vector));
                    Keypoint { u: o[0], v: o[1], u_right: o[2], level: 0, angle: 30.0 }
                })
                .collect();
            let descriptors = (0..60u8).map(|i| [i.wrapping_mul(37); 32]).collect();
            let features = Features::new(keypoints, descriptors, (1226.0, 370.0)).expect("features");
            let matched = match m.keyframe(0) {
                Some(k) => k.points.clone(),
                None => vec![None; 60],
            };
            let kf = NewKeyframe {
                id: n,
                frame: n as usize,
                pose,
                parent: n.checked_sub(1),
                features: Arc::new(features),
                matched,
            };
            m.insert_keyframe(kf, &CreationPolicy::default()).expect("inserted");
        }
        m
    }

    fn folder(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("slam-map-live-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("folder");
        d
    }

    /// Saved and loaded, a map rebuilds the live map it was made from: keyframes, points, the
    /// observations of each, the covisibility; its keypoints to f32 precision.
    #[test]
    fn a_saved_map_loads_back_and_rebuilds_its_live_map() {
        let live = live();
        let map = SavedMap::from_live(&live);
        assert_eq!(map.camera, Some(MapCamera::of(&camera(), (1226.0, 370.0))));
        let d = folder("roundtrip");
        let file = d.join("map.json");
        map.save(&file).expect("saved");
        assert!(super::super::features_path(&file).is_file(), "features beside the JSON");
        let back = SavedMap::load(&file).expect("loads");
        assert_eq!(back.keyframe_features.len(), 2);
        for (id, f) in &map.keyframe_features {
            let g = &back.keyframe_features[id];
            assert_eq!((&g.descriptors, &g.observations, g.size), (&f.descriptors, &f.observations, f.size));
            for (a, b) in g.keypoints.iter().zip(&f.keypoints) {
                assert!((a.u - b.u).abs() < 1e-3 && (a.v - b.v).abs() < 1e-3 && (a.u_right - b.u_right).abs() < 1e-3);
            }
        }
        let rebuilt = back.to_live(&MapCamera::of(&camera(), (1226.0, 370.0)), false).expect("rebuilt");
        assert!(!rebuilt.reexpressed);
        let m = rebuilt.map;
        m.check().expect("consistent");
        assert_eq!((m.keyframe_count(), m.point_count()), (live.keyframe_count(), live.point_count()));
        assert_eq!(m.covisibility().weight(0, 1), live.covisibility().weight(0, 1));
        assert!(m.covisibility().weight(0, 1) >= 50, "{}", m.covisibility().weight(0, 1));
        for (id, p) in live.points() {
            assert_eq!(m.point(id).map(|q| &q.observations), Some(&p.observations), "point {id}");
        }
        assert_eq!(m.next_keyframe_id(), 2);
        let _ = std::fs::remove_dir_all(d);
    }

    /// A damaged or missing features file, a file of another map, another camera and a map without
    /// features are refused with what is wrong; another calibration is accepted for localisation,
    /// each keypoint moved to where the run's camera sees its ray.
    #[test]
    fn damage_other_cameras_and_old_maps_are_refused_with_the_reason() {
        let map = SavedMap::from_live(&live());
        let d = folder("damage");
        let file = d.join("map.json");
        map.save(&file).expect("saved");
        let side = super::super::features_path(&file);
        let mut bytes = std::fs::read(&side).expect("features");
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(&side, &bytes).expect("damaged");
        let e = SavedMap::load(&file).expect_err("damaged").to_string();
        assert!(e.contains("map.features") && e.contains("checksum"), "{e}");
        std::fs::remove_file(&side).expect("removed");
        let e = SavedMap::load(&file).expect_err("missing").to_string();
        assert!(e.contains("map.features"), "{e}");
        let run = MapCamera { fx: 718.856, cx: 607.19, ..MapCamera::of(&camera(), (1241.0, 376.0)) };
        let e = map.to_live(&run, false).expect_err("another camera").to_string();
        assert!(e.contains("fx 707 px in the map, 718.856 px here") && e.contains("images 1226×370"), "{e}");
        let moved = map.to_live(&run, true).expect("re-expressed for localisation");
        assert!(moved.reexpressed);
        let (a, b) =
            (&map.keyframe_features[&0].keypoints[3], &moved.map.keyframe(0).expect("kf").features.keypoints[3]);
        assert!((b.u - (718.856 / 707.0 * (a.u - 601.9) + 607.19)).abs() < 1e-9);
        // the same depth: disparity scaled by the focal lengths (same baseline)
        assert!(((b.u - b.u_right) - (a.u - a.u_right) * 718.856 / 707.0).abs() < 1e-9);
        let old = SavedMap { keyframe_features: Default::default(), features: None, ..map.clone() };
        let e = old.to_live(&MapCamera::of(&camera(), (1226.0, 370.0)), false).expect_err("no features");
        assert!(matches!(e, ToLiveError::NoFeatures(_)), "{e}");
        let _ = std::fs::remove_dir_all(d);
    }

    /// A map file is checked whole before a run uses it, and what fails is refused naming the field:
    /// a keyframe id written twice (JSON keeps the last copy), a camera that cannot be right (a focal
    /// length of 1e300 px or 0, a baseline of 0 or below), observations on one side only (a keyframe's
    /// emptied, a point's `observed_by` naming a keyframe that does not observe it), a point moved to
    /// 1e5 m, a keyframe pose moved 1 m sideways (most of its observations beyond the noise) or 100 m, a
    /// keyframe without features and features without observations (the checksum made right again).
    /// The same pair found through a symbolic link to its JSON and copied under another name loads.
    #[test]
    fn a_map_is_checked_whole_and_refused_naming_what_and_where() {
        let d = folder("whole");
        let good = SavedMap::from_live(&live());
        let refused = |name: &str, m: &SavedMap| -> String {
            let file = d.join(format!("{name}.json"));
            m.save(&file).expect("saved");
            SavedMap::load(&file).expect_err(name).to_string()
        };
        let with = |edit: &dyn Fn(&mut SavedMap)| {
            let mut m = good.clone();
            edit(&mut m);
            m
        };
        let expect = |name: &str, m: &SavedMap, field: &str, why: &str| {
            let e = refused(name, m);
            assert!(e.contains(&format!("{name}.json: {field}")) && e.contains(why), "{name}: {e}");
        };
        // an id twice in the file
        let file = d.join("twice.json");
        good.save(&file).expect("saved");
        let text = std::fs::read_to_string(&file).expect("json");
        let at = text.find("\"1\":{\"frame\"").expect("keyframe 1");
        let copy = text[at..].split_once("},\"").map(|(k, _)| k).expect("its end");
        std::fs::write(&file, format!("{}{copy},{}", &text[..at], &text[at..])).expect("edited");
        let e = SavedMap::load(&file).expect_err("twice").to_string();
        assert!(e.contains("keyframes") && e.contains("id 1 appears twice"), "{e}");
        // the camera
        for (name, edit, field) in [
            ("fx-huge", (|c: &mut MapCamera| c.fx = 1e300) as fn(&mut MapCamera), "camera.fx"),
            ("fx-zero", |c| c.fx = 0.0, "camera.fx"),
            ("baseline-zero", |c| c.baseline = 0.0, "camera.baseline"),
            ("baseline-negative", |c| c.baseline = -0.54, "camera.baseline"),
        ] {
            let m = with(&|m: &mut SavedMap| edit(m.camera.as_mut().expect("camera")));
            expect(name, &m, field, "must be a finite number in");
        }
        // both sides of an observation
        let m = with(&|m: &mut SavedMap| m.keyframes.get_mut(&1).expect("kf").observations.clear());
        expect("no-observations", &m, "points.", "each side must name the other");
        let m = with(&|m: &mut SavedMap| {
            let p = m.points.values_mut().next().expect("point");
            p.observed_by = vec![0];
        });
        expect("observed-by", &m, "points.", "the keyframes observing it are [0, 1]");
        // positions that disagree with the observations
        let m = with(&|m: &mut SavedMap| m.points.values_mut().next().expect("point").position[0] = 1e5);
        expect("far-point", &m, "keyframes.0.observations[", "farther than the image is wide");
        let moved = |dx: f64| {
            move |m: &mut SavedMap| {
                let k = m.keyframes.get_mut(&1).expect("kf");
                k.pose[4] += dx;
            }
        };
        expect("pose-1m", &with(&moved(1.0)), "keyframes.1.pose", "60 of its 60 observations");
        expect("pose-100m", &with(&moved(100.0)), "keyframes.1.observations[", "the image is wide");
        // the features file against the JSON (the features file written anew, its checksum right)
        let m = with(&|m: &mut SavedMap| drop(m.keyframe_features.remove(&1)));
        expect("no-features", &m, "keyframes.1", "holds no features of it");
        let m = with(&|m: &mut SavedMap| m.keyframe_features.values_mut().for_each(|f| f.observations.clear()));
        expect("features-emptied", &m, "keyframes.0.observations", "not in the features file");
        // the right pair through a link, and copied under another name
        let made = d.join("made");
        std::fs::create_dir_all(&made).expect("folder");
        good.save(&made.join("map.json")).expect("saved");
        std::os::unix::fs::symlink(made.join("map.json"), d.join("06.json")).expect("link");
        assert_eq!(SavedMap::load(&d.join("06.json")).expect("through the link").keyframe_features.len(), 2);
        let copy = d.join("copy");
        std::fs::create_dir_all(&copy).expect("folder");
        std::fs::copy(made.join("map.json"), copy.join("06.json")).expect("json");
        std::fs::copy(made.join("map.features"), copy.join("06.features")).expect("features");
        assert_eq!(SavedMap::load(&copy.join("06.json")).expect("renamed pair").keyframe_features.len(), 2);
        std::fs::remove_file(copy.join("06.features")).expect("removed");
        let e = SavedMap::load(&copy.join("06.json")).expect_err("no features").to_string();
        assert!(e.contains("is in none of") && e.contains("06.features"), "{e}");
        let _ = std::fs::remove_dir_all(d);
    }
}
