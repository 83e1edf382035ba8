//! The optimiser benchmark behind `slam-app optim-bench`: the anchor problems of
//! `fixtures/optim/ANCHORS.md` with their reference figures ([`ANCHORS`], [`run_anchor`], the table
//! rows), the generated bundle adjustment that compares the dense and sparse paths of the reduced
//! system ([`generated_solve`], one machine-readable line per solve, [`GeneratedRun`]), and process CPU
//! time and peak memory from Linux's `/proc`. Nothing here is used by the solvers.

use std::{path::Path, time::Duration};

use slam_optim::{
    conformance,
    io::{read_bal, read_g2o, Problem, ProblemError},
    Graph, OptimError, Optimizer, Options, Summary, Values,
};

/// Errors of the benchmark: a problem file that cannot be loaded, a solve that fails, or a result line
/// of a child process that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// An anchor problem's file.
    #[error("loading {file}")]
    Load {
        /// The file name inside the data folder.
        file: String,
        /// Why.
        #[source]
        source: ProblemError,
    },
    /// The optimiser refused the problem.
    #[error("solving {name}")]
    Solve {
        /// The problem's name.
        name: String,
        /// Why.
        #[source]
        source: OptimError,
    },
    /// A [`GeneratedRun`] line without one of its fields.
    #[error("field {field} missing in {line:?}")]
    Field {
        /// The missing field.
        field: &'static str,
        /// The line read.
        line: String,
    },
    /// A problem that cannot be solved here: its file is missing or too large, or a generated one needs
    /// more memory than this process can have.
    #[error("{0}")]
    Refused(String),
    /// A child process of `--generated` could not be run or gave no result line.
    #[error("the {path} run gave no result: {message}")]
    Child {
        /// `dense` or `sparse`.
        path: &'static str,
        /// Why (the process's error output, or the error starting it).
        message: String,
    },
}

/// One anchor problem and the reference figures measured with Ceres 2.1.0 / GTSAM 4.3.0 on this
/// machine (fixtures/optim/ANCHORS.md).
#[derive(Debug, Clone, Copy)]
pub struct Anchor {
    /// Row name.
    pub name: &'static str,
    /// File in the data folder (`.g2o`: a pose graph; else a BAL problem).
    pub file: &'static str,
    /// Huber threshold of the BAL reprojection errors (`None`: squared loss).
    pub huber: Option<f64>,
    /// Lowest cost known for the problem.
    pub best_known: f64,
    /// The reference solver's final cost.
    pub reference_cost: f64,
    /// The reference solver.
    pub reference: &'static str,
    /// The reference solver's single-thread median time, seconds.
    pub reference_seconds: f64,
}

/// The anchor problems, in table order.
pub const ANCHORS: [Anchor; 6] = [
    Anchor {
        name: "problem-49 L2",
        file: "problem-49-7776-pre.txt",
        huber: None,
        best_known: 1.334424e4,
        reference_cost: 1.334432e4,
        reference: "Ceres 1T",
        reference_seconds: 1.95,
    },
    Anchor {
        name: "problem-49 Huber",
        file: "problem-49-7776-pre.txt",
        huber: Some(1.0),
        best_known: 7.647950e3,
        reference_cost: 7.648723e3,
        reference: "Ceres 1T",
        reference_seconds: 2.41,
    },
    Anchor {
        name: "problem-16 L2",
        file: "problem-16-22106-pre.txt",
        huber: None,
        best_known: 1.803390e4,
        reference_cost: 1.803390e4,
        reference: "Ceres 1T",
        reference_seconds: 0.71,
    },
    Anchor {
        name: "problem-16 Huber",
        file: "problem-16-22106-pre.txt",
        huber: Some(1.0),
        best_known: 1.233667e4,
        reference_cost: 1.233701e4,
        reference: "Ceres 1T",
        reference_seconds: 5.66,
    },
    Anchor {
        name: "sphere2500",
        file: "sphere2500.g2o",
        huber: None,
        best_known: 6.757010e2,
        reference_cost: 6.757010e2,
        reference: "GTSAM",
        reference_seconds: 0.30,
    },
    Anchor {
        name: "parking-garage",
        file: "parking-garage.g2o",
        huber: None,
        best_known: 6.341924e-1,
        reference_cost: 6.341924e-1,
        reference: "GTSAM",
        reference_seconds: 0.25,
    },
];

