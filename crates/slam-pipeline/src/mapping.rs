//! Local mapping: the work on the map around each new keyframe, done on a snapshot of its window on
//! the local-mapping thread and handed back as edits ([`slam_map::Edit`]) that the tracking thread
//! applies to the live map:
//! 1. young points that fail their probation are culled ([`slam_map::point_culling`]);
//! 2. new points are triangulated between the keyframe and its covisible neighbours
//!    ([`slam_map::triangulation`]);
//! 3. points found twice are fused ([`slam_map::fusion`]);
//! 4. local bundle adjustment: the keyframe and its covisible keyframes free, the other keyframes that
//!    see their points fixed (the optimisation crate's stereo reprojection factor, Huber; a left-only
//!    one for observations without a usable right column), then outlier observations culled;
//! 5. redundant keyframes among the covisible ones are culled ([`slam_map::keyframe_culling`]).

use std::collections::{BTreeMap, BTreeSet};

use nalgebra::{Isometry3, Point3, Vector3};
use slam_core::{KeyframeId, PointId};
use slam_map::{
    fusion::Fusion,
    keyframe_culling::KeyframeCulling,
    local::{Window, WindowConfig},
    point_culling::PointCulling,
    triangulation::Triangulation,
    CreationPolicy, Edit, Map,
};
use slam_optim::{
    factors::{MonoReprojection, StereoReprojection},
    Graph, Huber, NoiseModel, Options, SharedOptimizer, Values, Var,
};

/// Settings of local mapping (the `[mapping]` table of `slam-app run --config`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, documented::DocumentedFieldsOpt)]
#[serde(default, deny_unknown_fields)]
pub struct MappingConfig {
    /// Most keyframes optimised together: the new keyframe and its covisible keyframes (at least 15
    /// shared points), heaviest links first. Default 20 (driving, some 5–15 keyframes share points
    /// with a new one; the bound keeps an adjustment's cost flat where a place was mapped many times).
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
    /// Weight each observation by its keypoint's pyramid level: σ = the level's scale (1.2^level) in
    /// the adjustment and in the cull after it.
    pub level_sigma: bool,
    /// Far stereo keypoints (beyond the near bound) of a new keyframe become points at once too. Their
    /// disparity is never a measurement (tracking and bundle adjustment use their observations left
    /// only), so their depth comes from the keyframes' parallax as they are seen again; what they give
    /// tracking is points whose projection hardly depends on their depth: after a 4.8 m step, 5 % of
    /// depth error moves a point 8 m ahead and 3 m aside by 40 px in the image, one 40 m ahead by 3 px.
    /// Off: ORB-SLAM2's policy, far points only by triangulation between keyframes (on the dev drives it
    /// loses frames at 4.8 m a frame: docs/system.md). Default on.
    pub make_far_points: bool,
    /// With `make_far_points` off: least points a new keyframe makes from its nearest stereo keypoints,
    /// farther than the near bound if need be (`slam_map::CreationPolicy::min_points`). Default 100.
    pub min_new_points: usize,
    /// Triangulate new points between a keyframe and its covisible neighbours. Default on.
    pub triangulate: bool,
    /// Fuse points found twice (project the keyframe's points into its neighbours and back). Default on.
    pub fuse: bool,
    /// Cull young points that tracking does not find again or too few keyframes see. Default on.
    pub cull_points: bool,
    /// Cull keyframes whose near points at least three others see as finely. Default on.
    pub cull_keyframes: bool,
    /// Beyond this many baselines a stereo observation is used as a left-image one only, and a stereo
    /// keypoint does not become a point at once: the tracker's `far_baselines` (set from the `[tracking]`
    /// table, not a key of this one).
    #[serde(skip)]
    pub near_baselines: f64,
}

