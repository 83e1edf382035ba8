//! Trials, cells and the sweep.

use slam_quadric::{metrics, Ellipsoid};

use crate::{
    methods::{Method, ObjectPrior},
    scene::{perturb, Geometry, NoiseKind, Scene, IMAGE},
};

/// Outcome of one trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrialResult {
    /// A real ellipsoid in front of every true camera.
    pub success: bool,
    /// Centre error, metres (NaN on failure).
    pub e_trans: f64,
    /// Semi-axis error in the best axis order, metres (NaN on failure).
    pub e_axe: f64,
    /// Mean over views of the IoU of the estimate's projected (clipped) box with the true box, using the
    /// true cameras (NaN on failure).
    pub iou: f64,
}

/// Run one trial.
pub fn run_trial(
    scene: &Scene,
    method: Method,
    kind: NoiseKind,
    level: f64,
    master_seed: u64,
    object: u64,
    seed: u64,
) -> TrialResult {
    let views = perturb(scene, kind, level, master_seed, object, seed);
    let failed = TrialResult { success: false, e_trans: f64::NAN, e_axe: f64::NAN, iou: f64::NAN };
    let Ok(e) = method.run(&views, &IMAGE, &ObjectPrior::car()) else { return failed };
    evaluate(scene, &e).unwrap_or(failed)
}

fn evaluate(scene: &Scene, e: &Ellipsoid) -> Option<TrialResult> {
    let centre = nalgebra::Point3::from(e.centre());
    let in_front = scene.cameras.iter().all(|c| (c.camera_from_world() * centre).z > 0.0);
    if !in_front || !e.is_valid() {
        return None;
    }
    let iou = scene.cameras.iter().zip(&scene.boxes).map(|(c, b)| metrics::projected_iou(e, c, &IMAGE, b)).sum::<f64>()
        / scene.cameras.len() as f64;
    Some(TrialResult {
        success: true,
        e_trans: metrics::e_trans(e, &scene.truth),
        e_axe: metrics::e_axe(e, &scene.truth),
        iou,
    })
}

/// Statistics of one cell (geometry, noise kind, level, method).
#[derive(Debug, Clone, PartialEq)]
pub struct CellStats {
    /// Geometry.
    pub geometry: Geometry,
    /// Noise kind.
    pub noise: NoiseKind,
    /// Level, per cent.
    pub level: f64,
    /// Method.
    pub method: Method,
    /// Trials run.
    pub trials: usize,
    /// Share of successful trials.
    pub success: f64,
    /// Mean / median centre error over successes (NaN when none).
    pub e_trans_mean: f64,
    /// Median centre error.
    pub e_trans_median: f64,
    /// Mean semi-axis error.
    pub e_axe_mean: f64,
    /// Median semi-axis error.
    pub e_axe_median: f64,
    /// Mean IoU2D.
    pub iou_mean: f64,
    /// Median IoU2D.
    pub iou_median: f64,
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

impl CellStats {
    fn from_trials(geometry: Geometry, noise: NoiseKind, level: f64, method: Method, trials: &[TrialResult]) -> Self {
        let ok: Vec<&TrialResult> = trials.iter().filter(|t| t.success).collect();
        let col = |f: fn(&TrialResult) -> f64| ok.iter().map(|t| f(t)).collect::<Vec<f64>>();
        let (et, ea, iou) = (col(|t| t.e_trans), col(|t| t.e_axe), col(|t| t.iou));
        Self {
            geometry,
            noise,
            level,
            method,
            trials: trials.len(),
            success: ok.len() as f64 / trials.len().max(1) as f64,
            e_trans_mean: mean(&et),
            e_trans_median: median(&et),
            e_axe_mean: mean(&ea),
            e_axe_median: median(&ea),
            iou_mean: mean(&iou),
            iou_median: median(&iou),
        }
    }
}

/// Settings of [`sweep`].
#[derive(Debug, Clone, PartialEq)]
pub struct SweepConfig {
    /// Master seed.
    pub seed: u64,
    /// Objects per cell.
    pub objects: u64,
    /// Noise seeds per object.
    pub noise_seeds: u64,
    /// Geometries to run.
    pub geometries: Vec<Geometry>,
    /// Noise kinds to run.
    pub noise: Vec<NoiseKind>,
    /// Methods to run.
    pub methods: Vec<Method>,
}

impl Default for SweepConfig {
    fn default() -> Self {
        Self {
            seed: 20220601,
            objects: 10,
            noise_seeds: 10,
            geometries: vec![Geometry::Arc, Geometry::DriveBy],
            noise: vec![NoiseKind::Translation, NoiseKind::Rotation, NoiseKind::Box],
            methods: Method::ALL.to_vec(),
        }
    }
}

/// Run the sweep on all cores; `progress(done, total)` is called as cells finish (from the calling
/// thread). Results are in the order geometry, noise kind, level, method, and do not depend on the
/// number of threads.
pub fn sweep(config: &SweepConfig, mut progress: impl FnMut(usize, usize)) -> Vec<CellStats> {
    use std::sync::{
        atomic::{AtomicUsize, Ordering},
        mpsc,
    };
    let scenes: Vec<(Geometry, Vec<Scene>)> = config
        .geometries
        .iter()
        .map(|&g| (g, (0..config.objects).map(|o| Scene::new(g, config.seed, o)).collect()))
        .collect();
    let mut jobs = Vec::new();
    for (gi, &(g, _)) in scenes.iter().enumerate() {
        for &kind in &config.noise {
            for &level in kind.levels() {
                for &m in &config.methods {
                    jobs.push((gi, g, kind, level, m));
                }
            }
        }
    }
    let total = jobs.len();
    let next = AtomicUsize::new(0);
    let threads = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1).max(1);
    let (tx, rx) = mpsc::channel();
    let mut results: Vec<Option<CellStats>> = vec![None; total];
    std::thread::scope(|s| {
        for _ in 0..threads {
            let tx = tx.clone();
            let (jobs, scenes, next) = (&jobs, &scenes, &next);
            s.spawn(move || loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(&(gi, g, kind, level, m)) = jobs.get(i) else { break };
                let mut trials = Vec::with_capacity((config.objects * config.noise_seeds) as usize);
                for (o, scene) in scenes[gi].1.iter().enumerate() {
                    for seed in 0..config.noise_seeds {
                        trials.push(run_trial(scene, m, kind, level, config.seed, o as u64, seed));
                    }
                }
                if tx.send((i, CellStats::from_trials(g, kind, level, m, &trials))).is_err() {
                    break;
                }
            });
        }
        drop(tx);
        let mut done = 0;
        for (i, cell) in rx {
            results[i] = Some(cell);
            done += 1;
            progress(done, total);
        }
    });
    results.into_iter().flatten().collect()
}

/// The smallest level at which a method's success rate falls below 50 % (`None` if it never does).
pub fn breakdown_level(cells: &[CellStats], geometry: Geometry, noise: NoiseKind, method: Method) -> Option<f64> {
    cells
        .iter()
        .filter(|c| c.geometry == geometry && c.noise == noise && c.method == method && c.success < 0.5)
        .map(|c| c.level)
        .min_by(|a, b| a.total_cmp(b))
}