/// The anchors whose name contains `only` (all when `None`).
pub fn anchors_matching(only: Option<&str>) -> Vec<Anchor> {
    ANCHORS.iter().filter(|a| only.is_none_or(|o| a.name.contains(o))).copied().collect()
}

impl Anchor {
    /// The problem and its options: a pose graph with its first vertex fixed and
    /// [`Options::pose_graph`], or a BAL problem with its points eliminated and the default options.
    pub fn load(&self, dir: &Path) -> Result<(Problem, Options), BenchError> {
        let path = dir.join(self.file);
        let err = |source| BenchError::Load { file: self.file.to_string(), source };
        Ok(if self.file.ends_with(".g2o") {
            let mut p = read_g2o(&path).map_err(err)?;
            if let Some(&k) = p.cameras.first() {
                p.graph.fix(k);
            }
            (p, Options::pose_graph())
        } else {
            let mut p = read_bal(&path, self.huber).map_err(err)?;
            for &k in &p.points {
                p.graph.eliminate(k);
            }
            (p, Options::default())
        })
    }

    /// The table row of a run (columns of [`anchor_table_header`]).
    pub fn row(&self, run: &AnchorRun) -> String {
        let s = &run.summary;
        let vs_best = (s.final_cost - self.best_known) / self.best_known;
        let median = run.median_wall.as_secs_f64();
        format!(
            "{:<18} {:>13.6e} {:>13.6e} {:>13.6e} {:>+8.4}% {:>5} {:>9.3} {:>9} {:>4.2}s {:>6.2}x {:>13.6e} {:>7.2}",
            self.name,
            s.initial_cost,
            s.final_cost,
            self.best_known,
            100.0 * vs_best,
            s.iterations,
            median,
            self.reference,
            self.reference_seconds,
            median / self.reference_seconds,
            self.reference_cost,
            run.median_cpu
        )
    }
}

/// The header of the anchor table.
pub fn anchor_table_header() -> String {
    format!(
        "{:<18} {:>13} {:>13} {:>13} {:>9} {:>5} {:>9} {:>14} {:>7} {:>13} {:>7}",
        "problem",
        "initial",
        "final",
        "best known",
        "vs best",
        "iters",
        "time s",
        "reference",
        "ratio",
        "ref. cost",
        "cpu s"
    )
}

/// `reps` solves of one anchor problem (each from a fresh load): the last summary and the median wall
/// and CPU times.
#[derive(Debug, Clone)]
pub struct AnchorRun {
    /// The last solve's summary.
    pub summary: Summary,
    /// Median wall time of the solves.
    pub median_wall: Duration,
    /// Median process CPU time of the solves, seconds.
    pub median_cpu: f64,
}

/// The whole anchor table: every anchor of `anchors` solved `reps` times with `optimizer`, files in
/// `dir`; every printed line goes to `print` (a title, the header, one row per problem, the notes).
pub fn anchor_table(
    optimizer: &dyn Optimizer,
    dir: &Path,
    anchors: &[Anchor],
    reps: usize,
    print: &mut dyn FnMut(String),
) -> Result<(), BenchError> {
    // every problem file is checked before the first solve (a missing last one is found at once)
    for a in anchors {
        slam_core::files::check_readable(&dir.join(a.file), &slam_core::files::PROBLEM)
            .map_err(|e| BenchError::Refused(format!("--data {}: {e}", dir.display())))?;
    }
    print(format!(
        "Optimiser benchmark, backend {:?}, on {} ({reps} timed runs each, median; single thread)",
        optimizer.name(),
        dir.display()
    ));
    print(anchor_table_header());
    for a in anchors {
        print(a.row(&run_anchor(optimizer, dir, a, reps)?));
    }
    print("ratio = our median time / the anchor's single-thread median (ANCHORS.md, another day: for a ratio measured in one sitting use tools/ceres-vs-ours.sh).".into());
    print("cpu s = median process CPU time of the solve (steadier than wall time on a shared machine).".into());
    print("BA: Options::default() (Ceres' defaults), points eliminated by Schur; pose graphs: Options::pose_graph(), vertex 0 fixed.".into());
    Ok(())
}

