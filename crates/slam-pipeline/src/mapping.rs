//! Local mapping: keyframes into the map, local bundle adjustment over a window of recent keyframes
//! (the optimisation crate's stereo reprojection factor, Huber; the left-only reprojection factor for
//! observations of triangulated points), and culling of outlier observations.

use std::collections::{BTreeMap, BTreeSet};

use nalgebra::{Isometry3, Point3, Vector3};
use slam_core::{geometry::Intrinsics, KeyframeCorrection, KeyframeData, KeyframeId, PointId};
use slam_optim::{
    factors::{MonoReprojection, StereoReprojection},
    Graph, Huber, NoiseModel, Options, SharedOptimizer, Values, Var,
};

use crate::map::{pose_to_array, Map, MapKeyframe, MapPoint};

/// Settings of the local mapper.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, documented::DocumentedFieldsOpt)]
#[serde(default, deny_unknown_fields)]
pub struct MappingConfig {
    /// Keyframes optimised together (the newest ones of the current map segment). Default 6.
    pub window: usize,
    /// Huber threshold of the stereo reprojection error, pixels. Default √7.815 ≈ 2.80 (the 95 % χ² bound
    /// of a 3-D residual at σ = 1 px).
    pub huber_px: f64,
    /// Observations whose squared error (px²) exceeds this after the adjustment are culled. Default 7.815.
    pub cull_chi2: f64,
    /// The same for left-only observations (2-D residual). Default 5.991 (95 % χ², 2 degrees of freedom).
    pub cull_chi2_mono: f64,
    /// Levenberg-Marquardt iterations per adjustment. Default 10.
    pub iterations: usize,
    /// Run bundle adjustment at all (off: keyframes are only inserted). Default on.
    pub bundle_adjustment: bool,
}

impl Default for MappingConfig {
    fn default() -> Self {
        Self {
            window: 6,
            huber_px: 7.815f64.sqrt(),
            cull_chi2: 7.815,
            cull_chi2_mono: 5.991,
            iterations: 10,
            bundle_adjustment: true,
        }
    }
}

/// Most keyframes held fixed in a local adjustment, per keyframe of the window. While a car drives,
/// the keyframes that see the window's points are those the points stayed in view for: at most 15 on
/// the dev drives (odometry 06, raw 0005; 6 free). Standing still or driving over the same road again,
/// every keyframe of the place sees them, and without a bound the adjustment would grow with the run
/// (500 fixed keyframes after 2000 frames standing still, 0.6 s per keyframe). Four times the window
/// keeps an adjustment within a constant factor of the window's own size, as the tracker's local map is.
pub const FIXED_PER_WINDOW: usize = 4;

/// Result of inserting a keyframe.
#[derive(Debug, Clone, PartialEq)]
pub struct MappingReport {
    /// What to send back to the tracker.
    pub correction: KeyframeCorrection,
    /// Keyframes adjusted (free) and held fixed.
    pub window: (usize, usize),
    /// Observations culled.
    pub culled_observations: usize,
    /// Milliseconds in the adjustment.
    pub ba_ms: f64,
}

/// Owner of the map's keyframes and points.
pub struct LocalMapper {
    map: Map,
    k: Intrinsics,
    baseline: f64,
    config: MappingConfig,
    optimizer: SharedOptimizer,
}

impl LocalMapper {
    /// A mapper for a rectified stereo rig; local BA uses `optimizer`.
    pub fn new(k: Intrinsics, baseline: f64, config: MappingConfig, optimizer: SharedOptimizer) -> Self {
        Self { map: Map::default(), k, baseline, config, optimizer }
    }

    /// The stereo rig: left intrinsics and baseline, metres.
    pub fn rig(&self) -> (Intrinsics, f64) {
        (self.k, self.baseline)
    }

    /// The map so far.
    pub fn map(&self) -> &Map {
        &self.map
    }

    /// Mutable access for the pipeline (objects, trajectory).
    pub fn map_mut(&mut self) -> &mut Map {
        &mut self.map
    }

