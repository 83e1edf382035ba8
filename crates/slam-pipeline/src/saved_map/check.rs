//! The checks of a saved map read from a file: every number finite and within bounds, every id naming
//! something, both sides of each observation agreeing, and, with its features and camera, the
//! keyframes' observations matching their keypoints and their poses.

use std::collections::BTreeMap;

use nalgebra::Vector3;
use slam_core::{KeyframeId, PointId};

use super::{pose_from_array, MapCamera, PoseArray, SavedMap};

impl SavedMap {
    /// The features refer to keyframes of the map that are not culled, and to points that exist; every
    /// keyframe that is not culled has its features; each keyframe's observations are the same in the
    /// JSON and in the features file (the same points, at the keypoints' positions).
    pub(super) fn check_features(&self) -> Result<(), (String, String)> {
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

    /// The keyframes of [`SavedMap::check`]: poses, parents that exist and lead back without a cycle,
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

    /// The objects of [`SavedMap::check`]: unique ids, finite centres inside the map, positive bounded
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

    /// The trajectory of [`SavedMap::check`]: keyframes that exist, poses, known states, frames in
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::saved_map::{sample::sample, ObjectView, SavedMapPoint, SavedObject};

    /// A map file holding a point beyond the Earth's diameter is refused when loaded, naming the point
    /// (its PLY exports refuse what a 32-bit float cannot hold: slam-runner's `map_export`).
    #[test]
    fn coordinates_beyond_the_earth_are_refused() {
        let dir = std::env::temp_dir().join(format!("map-far-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let mut m = sample();
        m.points.insert(9, SavedMapPoint { position: [0.0, 1e300, 0.0], observed_by: vec![0] });
        m.save(&dir.join("far.json")).expect("saves");
        let e = SavedMap::load(&dir.join("far.json")).expect_err("far").to_string();
        assert!(e.contains("points.9.position") && e.contains("Earth's diameter"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A corruption of a consistent map: its name (the file's), the change, the field the error must
    /// name and a phrase the message must hold.
    type Corruption = (&'static str, fn(&mut SavedMap), &'static str, &'static str);

    /// The sample map with one object (id 3, car, texture point 7), consistent.
    fn sample_with_object() -> SavedMap {
        let mut m = sample();
        m.objects.push(SavedObject {
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
            let e = SavedMap::load(&path).expect_err(name).to_string();
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
}