/// The `--generated n` table: the sparse then the dense path of the reduced system, each solved in a
/// child process of `exe` (so each peak memory is its own) started with `child_args(path)`, whose
/// stdout holds the [`GeneratedRun`] line; `backend` is named in the title.
pub fn generated_table(
    exe: &Path,
    child_args: &dyn Fn(&str) -> Vec<String>,
    (n, iterations, backend): (usize, usize, &str),
    print: &mut dyn FnMut(String),
) -> Result<(), BenchError> {
    print(format!(
        "Generated stereo BA: {n} cameras (2 fixed), {GENERATED_POINTS_PER_CAMERA} points per camera seen by 4 cameras, seed {GENERATED_SEED}, {iterations} iterations, backend {backend:?}"
    ));
    let (sparse_need, dense_need) = generated_memory(n);
    slam_core::memory::check_fits(&format!("the generated BA of {n} cameras on the sparse path"), sparse_need)
        .map_err(|m| BenchError::Refused(format!("--generated {n}: {m}")))?;
    // the dense path's matrix grows with the square of the cameras: past what the machine has it is
    // left out, saying why, and the sparse row still runs
    let dense = slam_core::memory::check_fits(
        &format!("the dense path's {0} × {0} reduced matrix", generated_unknowns(n)),
        dense_need,
    );
    print(generated_table_header());
    let mut finals = Vec::new();
    let paths: &[&'static str] = if dense.is_ok() { &["sparse", "dense"] } else { &["sparse"] };
    for &path in paths {
        let out = std::process::Command::new(exe)
            .args(child_args(path))
            .output()
            .map_err(|e| BenchError::Child { path, message: format!("running {}: {e}", exe.display()) })?;
        let text = String::from_utf8_lossy(&out.stdout);
        let Some(line) = text.lines().find(|l| l.starts_with("GENERATED ")) else {
            let stderr = String::from_utf8_lossy(&out.stderr).trim().to_string();
            return Err(BenchError::Child { path, message: format!("exit {:?}: {stderr}", out.status.code()) });
        };
        let r = GeneratedRun::parse(line)?;
        finals.push(r.final_cost);
        print(r.row(path));
    }
    if let [s, d] = finals[..] {
        print(format!("final costs: sparse vs dense differ by {:.2e} (relative)", (s - d).abs() / d.abs()));
    }
    if let Err(m) = dense {
        print(format!("dense: not run: {m}"));
    }
    print("peak MiB: the process's peak resident memory (VmHWM); solver MiB: its growth during the solve.".into());
    Ok(())
}

/// Solve `anchor` `reps` times (at least once) with `optimizer`.
pub fn run_anchor(
    optimizer: &dyn Optimizer,
    dir: &Path,
    anchor: &Anchor,
    reps: usize,
) -> Result<AnchorRun, BenchError> {
    let (mut wall, mut cpu, mut last) = (Vec::new(), Vec::new(), None);
    for _ in 0..reps.max(1) {
        let (mut p, options) = anchor.load(dir)?;
        let c0 = cpu_seconds();
        let s = optimizer
            .optimize(&p.graph, &mut p.values, &options, None)
            .map_err(|source| BenchError::Solve { name: anchor.name.to_string(), source })?;
        cpu.push(cpu_seconds() - c0);
        wall.push(s.elapsed);
        last = Some(s);
    }
    wall.sort();
    cpu.sort_by(f64::total_cmp);
    let summary = last.expect("at least one solve ran");
    Ok(AnchorRun { summary, median_wall: wall[wall.len() / 2], median_cpu: cpu[cpu.len() / 2] })
}

fn cpu_seconds() -> f64 {
    process_cpu_seconds().unwrap_or(0.0)
}

/// Unknowns of the generated BA's reduced system with `n` cameras (two fixed, six each).
pub fn generated_unknowns(n: usize) -> usize {
    6 * n.saturating_sub(2)
}

/// Memory the generated BA of `n` cameras needs, bytes, on the sparse and on the dense path, from
/// `--generated 2000` measured (docs/optimisation.md): the sparse process peaked at 131 MiB, about
/// 69 kB per camera (the problem, its Jacobians and the sparse factor all grow with the cameras); the
/// dense solve grew by 3 324 MiB for its 11 988² reduced matrix, 3 copies of 8-byte entries (the
/// matrix, its damped copy and the factor).
pub fn generated_memory(n: usize) -> (f64, f64) {
    let per_camera = 131.0 * 1024.0 * 1024.0 / 2000.0;
    let sparse = per_camera * n as f64;
    let u = generated_unknowns(n) as f64;
    (sparse, sparse + 3.0 * 8.0 * u * u)
}

/// Points per camera of the generated bundle adjustment of `optim-bench --generated`.
pub const GENERATED_POINTS_PER_CAMERA: usize = 6;
/// Seed of the generated bundle adjustment of `optim-bench --generated`.
pub const GENERATED_SEED: u64 = 11;

/// One solve of the generated bundle adjustment, as a child process prints it ([`GeneratedRun::line`])
/// and its parent reads it back ([`GeneratedRun::parse`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeneratedRun {
    /// Whether the sparse path solved the reduced system.
    pub sparse: bool,
    /// Unknowns of the reduced system.
    pub reduced: usize,
    /// Iterations run.
    pub iterations: usize,
    /// Cost at the start.
    pub initial: f64,
    /// Cost at the end.
    pub final_cost: f64,
    /// Wall time of the solve, seconds.
    pub seconds: f64,
    /// Process CPU time of the solve, seconds.
    pub cpu: f64,
    /// Resident memory before the solve, KiB.
    pub rss_before_kib: u64,
    /// Peak resident memory of the process, KiB.
    pub peak_kib: u64,
}