    /// Give up the map.
    pub fn into_map(self) -> Map {
        self.map
    }

    fn project(&self, pose: &Isometry3<f64>, x: &Vector3<f64>) -> Option<[f64; 3]> {
        let c = pose.inverse() * Point3::from(*x);
        (c.z > 0.1).then(|| {
            let u = self.k.fx * c.x / c.z + self.k.cx;
            [u, self.k.fy * c.y / c.z + self.k.cy, u - self.k.fx * self.baseline / c.z]
        })
    }

    /// Insert a keyframe (its pose chained to its parent's refined pose), adjust the local window and
    /// cull outliers.
    pub fn insert_keyframe(&mut self, kf: &KeyframeData) -> MappingReport {
        let pose = match kf.parent {
            Some((p, rel)) => self.map.keyframe_pose(p).map(|pp| pp * rel).unwrap_or(kf.world_from_camera),
            None => kf.world_from_camera,
        };
        // a left-only observation has a NaN right column; anything else non-finite is unusable
        let usable = |p: &slam_core::KeyframePoint| {
            p.observation[..2].iter().chain(p.camera_point.iter()).all(|v| v.is_finite())
                && !p.observation[2].is_infinite()
        };
        let mut observations = Vec::with_capacity(kf.points.len());
        for p in kf.points.iter().filter(|p| usable(p)) {
            let entry = self.map.points.entry(p.id).or_insert_with(|| {
                let x = pose * Point3::from(p.camera_point);
                MapPoint { position: [x.x, x.y, x.z], observed_by: Vec::new() }
            });
            entry.observed_by.push(kf.id);
            observations.push((p.id, p.observation));
        }
        self.map.keyframes.insert(
            kf.id,
            MapKeyframe { frame: kf.frame, pose: pose_to_array(&pose), parent: kf.parent.map(|p| p.0), observations },
        );
        // triangulated points: their observations in the earlier keyframe they were triangulated with
        for (earlier, p) in kf.earlier.iter().filter(|(_, p)| usable(p)) {
            let (Some(k), Some(point)) = (self.map.keyframes.get_mut(earlier), self.map.points.get_mut(&p.id)) else {
                continue;
            };
            k.observations.push((p.id, p.observation));
            point.observed_by.push(*earlier);
        }
        let start = std::time::Instant::now();
        let (window, culled) = if self.config.bundle_adjustment { self.adjust(kf.id) } else { ((0, 0), 0) };
        let ba_ms = start.elapsed().as_secs_f64() * 1e3;
        let mut culled_ids = Vec::new();
        let mut points = Vec::new();
        if let Some(k) = self.map.keyframes.get(&kf.id) {
            let kept: BTreeSet<PointId> = k.observations.iter().map(|o| o.0).collect();
            for p in &kf.points {
                if kept.contains(&p.id) {
                    if let Some(x) = self.map.point(p.id) {
                        points.push((p.id, x));
                    }
                } else {
                    culled_ids.push(p.id);
                }
            }
        }
        MappingReport {
            correction: KeyframeCorrection {
                id: kf.id,
                world_from_camera: self.map.keyframe_pose(kf.id).unwrap_or(pose),
                points,
                culled: culled_ids,
            },
            window,
            culled_observations: culled,
            ba_ms,
        }
    }

    /// Bundle adjustment of the newest keyframes of `newest`'s segment; returns (free, fixed) keyframe
    /// counts and the number of culled observations.
    fn adjust(&mut self, newest: KeyframeId) -> ((usize, usize), usize) {
        let window = self.window(newest);
        let window_set: BTreeSet<KeyframeId> = window.iter().copied().collect();
        let (local_points, fixed) = self.local_points_and_gauge(&window);
        if window.len() < 2 && fixed.iter().all(|f| window_set.contains(f)) {
            return ((0, fixed.len()), 0);
        }
        let mut problem = self.problem(&window_set, &fixed, &local_points);
        let options = Options::with_max_iterations(self.config.iterations);
        if let Err(e) = self.optimizer.optimize(&problem.graph, &mut problem.values, &options, None) {
            tracing::warn!(keyframe = newest, "local bundle adjustment failed: {e}");
            return ((0, fixed.len()), 0);
        }
        self.write_back(&problem, &fixed);
        let culled = self.cull(&window);
        ((window_set.len() - window_set.intersection(&fixed).count(), fixed.len()), culled)
    }