impl Default for MappingConfig {
    fn default() -> Self {
        Self {
            window: 20,
            huber_px: 7.815f64.sqrt(),
            cull_chi2: 7.815,
            cull_chi2_mono: 5.991,
            iterations: 10,
            bundle_adjustment: true,
            level_sigma: false,
            make_far_points: true,
            min_new_points: 100,
            triangulate: true,
            fuse: true,
            cull_points: true,
            cull_keyframes: true,
            near_baselines: 40.0,
        }
    }
}

impl MappingConfig {
    /// The point-creation policy of new keyframes.
    pub fn creation_policy(&self) -> CreationPolicy {
        let near_baselines = if self.make_far_points { f64::INFINITY } else { self.near_baselines };
        CreationPolicy { near_baselines, min_points: self.min_new_points }
    }

    /// The window around a new keyframe.
    pub fn window_config(&self) -> WindowConfig {
        WindowConfig { max_free: self.window.max(1), ..WindowConfig::default() }
    }
}

/// Most keyframes held fixed in a local adjustment, per keyframe optimised. While a car drives, the
/// keyframes that see the window's points are those the points stayed in view for; standing still or
/// driving over the same road again, every keyframe of the place does, and without a bound the
/// adjustment would grow with the run. Four times the window keeps an adjustment within a constant
/// factor of the window's own size, as the tracker's local map is.
pub const FIXED_PER_WINDOW: usize = 4;

/// Least depth of a point in a keyframe observing it, metres: nearer is no stereo measurement of this
/// rig (its nearest depth is a metre) and, at or behind the camera, no projection at all.
const MIN_DEPTH_M: f64 = 0.1;

/// The work of local mapping around one keyframe: a snapshot of its window (recording its edits).
pub struct MappingJob {
    /// The keyframe.
    pub keyframe: KeyframeId,
    /// Which keyframes of the snapshot play which part.
    pub window: Window,
    /// The snapshot.
    pub snapshot: Map,
}

/// What local mapping did around a keyframe.
#[derive(Debug, Clone, PartialEq)]
pub struct MappingReport {
    /// The keyframe.
    pub keyframe: KeyframeId,
    /// The changes, for the live map.
    pub edits: Vec<Edit>,
    /// Keyframes adjusted (free) and held fixed.
    pub window: (usize, usize),
    /// Observations culled as outliers after the adjustment.
    pub culled_observations: usize,
    /// Young points culled, points triangulated, points merged by fusion.
    pub points: (usize, usize, usize),
    /// Keyframes culled.
    pub culled_keyframes: Vec<KeyframeId>,
    /// Milliseconds in the adjustment.
    pub ba_ms: f64,
    /// Milliseconds culling, triangulating and fusing.
    pub maintenance_ms: f64,
}

/// Local mapping's settings and optimiser.
pub struct LocalMapper {
    config: MappingConfig,
    optimizer: SharedOptimizer,
}

impl LocalMapper {
    /// A mapper with `config`; local BA uses `optimizer`.
    pub fn new(config: MappingConfig, optimizer: SharedOptimizer) -> Self {
        Self { config, optimizer }
    }

    /// The settings.
    pub fn config(&self) -> &MappingConfig {
        &self.config
    }

    /// The job for keyframe `keyframe` just inserted into `map`: the snapshot of its window.
    pub fn job(config: &MappingConfig, map: &Map, keyframe: KeyframeId) -> MappingJob {
        let window =
            map.window_of(keyframe, &WindowConfig { fixed_per_free: FIXED_PER_WINDOW, ..config.window_config() });
        let snapshot = map.window(&window.all());
        MappingJob { keyframe, window, snapshot }
    }