/// Build the generated bundle adjustment with `n` cameras and solve it in this process with `iterations`
/// iterations on the dense (`dense`) or the sparse path, whatever its size.
pub fn generated_solve(
    optimizer: &dyn Optimizer,
    n: usize,
    iterations: usize,
    dense: bool,
) -> Result<GeneratedRun, BenchError> {
    let (sparse_need, dense_need) = generated_memory(n);
    let (what, need) = if dense {
        (format!("the dense path's {0} × {0} reduced matrix", generated_unknowns(n)), dense_need)
    } else {
        (format!("the generated BA of {n} cameras on the sparse path"), sparse_need)
    };
    slam_core::memory::check_fits(&what, need).map_err(|m| BenchError::Refused(format!("--generated {n}: {m}")))?;
    let (mut values, graph) = generated_ba(n, GENERATED_POINTS_PER_CAMERA, GENERATED_SEED);
    let mut options = Options::with_max_iterations(iterations);
    options.dense_limit = if dense { usize::MAX } else { 0 };
    let rss_before_kib = status_kib("VmRSS").unwrap_or(0);
    let c0 = cpu_seconds();
    let s = optimizer
        .optimize(&graph, &mut values, &options, None)
        .map_err(|source| BenchError::Solve { name: "the generated BA".to_string(), source })?;
    let cpu = cpu_seconds() - c0;
    Ok(GeneratedRun {
        sparse: s.sparse,
        reduced: s.reduced_dim,
        iterations: s.iterations,
        initial: s.initial_cost,
        final_cost: s.final_cost,
        seconds: s.elapsed.as_secs_f64(),
        cpu,
        rss_before_kib,
        peak_kib: status_kib("VmHWM").unwrap_or(0),
    })
}