    /// The window: the newest keyframes back to the segment's start, at most `config.window`, newest
    /// first.
    fn window(&self, newest: KeyframeId) -> Vec<KeyframeId> {
        let mut window = Vec::new();
        for (&id, k) in self.map.keyframes.range(..=newest).rev() {
            window.push(id);
            if k.parent.is_none() || window.len() >= self.config.window {
                break;
            }
        }
        window
    }

    /// The window's points seen at least twice (a point seen by one keyframe only says nothing about
    /// the poses: its stereo observation alone fixes it), and the keyframes held fixed: those outside
    /// the window that see them, at most [`FIXED_PER_WINDOW`] times the window (the ones sharing the
    /// most points with it, then the newest), or, at a segment's start, the window's oldest (the gauge).
    fn local_points_and_gauge(&self, window: &[KeyframeId]) -> (BTreeSet<PointId>, BTreeSet<KeyframeId>) {
        let local_points: BTreeSet<PointId> = window
            .iter()
            .filter_map(|id| self.map.keyframes.get(id))
            .flat_map(|k| k.observations.iter().map(|o| o.0))
            .filter(|p| self.map.points.get(p).is_some_and(|x| x.observed_by.len() >= 2))
            .collect();
        let mut shared: BTreeMap<KeyframeId, usize> = BTreeMap::new();
        for k in local_points.iter().filter_map(|p| self.map.points.get(p)).flat_map(|p| p.observed_by.iter()) {
            if !window.contains(k) {
                *shared.entry(*k).or_default() += 1;
            }
        }
        let mut ranked: Vec<(KeyframeId, usize)> = shared.into_iter().collect();
        ranked.sort_by(|a, b| b.1.cmp(&a.1).then(b.0.cmp(&a.0)));
        ranked.truncate(FIXED_PER_WINDOW * window.len().max(1));
        let mut fixed: BTreeSet<KeyframeId> = ranked.into_iter().map(|(k, _)| k).collect();
        if fixed.is_empty() {
            if let Some(&oldest) = window.last() {
                fixed.insert(oldest);
            }
        }
        (local_points, fixed)
    }

    /// The adjustment's graph: poses of the window and the fixed keyframes, the local points
    /// (eliminated), and a stereo or left-only reprojection factor (Huber) per observation.
    fn problem(
        &self,
        window: &BTreeSet<KeyframeId>,
        fixed: &BTreeSet<KeyframeId>,
        local_points: &BTreeSet<PointId>,
    ) -> BaProblem {
        let mut p = BaProblem {
            graph: Graph::new(),
            values: Values::new(),
            pose_keys: BTreeMap::new(),
            point_keys: BTreeMap::new(),
        };
        for id in window.union(fixed) {
            let Some(pose) = self.map.keyframe_pose(*id) else { continue };
            let key = p.values.add(Var::Pose(pose));
            if fixed.contains(id) {
                p.graph.fix(key);
            }
            p.pose_keys.insert(*id, key);
        }
        for pid in local_points {
            let Some(x) = self.map.point(*pid) else { continue };
            let key = p.values.add(Var::Point(x));
            p.graph.eliminate(key);
            p.point_keys.insert(*pid, key);
        }
        for (kid, &pk) in &p.pose_keys {
            let Some(k) = self.map.keyframes.get(kid) else { continue };
            for (pid, obs) in &k.observations {
                let Some(&xk) = p.point_keys.get(pid) else { continue };
                let (noise, huber) = (NoiseModel::Isotropic(1.0), Huber(self.config.huber_px));
                let added = if obs[2].is_nan() {
                    p.graph.add(MonoReprojection::new(pk, xk, self.k, [obs[0], obs[1]]), noise, huber)
                } else {
                    p.graph.add(StereoReprojection::new(pk, xk, self.k, self.baseline, *obs), noise, huber)
                };
                // an isotropic 1 px noise fits every reprojection factor; should that change, the
                // observation is left out and said so
                if let Err(e) = added {
                    tracing::warn!(keyframe = kid, point = pid, "observation left out of local BA: {e}");
                }
            }
        }
        p
    }

