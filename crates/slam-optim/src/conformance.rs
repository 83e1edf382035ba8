//! Checks every [`Optimizer`] must pass. A backend crate runs them from its own tests:
//! `slam_optim::conformance::check_all(&MyOptimizer::default(), &fixtures_optim_dir)`.
//!
//! Each check returns `Err(description)` on the first violation. These are test helpers, for a
//! test to assert on and print: the description is for a person (the seam itself returns the typed
//! [`crate::OptimError`]). The references are external: the
//! Ceres / GTSAM minima of the anchor problems (`fixtures/optim/ANCHORS.md`), and for the generated
//! problems the ground truth they were made from.
//!
//! | check | problem | passes when |
//! |---|---|---|
//! | [`check_bal`] | dubrovnik-3-7; BAL problem-16 (16 cameras, 22 106 points, L2, points eliminated) | dubrovnik → cost < 1e-6; problem-16 within 0.1 % of the best-known 1.803390e4 |
//! | [`check_pose_graphs`] | sphere2500, parking-garage, vertex 0 fixed | within 0.1 % of the GTSAM / Ceres minima |
//! | [`check_object_fit`] | a car from 6–8 box factors (Huber), an axis prior and a texture plane | centre and axes within 5 cm of the truth, cost down 1000× |
//! | [`check_local_ba`] | stereo + left-only reprojection, 6 keyframes, 2 fixed, points eliminated, noisy | fixed poses unchanged, cost ≤ the cost at the truth, poses within 5 cm / 0.3° of it |
//! | [`check_sparse_matches_dense`] | a generated BA whose reduced system (2 112 unknowns) is above the default dense limit | the sparse path reaches the dense path's minimum (cost within 1e-9 relative, poses within 1e-6) |
//! | [`check_bad_start`] | a factor undefined at the start | an error, not a panic |

use std::path::Path;

use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3, Vector4};
use slam_quadric::{metrics, project, BoundsModel, Camera, Ellipsoid, ImageSize, Intrinsics};

use crate::{
    factor::{Factor, FactorError},
    factors::{AxisPrior, BoxFactor, MonoReprojection, StereoReprojection, TexturePlane},
    io::{read_bal, read_g2o},
    noise::NoiseModel,
    optimizer::{Optimizer, Options, Summary},
    robust::{Huber, L2},
    values::{Key, Values, Var},
    Graph,
};