    /// Do the work of a job on its snapshot; the report (its edits for the live map) and the snapshot as
    /// the work left it (refined poses and points, for the object fits).
    pub fn process(&self, job: MappingJob) -> (MappingReport, Map) {
        let MappingJob { keyframe, window, mut snapshot } = job;
        let t = std::time::Instant::now();
        let culled_points =
            if self.config.cull_points { snapshot.cull_young_points(&PointCulling::default()).len() } else { 0 };
        let made = if self.config.triangulate {
            snapshot.triangulate_new_points(keyframe, &window.neighbours, &Triangulation::default()).len()
        } else {
            0
        };
        let merged =
            if self.config.fuse { snapshot.fuse(keyframe, &window.fusion, &Fusion::default()).merged } else { 0 };
        let maintenance_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = std::time::Instant::now();
        let (counts, culled_observations) =
            if self.config.bundle_adjustment { self.adjust(&mut snapshot, &window) } else { ((0, 0), 0) };
        let ba_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = std::time::Instant::now();
        let culled_keyframes = if self.config.cull_keyframes {
            let culling = KeyframeCulling { near_baselines: self.config.near_baselines, ..KeyframeCulling::default() };
            snapshot.cull_redundant_keyframes(&window.free, keyframe, &culling)
        } else {
            Vec::new()
        };
        let maintenance_ms = maintenance_ms + t.elapsed().as_secs_f64() * 1e3;
        tracing::debug!(
            keyframe,
            culled_points,
            made,
            merged,
            ?counts,
            culled_observations,
            ?culled_keyframes,
            "local mapping"
        );
        let report = MappingReport {
            keyframe,
            edits: snapshot.take_edits(),
            window: counts,
            culled_observations,
            points: (culled_points, made, merged),
            culled_keyframes,
            ba_ms,
            maintenance_ms,
        };
        (report, snapshot)
    }

    /// Bundle adjustment of the window's free keyframes with the fixed ones holding the gauge, then the
    /// outlier observations of the free keyframes culled; (free, fixed) counts and the culled
    /// observations.
    fn adjust(&self, map: &mut Map, window: &Window) -> ((usize, usize), usize) {
        let free: Vec<KeyframeId> = window.free.iter().copied().filter(|k| map.keyframe(*k).is_some()).collect();
        let free_set: BTreeSet<KeyframeId> = free.iter().copied().collect();
        // the points the free keyframes see, observed by at least two keyframes present (a point seen
        // once is fixed by its own stereo observation and says nothing about the poses)
        let mut local_points = BTreeSet::new();
        for k in free.iter().filter_map(|k| map.keyframe(*k)) {
            for (_, p) in k.observations() {
                let present = map
                    .point(p)
                    .map_or(0, |x| x.observations.iter().filter(|o| map.keyframe(o.keyframe).is_some()).count());
                if present >= 2 {
                    local_points.insert(p);
                }
            }
        }
        let mut fixed: BTreeSet<KeyframeId> =
            window.fixed.iter().copied().filter(|k| map.keyframe(*k).is_some() && !free_set.contains(k)).collect();
        let mut free_set = free_set;
        if fixed.is_empty() {
            // at a segment's start: the oldest free keyframe holds the gauge
            match free.iter().min().copied() {
                Some(oldest) if free.len() >= 2 => {
                    free_set.remove(&oldest);
                    fixed.insert(oldest);
                }
                _ => return ((0, free.len()), 0),
            }
        }
        if local_points.is_empty() {
            return ((0, fixed.len()), 0);
        }
        let mut p = self.problem(map, &free_set, &fixed, &local_points);
        let options = Options::with_max_iterations(self.config.iterations);
        if let Err(e) = self.optimizer.optimize(&p.graph, &mut p.values, &options, None) {
            tracing::warn!("local bundle adjustment failed: {e}");
            return ((0, fixed.len()), 0);
        }
        for (kid, key) in &p.pose_keys {
            if !fixed.contains(kid) {
                if let Some(pose) = p.values.pose(*key) {
                    map.set_pose(*kid, *pose);
                }
            }
        }
        for (pid, key) in &p.point_keys {
            if let Some(x) = p.values.point(*key) {
                if x.iter().all(|v| v.is_finite()) {
                    map.set_position(*pid, *x);
                }
            }
        }
        let culled = self.cull(map, &free_set) + self.cull_unmeasurable(map, &local_points);
        ((free_set.len(), fixed.len()), culled)
    }