    /// Store the adjusted poses of the free keyframes and the finite adjusted points.
    fn write_back(&mut self, p: &BaProblem, fixed: &BTreeSet<KeyframeId>) {
        for (kid, key) in &p.pose_keys {
            if fixed.contains(kid) {
                continue;
            }
            if let (Some(pose), Some(k)) = (p.values.pose(*key), self.map.keyframes.get_mut(kid)) {
                k.pose = pose_to_array(pose);
            }
        }
        for (pid, key) in &p.point_keys {
            if let (Some(x), Some(point)) = (p.values.point(*key), self.map.points.get_mut(pid)) {
                if x.iter().all(|v| v.is_finite()) {
                    point.position = [x.x, x.y, x.z];
                }
            }
        }
    }

    /// Cull the window's observations that still disagree with the adjusted map (χ² bounds), then the
    /// points nobody sees; returns the number of culled observations.
    fn cull(&mut self, window: &[KeyframeId]) -> usize {
        let mut culled = 0;
        for kid in window {
            let Some(pose) = self.map.keyframe_pose(*kid) else { continue };
            let obs = self.map.keyframes.get_mut(kid).map(|k| std::mem::take(&mut k.observations)).unwrap_or_default();
            let mut keep = Vec::with_capacity(obs.len());
            for (pid, o) in obs {
                if self.agrees(&pose, pid, &o) {
                    keep.push((pid, o));
                } else {
                    culled += 1;
                    if let Some(p) = self.map.points.get_mut(&pid) {
                        p.observed_by.retain(|k| k != kid);
                        if p.observed_by.is_empty() {
                            self.map.points.remove(&pid);
                        }
                    }
                }
            }
            if let Some(k) = self.map.keyframes.get_mut(kid) {
                k.observations = keep;
            }
        }
        culled
    }

    /// Whether observation `o` (stereo, or left-only with a NaN right x) of point `pid` from a keyframe
    /// at `pose` is within the χ² bound of its kind.
    fn agrees(&self, pose: &Isometry3<f64>, pid: PointId, o: &[f64; 3]) -> bool {
        self.map.point(pid).and_then(|x| self.project(pose, &x)).is_some_and(|p| {
            let left = (p[0] - o[0]).powi(2) + (p[1] - o[1]).powi(2);
            if o[2].is_nan() {
                left <= self.config.cull_chi2_mono
            } else {
                left + (p[2] - o[2]).powi(2) <= self.config.cull_chi2
            }
        })
    }

    /// Keyframe pose of a stored keyframe (convenience for callers holding an id).
    pub fn keyframe_pose(&self, id: KeyframeId) -> Option<Isometry3<f64>> {
        self.map.keyframe_pose(id)
    }
}

/// A local bundle adjustment: its graph, values, and the keys of the keyframes and points in it.
struct BaProblem {
    graph: Graph,
    values: Values,
    pose_keys: BTreeMap<KeyframeId, slam_optim::Key>,
    point_keys: BTreeMap<PointId, slam_optim::Key>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::KeyframePoint;