/// Run every check; `fixtures` is the folder holding the anchor problems (`fixtures/optim`).
pub fn check_all(opt: &dyn Optimizer, fixtures: &Path) -> Result<(), String> {
    check_bal(opt, fixtures)?;
    check_pose_graphs(opt, fixtures)?;
    check_object_fit(opt)?;
    check_local_ba(opt)?;
    check_sparse_matches_dense(opt)?;
    check_bad_start(opt)?;
    Ok(())
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

fn run(opt: &dyn Optimizer, graph: &Graph, values: &mut Values, options: &Options) -> Result<Summary, String> {
    opt.optimize(graph, values, options, None).map_err(|e| format!("{}: {e}", opt.name()))
}

/// BAL: dubrovnik-3-7 to zero (under-determined), problem-16 (L2) to its best-known minimum. Returns
/// problem-16's summary (a backend's own tests may check iteration counts).
pub fn check_bal(opt: &dyn Optimizer, fixtures: &Path) -> Result<Summary, String> {
    let mut p = read_bal(fixtures.join("dubrovnik-3-7-pre.txt"), None).map_err(|e| e.to_string())?;
    for &k in &p.points {
        p.graph.eliminate(k);
    }
    let tight = Options { function_tolerance: 1e-14, parameter_tolerance: 1e-14, ..Options::default() };
    let s = run(opt, &p.graph, &mut p.values, &tight)?;
    if s.final_cost >= 1e-6 {
        return Err(format!("{}: dubrovnik-3-7 should reach ~0: {s:?}", opt.name()));
    }
    let mut p = read_bal(fixtures.join("problem-16-22106-pre.txt"), None).map_err(|e| e.to_string())?;
    for &k in &p.points {
        p.graph.eliminate(k);
    }
    let s = run(opt, &p.graph, &mut p.values, &Options::default())?;
    if rel(s.final_cost, 1.803390e4) >= 1e-3 {
        return Err(format!("{}: problem-16 L2 should reach 1.803390e4 (Ceres): {s:?}", opt.name()));
    }
    Ok(s)
}

/// The two g2o pose graphs to the anchors' minima, vertex 0 fixed, with [`Options::pose_graph`].
pub fn check_pose_graphs(opt: &dyn Optimizer, fixtures: &Path) -> Result<(), String> {
    for (file, minimum) in [("sphere2500.g2o", 6.757010e+02), ("parking-garage.g2o", 6.341924e-01)] {
        let mut p = read_g2o(fixtures.join(file)).map_err(|e| e.to_string())?;
        let first = *p.cameras.first().ok_or("no pose")?;
        let before = p.values.pose(first).copied();
        p.graph.fix(first);
        let s = run(opt, &p.graph, &mut p.values, &Options::pose_graph())?;
        if rel(s.final_cost, minimum) >= 1e-3 {
            return Err(format!("{}: {file} should reach {minimum}: {s:?}", opt.name()));
        }
        if p.values.pose(first).copied() != before {
            return Err(format!("{}: {file}: the fixed vertex moved", opt.name()));
        }
    }
    Ok(())
}

const K: Intrinsics = Intrinsics { fx: 721.5377, fy: 721.5377, skew: 0.0, cx: 609.5593, cy: 172.854 };

/// Object fit: box factors (Huber) from fixed keyframes, an axis prior and a texture plane recover a
/// car from a poor start.
pub fn check_object_fit(opt: &dyn Optimizer) -> Result<(), String> {
    let image = ImageSize::new(1242.0, 375.0);
    let truth = Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(4.0, 0.9, 18.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.08),
        ),
        Vector3::new(2.1, 0.8, 0.85),
    );
    let mut values = Values::new();
    let mut graph = Graph::new();
    let mut poses = Vec::new();
    let mut boxes = Vec::new();
    for i in 0..8 {
        // driving forward 1 m per keyframe, drifting left
        let pose = Isometry3::translation(-0.3 * i as f64, 0.0, 1.0 * i as f64);
        let b = project(&truth, &Camera::new(K, pose))
            .and_then(|c| c.clipped_bounds(&image))
            .map_err(|e| format!("not visible: {e:?}"))?;
        if BoxFactor::usable(&b, &image, 2.0) {
            let kp = values.add(Var::Pose(pose));
            graph.fix(kp);
            poses.push(kp);
            boxes.push(b);
        }
    }
    if poses.len() < 6 {
        return Err("object fit: too few usable boxes".into());
    }
    let start = Ellipsoid::new(
        Isometry3::from_parts(Translation3::new(4.6, 0.6, 19.5), UnitQuaternion::identity()),
        Vector3::new(1.8, 0.9, 1.1),
    );
    let ko = values.add(Var::Ellipsoid(start));
    let err = |e: crate::OptimError| e.to_string();
    for (&kp, b) in poses.iter().zip(&boxes) {
        graph
            .add(BoxFactor::new(kp, ko, K, *b, BoundsModel::Clipped(image)), NoiseModel::Isotropic(2.0), Huber(1.0))
            .map_err(err)?;
    }
    graph.add(AxisPrior::new(ko, Vector3::new(2.1, 0.8, 0.85)), NoiseModel::Isotropic(0.5), L2).map_err(err)?;
    // the car's side facing the cameras as a texture plane nᵀx + d = 0, tangent to the true ellipsoid
    let n = truth.rotation() * Vector3::new(0.0, 0.0, -1.0);
    let d = -(n.dot(&truth.centre()) + truth.half_extent(&n));
    let plane = TexturePlane::new(ko, Vector4::new(n.x, n.y, n.z, d)).ok_or("plane")?;
    graph.add(plane, NoiseModel::Isotropic(0.2), Huber(1.0)).map_err(err)?;
    let s = run(opt, &graph, &mut values, &Options { function_tolerance: 1e-10, ..Options::default() })?;
    let est = values.ellipsoid(ko).ok_or("ellipsoid")?;
    let (et, ea) = (metrics::e_trans(est, &truth), metrics::e_axe_ordered(est, &truth));
    if et >= 0.05 || ea >= 0.05 || s.final_cost >= 1e-3 * s.initial_cost {
        return Err(format!("{}: object fit e_trans {et:.4} m, e_axe {ea:.4} m: {s:?}", opt.name()));
    }
    Ok(())
}

/// The seeded generator of the generated problems: ChaCha8 (its stream is fixed by the ChaCha
/// specification, so the problems are the same on every platform and version) keyed by the seed
/// through `SeedableRng::seed_from_u64`, with `rand_distr`'s normal distribution.
struct Rng(rand::rngs::ChaCha8Rng);