impl GeneratedRun {
    /// The machine-readable line, starting `GENERATED `.
    pub fn line(&self) -> String {
        format!(
            "GENERATED sparse={} reduced={} iterations={} initial={:e} final={:e} seconds={:.3} cpu={:.2} rss_before_kib={} peak_kib={}",
            self.sparse,
            self.reduced,
            self.iterations,
            self.initial,
            self.final_cost,
            self.seconds,
            self.cpu,
            self.rss_before_kib,
            self.peak_kib
        )
    }

    /// Read a [`GeneratedRun::line`] back.
    pub fn parse(line: &str) -> Result<Self, BenchError> {
        fn field<T: std::str::FromStr>(line: &str, name: &'static str) -> Result<T, BenchError> {
            line.split_whitespace()
                .find_map(|kv| kv.strip_prefix(name)?.strip_prefix('='))
                .and_then(|v| v.parse().ok())
                .ok_or(BenchError::Field { field: name, line: line.to_string() })
        }
        Ok(Self {
            sparse: field(line, "sparse")?,
            reduced: field(line, "reduced")?,
            iterations: field(line, "iterations")?,
            initial: field(line, "initial")?,
            final_cost: field(line, "final")?,
            seconds: field(line, "seconds")?,
            cpu: field(line, "cpu")?,
            rss_before_kib: field(line, "rss_before_kib")?,
            peak_kib: field(line, "peak_kib")?,
        })
    }

    /// The table row of this solve under `path` (`sparse` or `dense`; columns of
    /// [`generated_table_header`]).
    pub fn row(&self, path: &str) -> String {
        format!(
            "{:<7} {:>8} {:>6} {:>13.6e} {:>13.6e} {:>9.3} {:>8.2} {:>12.1} {:>12.1}",
            path,
            self.reduced,
            self.iterations,
            self.initial,
            self.final_cost,
            self.seconds,
            self.cpu,
            self.peak_kib as f64 / 1024.0,
            (self.peak_kib as f64 - self.rss_before_kib as f64) / 1024.0
        )
    }
}

/// The header of the generated-problem table.
pub fn generated_table_header() -> String {
    format!(
        "{:<7} {:>8} {:>6} {:>13} {:>13} {:>9} {:>8} {:>12} {:>12}",
        "path", "unknowns", "iters", "initial", "final", "time s", "cpu s", "peak MiB", "solver MiB"
    )
}

/// CPU time (user + system) this process has used, in seconds, from `/proc/self/stat` (clock ticks
/// of 10 ms); `None` where `/proc` is not available. Steadier than wall time on a loaded machine.
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // the fields after the command name, which is in parentheses and may hold spaces
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the line, 12 and 13 after the name
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// A `kB` field of `/proc/self/status` (`VmHWM`: peak resident memory; `VmRSS`: current), in KiB.
pub fn status_kib(field: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status.lines().find_map(|l| {
        let rest = l.strip_prefix(field)?.strip_prefix(':')?;
        rest.split_whitespace().next()?.parse().ok()
    })
}