    /// Noisy keyframes over a static point field: local BA pulls the keyframe poses back towards the
    /// truth and culls a gross outlier.
    #[test]
    fn local_ba_reduces_pose_error_and_culls_outliers() {
        let k = Intrinsics::new(700.0, 700.0, 600.0, 180.0);
        let b = 0.54;
        let mut rng = slam_core::rng::SimRng::new(3);
        let points: Vec<Vector3<f64>> = (0..300)
            .map(|_| Vector3::new(rng.uniform(-15.0, 15.0), rng.uniform(-3.0, 2.0), rng.uniform(8.0, 40.0)))
            .collect();
        let truth: Vec<Isometry3<f64>> =
            (0..6).map(|i| Isometry3::translation(0.1 * i as f64, 0.0, 1.0 * i as f64)).collect();
        let mut mapper = LocalMapper::new(
            k,
            b,
            MappingConfig::default(),
            std::sync::Arc::new(slam_lm::LevenbergMarquardt::default()),
        );
        let mut err_before = 0.0;
        let mut last = None;
        for (i, t) in truth.iter().enumerate() {
            // the tracker's pose: off by a growing error
            let noisy = Isometry3::translation(0.03 * i as f64, -0.02 * i as f64, 0.04 * i as f64) * t;
            err_before += (noisy.translation.vector - t.translation.vector).norm();
            let mut kps = Vec::new();
            for (id, x) in points.iter().enumerate() {
                let c = t.inverse() * Point3::from(*x);
                if c.z < 1.0 {
                    continue;
                }
                let u = k.fx * c.x / c.z + k.cx + 0.3 * rng.normal();
                let v = k.fy * c.y / c.z + k.cy + 0.3 * rng.normal();
                let mut ur = u - k.fx * b / c.z + 0.3 * rng.normal();
                if id == 5 && i == 5 {
                    ur -= 25.0; // a gross stereo mismatch
                }
                let z = k.fx * b / (u - ur);
                let cp = Vector3::new((u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z);
                kps.push(KeyframePoint { id: id as u64, camera_point: cp, observation: [u, v, ur] });
            }
            // the tracker's relative pose to the previous keyframe, from its own (noisy) poses
            let parent = (i > 0).then(|| {
                let prev_noisy =
                    Isometry3::translation(0.03 * (i - 1) as f64, -0.02 * (i - 1) as f64, 0.04 * (i - 1) as f64)
                        * truth[i - 1];
                (i as u64 - 1, prev_noisy.inverse() * noisy)
            });
            let data =
                KeyframeData { id: i as u64, frame: i, world_from_camera: noisy, parent, points: kps, earlier: vec![] };
            last = Some(mapper.insert_keyframe(&data));
        }
        let report = last.expect("report");
        assert!(report.window.0 >= 4, "{:?}", report.window);
        assert!(report.correction.culled.contains(&5), "the mismatch is culled");
        let err_after: f64 = truth
            .iter()
            .enumerate()
            .map(|(i, t)| {
                (mapper.keyframe_pose(i as u64).expect("kf").translation.vector - t.translation.vector).norm()
            })
            .sum();
        assert!(err_after < 0.2 * err_before, "BA error {err_after:.3} vs tracker error {err_before:.3}");
    }

    /// Forty keyframes at one place, all seeing the same points (a car standing still, or a road driven
    /// again): the keyframes held fixed stop at four times the window, the ones sharing the most points
    /// and then the newest, so an adjustment costs the same at the fortieth keyframe as at the
    /// thirtieth.
    #[test]
    fn the_fixed_keyframes_of_an_adjustment_are_bounded() {
        let k = Intrinsics::new(700.0, 700.0, 600.0, 180.0);
        let b = 0.54;
        let mut mapper = LocalMapper::new(
            k,
            b,
            MappingConfig { iterations: 2, ..MappingConfig::default() },
            std::sync::Arc::new(slam_lm::LevenbergMarquardt::default()),
        );
        let points: Vec<KeyframePoint> = (0..60)
            .map(|i| {
                let c = Vector3::new(-6.0 + 0.2 * i as f64, -1.0 + 0.03 * i as f64, 10.0 + 0.4 * i as f64);
                let u = k.fx * c.x / c.z + k.cx;
                KeyframePoint { id: i, camera_point: c, observation: [u, k.fy * c.y / c.z + k.cy, u - k.fx * b / c.z] }
            })
            .collect();
        let mut fixed = Vec::new();
        for i in 0..40u64 {
            let parent = (i > 0).then(|| (i - 1, Isometry3::identity()));
            let data = KeyframeData {
                id: i,
                frame: i as usize,
                world_from_camera: Isometry3::identity(),
                parent,
                points: points.clone(),
                earlier: vec![],
            };
            fixed.push(mapper.insert_keyframe(&data).window.1);
        }
        let cap = FIXED_PER_WINDOW * MappingConfig::default().window;
        assert_eq!(fixed[12], 7, "below the cap every keyframe seeing the points is held: {fixed:?}");
        assert_eq!((fixed[30], fixed[39]), (cap, cap), "{fixed:?}");
        assert!(fixed.iter().all(|&f| f <= cap), "{fixed:?}");
    }

    /// Points triangulated between two keyframes arrive with left-only observations in both (the
    /// earlier one through `KeyframeData::earlier`); they enter the adjustment with the left-only
    /// factor, keep their observations when consistent, and are saved and read back with `null` for the
    /// missing right column.
    #[test]
    fn left_only_observations_of_triangulated_points() {
        let k = Intrinsics::new(700.0, 700.0, 600.0, 180.0);
        let b = 0.54;
        let mut mapper = LocalMapper::new(
            k,
            b,
            MappingConfig::default(),
            std::sync::Arc::new(slam_lm::LevenbergMarquardt::default()),
        );
        let poses = [Isometry3::identity(), Isometry3::translation(0.2, 0.0, 3.0)];
        let stereo: Vec<Vector3<f64>> = (0..40)
            .map(|i| Vector3::new(-6.0 + 0.3 * i as f64, -1.0 + 0.05 * i as f64, 10.0 + 0.5 * i as f64))
            .collect();
        let mono: Vec<Vector3<f64>> = (0..10).map(|i| Vector3::new(-8.0 + 1.5 * i as f64, 0.5, 30.0)).collect();
        let observe = |pose: &Isometry3<f64>, x: &Vector3<f64>, stereo: bool, id: u64| {
            let c = (pose.inverse() * Point3::from(*x)).coords;
            let u = k.fx * c.x / c.z + k.cx;
            let ur = if stereo { u - k.fx * b / c.z } else { f64::NAN };
            KeyframePoint { id, camera_point: c, observation: [u, k.fy * c.y / c.z + k.cy, ur] }
        };
        for (i, pose) in poses.iter().enumerate() {
            let mut points: Vec<KeyframePoint> =
                stereo.iter().enumerate().map(|(j, x)| observe(pose, x, true, j as u64)).collect();
            let mut earlier = Vec::new();
            if i == 1 {
                for (j, x) in mono.iter().enumerate() {
                    points.push(observe(pose, x, false, 100 + j as u64));
                    earlier.push((0, observe(&poses[0], x, false, 100 + j as u64)));
                }
            }
            let parent = (i == 1).then(|| (0, poses[0].inverse() * pose));
            let data = KeyframeData { id: i as u64, frame: i, world_from_camera: *pose, parent, points, earlier };
            let report = mapper.insert_keyframe(&data);
            assert!(report.correction.culled.is_empty(), "{:?}", report.correction.culled);
        }
        let map = mapper.map();
        for j in 0..10u64 {
            let p = map.points.get(&(100 + j)).expect("triangulated point");
            assert_eq!(p.observed_by, vec![1, 0]);
            let x = map.point(100 + j).expect("position");
            assert!((x - mono[j as usize]).norm() < 1e-6, "{x} vs {}", mono[j as usize]);
        }
        let left_only =
            |m: &Map| m.keyframes.values().flat_map(|k| &k.observations).filter(|o| o.1[2].is_nan()).count();
        assert_eq!(left_only(map), 20);
        let path = std::env::temp_dir().join(format!("slam-mono-map-{}.json", std::process::id()));
        map.save(&path).expect("save");
        assert!(std::fs::read_to_string(&path).expect("text").contains("null"));
        let back = Map::load(&path).expect("load");
        assert_eq!(left_only(&back), 20);
        let _ = std::fs::remove_file(&path);
    }
}