impl Rng {
    fn new(seed: u64) -> Self {
        Self(rand::SeedableRng::seed_from_u64(seed))
    }
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * rand::RngExt::random::<f64>(&mut self.0)
    }
    /// Normal with standard deviation `sigma`.
    fn normal(&mut self, sigma: f64) -> f64 {
        sigma * rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, &mut self.0)
    }
}

/// A forward-driving stereo rig (`T_wc`, camera z forward) observing points along a corridor, 0.5 px
/// noise. Returns (values, graph, pose keys, true poses). Poses `0..fixed` are fixed; points are
/// eliminated. The free poses start perturbed (5 cm, 0.2°) unless `at_truth`; the random draws are the
/// same either way, so both variants hold the same measurements.
type Generated = (Values, Graph, Vec<Key>, Vec<Isometry3<f64>>);

/// The generated stereo BA of [`check_sparse_matches_dense`] at any size (two poses fixed, the rest
/// perturbed), for benchmarks: `(values, graph)`.
pub fn generated_stereo_ba(n_poses: usize, points_per_pose: usize, seed: u64) -> (Values, Graph) {
    let (values, graph, _, _) = stereo_ba(n_poses, points_per_pose, 2, false, seed);
    (values, graph)
}

fn stereo_ba(n_poses: usize, points_per_pose: usize, fixed: usize, at_truth: bool, seed: u64) -> Generated {
    let mut rng = Rng::new(seed);
    let baseline = 0.54;
    let truth: Vec<Isometry3<f64>> = (0..n_poses)
        .map(|i| {
            let yaw = 0.02 * (i as f64 * 0.3).sin();
            Isometry3::from_parts(
                Translation3::new(0.2 * (i as f64 * 0.2).sin(), 0.0, 1.0 * i as f64),
                UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw),
            )
        })
        .collect();
    let mut values = Values::new();
    let mut graph = Graph::new();
    let keys: Vec<Key> = truth
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let dt = Vector3::new(rng.normal(0.05), rng.normal(0.05), rng.normal(0.05));
            let dr = Vector3::new(rng.normal(0.003), rng.normal(0.003), rng.normal(0.003));
            let start = if i < fixed || at_truth {
                *t
            } else {
                Isometry3::from_parts(
                    Translation3::from(t.translation.vector + dt),
                    t.rotation * UnitQuaternion::from_scaled_axis(dr),
                )
            };
            values.add(Var::Pose(start))
        })
        .collect();
    for &k in keys.iter().take(fixed) {
        graph.fix(k);
    }
    for (i, t) in truth.iter().enumerate() {
        for _ in 0..points_per_pose {
            // a point 6–30 m ahead of camera i, seen by it and the next three cameras when in front
            let local = Vector3::new(rng.uniform(-8.0, 8.0), rng.uniform(-2.0, 1.5), rng.uniform(6.0, 30.0));
            let x = t * Point3::from(local);
            let mut obs = Vec::new();
            for (j, tj) in truth.iter().enumerate().skip(i).take(4) {
                let c = tj.inverse() * x;
                let (nu, nv, nr) = (rng.normal(0.5), rng.normal(0.5), rng.normal(0.5));
                if c.z < 1.0 {
                    continue;
                }
                let u = K.fx * c.x / c.z + K.cx + nu;
                let v = K.fy * c.y / c.z + K.cy + nv;
                let ur = K.fx * (c.x - baseline) / c.z + K.cx + nr;
                obs.push((j, [u, v, ur]));
            }
            let start = x.coords + Vector3::new(rng.normal(0.1), rng.normal(0.1), rng.normal(0.3));
            if obs.len() < 2 {
                continue;
            }
            let kx = values.add(Var::Point(start));
            graph.eliminate(kx);
            for (n, (j, o)) in obs.into_iter().enumerate() {
                let (noise, huber) = (NoiseModel::Isotropic(1.0), Huber(2.8));
                // every third point's second observation is left-only (a point without a right match)
                let added = if n == 1 && kx.0 % 3 == 0 {
                    graph.add(MonoReprojection::new(keys[j], kx, K, [o[0], o[1]]), noise, huber)
                } else {
                    graph.add(StereoReprojection::new(keys[j], kx, K, baseline, o), noise, huber)
                };
                debug_assert!(added.is_ok());
            }
        }
    }
    (values, graph, keys, truth)
}