    /// The image noise σ (px) of a keypoint at pyramid `level`.
    fn sigma(&self, map: &Map, level: u8) -> f64 {
        if self.config.level_sigma {
            map.pyramid().scale(level)
        } else {
            1.0
        }
    }

    /// An observation as the adjustment uses it: without its right column when there is none or its
    /// disparity is below the near bound's.
    fn usable(&self, map: &Map, o: [f64; 3]) -> [f64; 3] {
        let min_disparity = map.camera().k.fx / self.config.near_baselines;
        if o[2].is_finite() && o[0] - o[2] >= min_disparity {
            o
        } else {
            [o[0], o[1], f64::NAN]
        }
    }

    /// The adjustment's graph: poses of the free and fixed keyframes, the local points (eliminated),
    /// and a stereo or left-only reprojection factor (Huber) per observation.
    fn problem(
        &self,
        map: &Map,
        free: &BTreeSet<KeyframeId>,
        fixed: &BTreeSet<KeyframeId>,
        local_points: &BTreeSet<PointId>,
    ) -> BaProblem {
        let mut p = BaProblem {
            graph: Graph::new(),
            values: Values::new(),
            pose_keys: BTreeMap::new(),
            point_keys: BTreeMap::new(),
        };
        let cam = *map.camera();
        for id in free.union(fixed) {
            let Some(k) = map.keyframe(*id) else { continue };
            let key = p.values.add(Var::Pose(k.pose));
            if fixed.contains(id) {
                p.graph.fix(key);
            }
            p.pose_keys.insert(*id, key);
        }
        for pid in local_points {
            let Some(x) = map.position(*pid) else { continue };
            let key = p.values.add(Var::Point(x));
            p.graph.eliminate(key);
            p.point_keys.insert(*pid, key);
        }
        for (kid, &pk) in &p.pose_keys {
            let Some(k) = map.keyframe(*kid) else { continue };
            let from_world = k.pose.inverse();
            for (kp, pid) in k.observations() {
                let Some(&xk) = p.point_keys.get(&pid) else { continue };
                // an observation of a point now behind the keyframe is no measurement of it (the cull
                // after the adjustment removes it)
                if map.position(pid).is_none_or(|x| (from_world * Point3::from(x)).z <= MIN_DEPTH_M) {
                    continue;
                }
                let o = self.usable(map, k.features.keypoints[kp].observation());
                let sigma = self.sigma(map, k.features.keypoints[kp].level);
                let (noise, huber) = (NoiseModel::Isotropic(sigma), Huber(self.config.huber_px));
                let added = if o[2].is_nan() {
                    p.graph.add(MonoReprojection::new(pk, xk, cam.k, [o[0], o[1]]), noise, huber)
                } else {
                    p.graph.add(StereoReprojection::new(pk, xk, cam.k, cam.baseline, o), noise, huber)
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

    /// Cull the free keyframes' observations that still disagree with the adjusted map (χ² bounds);
    /// returns the number culled.
    fn cull(&self, map: &mut Map, free: &BTreeSet<KeyframeId>) -> usize {
        let mut doomed = Vec::new();
        for kid in free {
            let Some(k) = map.keyframe(*kid) else { continue };
            for (kp, pid) in k.observations() {
                let o = self.usable(map, k.features.keypoints[kp].observation());
                let sigma = self.sigma(map, k.features.keypoints[kp].level);
                if !self.agrees(map, &k.pose, pid, &o, sigma) {
                    doomed.push((pid, *kid));
                }
            }
        }
        for (p, k) in &doomed {
            map.unobserve(*p, *k);
        }
        doomed.len()
    }

    /// Remove the adjusted points that ended farther from every keyframe observing them than
    /// [`Triangulation::max_depth`] (or behind one): the rig measures no depth there (its stereo depth
    /// and the epipolar search of triangulation both stop at that depth), so such a point is one that
    /// the adjustment pushed along its rays because nothing held its depth (left-only observations of
    /// little parallax). Returns the number of observations removed with them.
    fn cull_unmeasurable(&self, map: &mut Map, points: &BTreeSet<PointId>) -> usize {
        let max_depth = Triangulation::default().max_depth;
        let mut doomed = Vec::new();
        for &p in points {
            let Some(point) = map.point(p) else { continue };
            let depths: Vec<f64> = point
                .observations
                .iter()
                .filter_map(|o| map.keyframe(o.keyframe))
                .map(|k| (k.pose.inverse() * Point3::from(point.position)).z)
                .collect();
            if depths.iter().any(|&z| z <= 0.0) || depths.iter().all(|&z| z > max_depth) {
                doomed.push((p, point.observations.len()));
            }
        }
        let removed = doomed.iter().map(|d| d.1).sum();
        for (p, _) in doomed {
            map.remove_point(p);
        }
        removed
    }

    /// Whether observation `o` (stereo, or left-only with a NaN right x) of point `pid` from a keyframe
    /// at `pose` is within the χ² bound of its kind.
    fn agrees(&self, map: &Map, pose: &Isometry3<f64>, pid: PointId, o: &[f64; 3], sigma: f64) -> bool {
        let Some(x) = map.position(pid) else { return false };
        let c: Vector3<f64> = (pose.inverse() * Point3::from(x)).coords;
        if c.z <= MIN_DEPTH_M {
            return false;
        }
        let p = map.camera().observe(&c);
        let s2 = sigma * sigma;
        let left = ((p[0] - o[0]).powi(2) + (p[1] - o[1]).powi(2)) / s2;
        if o[2].is_nan() {
            left <= self.config.cull_chi2_mono
        } else {
            left + (p[2] - o[2]).powi(2) / s2 <= self.config.cull_chi2
        }
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
    use std::{collections::HashMap, sync::Arc};

    use super::*;
    use slam_core::geometry::Intrinsics;
    use slam_map::{Features, Keypoint, NewKeyframe, ScalePyramid, StereoCamera};

    const K: Intrinsics = Intrinsics { fx: 700.0, fy: 700.0, skew: 0.0, cx: 600.0, cy: 180.0 };
    const B: f64 = 0.54;

    fn camera() -> StereoCamera {
        StereoCamera { k: K, baseline: B }
    }

    fn lm() -> SharedOptimizer {
        Arc::new(slam_lm::LevenbergMarquardt::default())
    }

    /// A keyframe at `pose` (the tracker's belief) seeing `points` from `truth` with stereo noise
    /// `noise.0` px, every keypoint at pyramid level `noise.1` (the keypoint of point `outlier`, if any,
    /// with a 25 px stereo mismatch; points beyond 35 m without a stereo match, as stereo matching loses
    /// most of them), matched to the map points `ids` knows.
    #[allow(clippy::too_many_arguments)]
    fn keyframe(
        map: &Map,
        pose: Isometry3<f64>,
        truth: &Isometry3<f64>,
        points: &[Vector3<f64>],
        ids: &HashMap<usize, PointId>,
        rng: &mut slam_core::rng::SimRng,
        noise: (f64, u8),
        outlier: Option<usize>,
    ) -> (NewKeyframe, Vec<usize>) {
        let (sigma, level) = noise;
        let cam = camera();
        let (mut kps, mut desc, mut seen) = (Vec::new(), Vec::new(), Vec::new());
        for (i, x) in points.iter().enumerate() {
            let c = truth.inverse() * Point3::from(*x);
            if c.z < 1.0 {
                continue;
            }
            let o = cam.observe(&c.coords);
            if !(0.0..1200.0).contains(&o[0]) || !(0.0..370.0).contains(&o[1]) {
                continue;
            }
            let mismatch = if Some(i) == outlier { 25.0 } else { 0.0 };
            let n = |rng: &mut slam_core::rng::SimRng| sigma * rng.normal();
            kps.push(Keypoint {
                u: o[0] + n(rng),
                v: o[1] + n(rng),
                u_right: if c.z < 35.0 { o[2] + n(rng) - mismatch } else { f64::NAN },
                level,
                angle: 0.0,
            });
            desc.push([i as u8; 32]);
            seen.push(i);
        }
        let features = Features::new(kps, desc, (1200.0, 370.0)).expect("lengths");
        let id = map.next_keyframe_id();
        let kf = NewKeyframe {
            id,
            frame: id as usize,
            pose,
            parent: id.checked_sub(1),
            matched: seen.iter().map(|i| ids.get(i).copied()).collect(),
            features: Arc::new(features),
        };
        (kf, seen)
    }

    /// Insert a keyframe into the live map, learn the map points its keypoints became, run local mapping
    /// on its window and apply the edits, as the system does; the report.
    fn map_keyframe(
        map: &mut Map,
        mapper: &LocalMapper,
        kf: NewKeyframe,
        seen: &[usize],
        ids: &mut HashMap<usize, PointId>,
    ) -> MappingReport {
        let id = kf.id;
        map.insert_keyframe(kf, &mapper.config().creation_policy()).expect("insert");
        for (kp, p) in map.keyframe(id).expect("kf").observations() {
            ids.entry(seen[kp]).or_insert(p);
        }
        let (report, _) = mapper.process(LocalMapper::job(mapper.config(), map, id));
        map.apply(&report.edits);
        map.check().expect("the live map stays consistent");
        report
    }

    /// Noisy keyframes over a static point field: local BA pulls the keyframe poses back towards the
    /// truth and culls a gross stereo mismatch.
    #[test]
    fn local_ba_reduces_pose_error_and_culls_outliers() {
        let mut rng = slam_core::rng::SimRng::new(3);
        let points: Vec<Vector3<f64>> = (0..300)
            .map(|_| Vector3::new(rng.uniform(-15.0, 15.0), rng.uniform(-3.0, 2.0), rng.uniform(8.0, 20.0)))
            .collect();
        let truth: Vec<Isometry3<f64>> =
            (0..6).map(|i| Isometry3::translation(0.1 * i as f64, 0.0, 1.0 * i as f64)).collect();
        let config = MappingConfig {
            triangulate: false,
            fuse: false,
            cull_points: false,
            cull_keyframes: false,
            ..MappingConfig::default()
        };
        let mapper = LocalMapper::new(config, lm());
        let mut map = Map::new(camera(), ScalePyramid::default());
        let mut ids = HashMap::new();
        let mut err_before = 0.0;
        let mut culled = 0;
        // a point every keyframe sees: its stereo match in the last keyframe is wrong
        let wrong = points.iter().position(|x| x.z > 14.0 && x.x.abs() < 3.0).expect("a point ahead");
        for (i, t) in truth.iter().enumerate() {
            // the tracker's pose: off by a growing error
            let noisy = Isometry3::translation(0.03 * i as f64, -0.02 * i as f64, 0.04 * i as f64) * t;
            err_before += (noisy.translation.vector - t.translation.vector).norm();
            let outlier = (i == 5).then_some(wrong);
            let (kf, seen) = keyframe(&map, noisy, t, &points, &ids, &mut rng, (0.3, 0), outlier);
            culled += map_keyframe(&mut map, &mapper, kf, &seen, &mut ids).culled_observations;
        }
        assert!(culled >= 1, "the mismatch is culled");
        assert!(
            map.keyframe(5).expect("kf").points.iter().all(|p| *p != ids.get(&wrong).copied()),
            "its observation is gone"
        );
        // the gauge: the first keyframe stays where it was put
        let err_after: f64 = truth
            .iter()
            .enumerate()
            .map(|(i, t)| (map.keyframe_pose(i as u64).expect("kf").translation.vector - t.translation.vector).norm())
            .sum();
        assert!(err_after < 0.2 * err_before, "BA error {err_after:.3} vs tracker error {err_before:.3}");
    }

    /// With `level_sigma` an observation's error is measured in its level's σ: 3 px off in u and in v
    /// is an outlier at level 0 and within the 95 % bound at level 6 (σ = 1.2⁶ ≈ 2.99 px); without it,
    /// an outlier at every level.
    #[test]
    fn level_sigma_measures_the_error_in_the_keypoints_level_sigma() {
        let mut rng = slam_core::rng::SimRng::new(5);
        let points = vec![Vector3::new(1.0, 0.5, 10.0), Vector3::new(-2.0, 0.3, 12.0)];
        let mut map = Map::new(camera(), ScalePyramid::default());
        let at = Isometry3::identity();
        let (kf, _) = keyframe(&map, at, &at, &points, &HashMap::new(), &mut rng, (0.0, 0), None);
        map.insert_keyframe(kf, &MappingConfig::default().creation_policy()).expect("insert");
        let (_, pid) = map.keyframe(0).expect("kf").observations().next().expect("a point");
        let exact = camera().observe(&map.position(pid).expect("point"));
        let off = [exact[0] + 3.0, exact[1] + 3.0, f64::NAN];
        let plain = LocalMapper::new(MappingConfig::default(), lm());
        let levelled = LocalMapper::new(MappingConfig { level_sigma: true, ..MappingConfig::default() }, lm());
        assert!(plain.agrees(&map, &at, pid, &exact, plain.sigma(&map, 0)), "the exact observation agrees");
        assert!(!plain.agrees(&map, &at, pid, &off, plain.sigma(&map, 6)));
        assert!(levelled.agrees(&map, &at, pid, &off, levelled.sigma(&map, 6)));
        assert!(!levelled.agrees(&map, &at, pid, &off, levelled.sigma(&map, 0)));
    }

    /// With `level_sigma` the adjustment weighs each observation by its keypoint's level: on two
    /// keyframes whose keypoints are all at level 6, every factor's whitened residual is the plain one
    /// over 1.2⁶, the same factors in the same order.
    #[test]
    fn level_sigma_weighs_the_adjustments_observations_by_their_level() {
        let mut rng = slam_core::rng::SimRng::new(9);
        let points: Vec<Vector3<f64>> = (0..80)
            .map(|_| Vector3::new(rng.uniform(-8.0, 8.0), rng.uniform(-2.0, 2.0), rng.uniform(6.0, 15.0)))
            .collect();
        let mut map = Map::new(camera(), ScalePyramid::default());
        let mut ids = HashMap::new();
        let policy = MappingConfig::default().creation_policy();
        for i in 0..2 {
            let t = Isometry3::translation(0.0, 0.0, 1.0 * i as f64);
            let (kf, seen) = keyframe(&map, t, &t, &points, &ids, &mut rng, (0.5, 6), None);
            let id = kf.id;
            map.insert_keyframe(kf, &policy).expect("insert");
            for (kp, p) in map.keyframe(id).expect("kf").observations() {
                ids.entry(seen[kp]).or_insert(p);
            }
        }
        let local: BTreeSet<PointId> =
            map.points().filter(|(_, p)| p.observations.len() == 2).map(|(id, _)| id).collect();
        assert!(local.len() > 30, "{} points seen twice", local.len());
        let (free, fixed) = (BTreeSet::from([1]), BTreeSet::from([0]));
        let plain = LocalMapper::new(MappingConfig::default(), lm()).problem(&map, &free, &fixed, &local);
        let levelled = LocalMapper::new(MappingConfig { level_sigma: true, ..MappingConfig::default() }, lm())
            .problem(&map, &free, &fixed, &local);
        assert_eq!(plain.graph.len(), levelled.graph.len());
        assert!(plain.graph.len() >= 2 * local.len());
        let scale = ScalePyramid::default().scale(6);
        let mut nonzero = 0;
        for f in 0..plain.graph.len() {
            let a = plain.graph.whitened_residual(f, &plain.values).expect("factor").expect("residual");
            let b = levelled.graph.whitened_residual(f, &levelled.values).expect("factor").expect("residual");
            nonzero += usize::from(a.norm() > 1e-6);
            assert!((&a / scale - &b).norm() <= 1e-12 * a.norm(), "factor {f}: {a} vs {b}");
        }
        // the second keyframe's noisy observations miss the points the first one made
        assert!(nonzero >= local.len(), "{nonzero} factors with a residual");
    }

    /// Forty keyframes at one place, all seeing the same points (a car standing still, or a road driven
    /// again, with keyframe culling off): the keyframes held fixed stop at four times the keyframes
    /// optimised, so an adjustment costs the same at the fortieth keyframe as at the thirtieth.
    #[test]
    fn the_fixed_keyframes_of_an_adjustment_are_bounded() {
        let mut rng = slam_core::rng::SimRng::new(4);
        let points: Vec<Vector3<f64>> = (0..60)
            .map(|i| Vector3::new(-6.0 + 0.2 * i as f64, -1.0 + 0.03 * i as f64, 10.0 + 0.2 * i as f64))
            .collect();
        let config = MappingConfig { window: 3, cull_keyframes: false, iterations: 2, ..MappingConfig::default() };
        let mapper = LocalMapper::new(config, lm());
        let mut map = Map::new(camera(), ScalePyramid::default());
        let mut ids = HashMap::new();
        let mut fixed = Vec::new();
        for _ in 0..40 {
            let (kf, seen) =
                keyframe(&map, Isometry3::identity(), &Isometry3::identity(), &points, &ids, &mut rng, (0.0, 0), None);
            fixed.push(map_keyframe(&mut map, &mapper, kf, &seen, &mut ids).window.1);
        }
        let cap = FIXED_PER_WINDOW * 3;
        assert_eq!((fixed[30], fixed[39]), (cap, cap), "{fixed:?}");
        assert!(fixed.iter().all(|&f| f <= cap), "{fixed:?}");
        assert_eq!(map.keyframe_count(), 40);
    }

    /// Driving a street of far and near points: local mapping triangulates far points between keyframes
    /// (no keyframe made them at once), fuses and culls, and every point of the live map is in front of
    /// the keyframes that observe it and within the depth the rig measures.
    #[test]
    fn local_mapping_makes_far_points_and_keeps_the_map_sound() {
        let mut rng = slam_core::rng::SimRng::new(5);
        let points: Vec<Vector3<f64>> = (0..800)
            .map(|_| Vector3::new(rng.uniform(-20.0, 20.0), rng.uniform(-3.0, 2.0), rng.uniform(5.0, 70.0)))
            .collect();
        let mapper = LocalMapper::new(MappingConfig::default(), lm());
        let mut map = Map::new(camera(), ScalePyramid::default());
        let mut ids = HashMap::new();
        let mut made = 0;
        for i in 0..8 {
            let t = Isometry3::translation(0.0, 0.0, 2.0 * i as f64);
            let (kf, seen) = keyframe(&map, t, &t, &points, &ids, &mut rng, (0.2, 0), None);
            made += map_keyframe(&mut map, &mapper, kf, &seen, &mut ids).points.1;
        }
        assert!(made > 50, "{made} points triangulated");
        let near = map.camera().baseline * MappingConfig::default().near_baselines;
        let far = map.points().filter(|(_, p)| p.position.z - 14.0 > near).count();
        assert!(far > 20, "{far} far points in the map");
        for (id, p) in map.points() {
            for o in &p.observations {
                let kf = map.keyframe(o.keyframe).expect("observing keyframe");
                let z = (kf.pose.inverse() * Point3::from(p.position)).z;
                assert!(z > 0.0 && z <= Triangulation::default().max_depth + 1e-9, "point {id} at depth {z}");
            }
        }
    }
}