/// A seeded stereo bundle adjustment along a 1 m-per-frame path: `n_poses` SE(3) cameras (the first
/// two fixed, the rest perturbed by ~5 cm / 0.2°), `points_per_pose` points per camera seen by it and
/// the next three (0.5 px noise, Huber), points marked for elimination. The reduced system has
/// `6 (n_poses − 2)` unknowns in a band; above the dense limit (2 000 unknowns, 336 poses) the sparse
/// path is taken. The same generator as [`conformance::check_sparse_matches_dense`].
pub fn generated_ba(n_poses: usize, points_per_pose: usize, seed: u64) -> (Values, Graph) {
    conformance::generated_stereo_ba(n_poses, points_per_pose, seed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_readings_are_plausible() {
        if !std::path::Path::new("/proc/self/status").exists() {
            return; // not Linux
        }
        let cpu = process_cpu_seconds().expect("cpu time");
        assert!((0.0..1e6).contains(&cpu));
        // the current size first: reading the file may grow it, and the peak read after covers that
        let now = status_kib("VmRSS").expect("VmRSS");
        let peak = status_kib("VmHWM").expect("VmHWM");
        assert!(peak >= now && now > 0, "peak {peak} KiB, now {now} KiB");
        assert_eq!(status_kib("NoSuchField"), None);
    }

    #[test]
    fn the_generated_problem_is_sized_before_it_is_built() {
        // --generated 2000 as measured; 100000 asks terabytes of the dense path, which is refused
        let (sparse, dense) = generated_memory(2000);
        assert!((sparse / 1048576.0 - 131.0).abs() < 1.0 && (dense / 1e9 - 3.58).abs() < 0.05, "{sparse} {dense}");
        let (sparse, dense) = generated_memory(100_000);
        assert!(sparse < 1e10 && dense > 8e12, "{sparse} {dense}");
        /// Never reached: the size is refused before the problem is built.
        #[derive(Debug)]
        struct Unused;
        impl Optimizer for Unused {
            fn name(&self) -> &str {
                "unused"
            }
            fn optimize(
                &self,
                _: &slam_optim::Graph,
                _: &mut Values,
                _: &Options,
                _: Option<&mut dyn slam_optim::Observer>,
            ) -> Result<slam_optim::Summary, slam_optim::OptimError> {
                Err(slam_optim::OptimError::NonFiniteCost)
            }
        }
        let e = generated_solve(&Unused, 100_000, 1, true).expect_err("dense refused");
        assert!(
            e.to_string()
                .contains("--generated 100000: the dense path's 599988 × 599988 reduced matrix needs about 8.6 TB"),
            "{e}"
        );
    }

    #[test]
    fn generated_run_lines_read_back_and_name_a_missing_field() {
        let r = GeneratedRun {
            sparse: true,
            reduced: 12,
            iterations: 3,
            initial: 1.5e3,
            final_cost: 2.25,
            seconds: 0.125,
            cpu: 0.5,
            rss_before_kib: 1024,
            peak_kib: 3072,
        };
        let back = GeneratedRun::parse(&r.line()).expect("parses");
        assert_eq!(back, r);
        assert!(r.row("sparse").ends_with("3.0          2.0"), "{}", r.row("sparse"));
        let e = GeneratedRun::parse("GENERATED sparse=true reduced=12").expect_err("fields missing");
        assert!(e.to_string().contains("field iterations missing"), "{e}");
    }

    #[test]
    fn anchors_filter_by_name_and_a_missing_file_names_it() {
        assert_eq!(anchors_matching(None).len(), ANCHORS.len());
        let bal: Vec<_> = anchors_matching(Some("problem-16")).iter().map(|a| a.name).collect();
        assert_eq!(bal, ["problem-16 L2", "problem-16 Huber"]);
        assert!(anchors_matching(Some("no such")).is_empty());
        let Err(e) = ANCHORS[0].load(Path::new("/nonexistent")) else { panic!("loaded a missing file") };
        assert!(e.to_string().contains("problem-49-7776-pre.txt"), "{e}");
    }

    #[test]
    fn generated_ba_is_above_the_dense_limit_and_seeded() {
        let (v, g) = generated_ba(400, 2, 5);
        let (v2, g2) = generated_ba(400, 2, 5);
        assert_eq!(v, v2);
        assert_eq!(g.len(), g2.len());
        let sys =
            slam_optim::linear::LinearSystem::new(&g, &v, slam_optim::Options::default().dense_limit).expect("layout");
        assert_eq!(sys.reduced_dim(), 6 * 398);
        assert!(sys.is_sparse());
    }
}