/// Local BA as the mapper builds it: stereo and left-only reprojection (Huber), the two oldest of six
/// keyframes fixed, points eliminated, 0.5 px noise.
pub fn check_local_ba(opt: &dyn Optimizer) -> Result<(), String> {
    let (mut values, graph, keys, truth) = stereo_ba(6, 60, 2, false, 7);
    let before: Vec<_> = keys.iter().map(|k| values.pose(*k).copied()).collect();
    let s = run(opt, &graph, &mut values, &Options::with_max_iterations(50))?;
    for (i, k) in keys.iter().enumerate().take(2) {
        if values.pose(*k).copied() != before[i] {
            return Err(format!("{}: local BA moved fixed keyframe {i}", opt.name()));
        }
    }
    for (k, t) in keys.iter().zip(&truth) {
        let p = values.pose(*k).ok_or("pose")?;
        let d = p.inverse() * t;
        let (dt, dr) = (d.translation.vector.norm(), d.rotation.angle().to_degrees());
        if dt > 0.05 || dr > 0.3 {
            return Err(format!("{}: local BA pose off by {dt:.3} m / {dr:.3}°: {s:?}", opt.name()));
        }
    }
    // the joint minimum is at most the cost with every pose held at the truth and only points free
    let (mut v_truth, g_truth, _, _) = stereo_ba(6, 60, 6, true, 7);
    let s_truth = run(opt, &g_truth, &mut v_truth, &Options::with_max_iterations(50))?;
    if s.final_cost > s_truth.final_cost * (1.0 + 1e-9) {
        return Err(format!(
            "{}: local BA cost {} above the cost at the true poses {}",
            opt.name(),
            s.final_cost,
            s_truth.final_cost
        ));
    }
    Ok(())
}

/// The sparse Schur path against the dense one on a BA whose reduced system is above the default
/// dense limit (352 free poses × 6 = 2 112 unknowns > 2 000): the same minimum.
pub fn check_sparse_matches_dense(opt: &dyn Optimizer) -> Result<(), String> {
    let (v0, graph, keys, _) = stereo_ba(354, 6, 2, false, 11);
    let options = Options::with_max_iterations(30);
    let mut sparse = v0.clone();
    let s = run(opt, &graph, &mut sparse, &options)?;
    if !s.sparse || s.reduced_dim <= options.dense_limit {
        return Err(format!("{}: expected the sparse path above the dense limit: {s:?}", opt.name()));
    }
    let mut dense = v0;
    let d = run(opt, &graph, &mut dense, &Options { dense_limit: usize::MAX, ..options })?;
    if d.sparse {
        return Err(format!("{}: expected the dense path: {d:?}", opt.name()));
    }
    if rel(s.final_cost, d.final_cost) > 1e-9 || s.final_cost >= 0.5 * s.initial_cost {
        return Err(format!("{}: sparse {s:?} vs dense {d:?}", opt.name()));
    }
    for k in &keys {
        let (a, b) = (sparse.pose(*k).ok_or("pose")?, dense.pose(*k).ok_or("pose")?);
        let diff = (a.inverse() * b).translation.vector.norm();
        if diff > 1e-6 {
            return Err(format!("{}: sparse and dense poses differ by {diff:e} m at {k:?}", opt.name()));
        }
    }
    Ok(())
}

/// A factor that cannot be evaluated at the start (and one joining two eliminated variables) gives an
/// error, not a panic or a silent result.
pub fn check_bad_start(opt: &dyn Optimizer) -> Result<(), String> {
    struct Undefined([Key; 1]);
    impl Factor for Undefined {
        fn keys(&self) -> &[Key] {
            &self.0
        }
        fn dim(&self) -> usize {
            1
        }
        fn evaluate(&self, _: &Values, _: Option<&mut Vec<DMatrix<f64>>>) -> Result<DVector<f64>, FactorError> {
            Err(FactorError::Undefined("always".into()))
        }
    }
    let mut values = Values::new();
    let k = values.add(Var::Point(Vector3::zeros()));
    let mut graph = Graph::new();
    graph.add_l2(Undefined([k]));
    if opt.optimize(&graph, &mut values, &Options::default(), None).is_ok() {
        return Err(format!("{}: an undefined factor at the start must be an error", opt.name()));
    }
    let (mut values, mut graph) = (Values::new(), Graph::new());
    let a = values.add(Var::Pose(Isometry3::identity()));
    let b = values.add(Var::Pose(Isometry3::translation(1.0, 0.0, 0.0)));
    graph.add_l2(crate::factors::Between::new(a, b, Isometry3::translation(1.0, 0.0, 0.0)));
    graph.eliminate(a).eliminate(b);
    if opt.optimize(&graph, &mut values, &Options::default(), None).is_ok() {
        return Err(format!("{}: a factor joining two eliminated variables must be an error", opt.name()));
    }
    Ok(())
}
