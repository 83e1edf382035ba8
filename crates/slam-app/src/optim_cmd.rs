//! `slam-app optim-bench`: the optimiser on the anchor problems of `fixtures/optim/ANCHORS.md`.

use std::{path::PathBuf, time::Duration};

use anyhow::Context;
use clap::Args;
use slam_optim::{
    io::{read_bal, read_g2o, Problem},
    Options, Summary,
};

use crate::optimizer_choice::OptimizerKind;

#[derive(Args, Debug)]
pub struct OptimBenchArgs {
    /// Folder with the problem files (default: the shipped fixtures/optim).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Timed repetitions per problem (the median is reported).
    #[arg(long, default_value_t = 3)]
    reps: usize,
    /// Only run problems whose name contains this text.
    #[arg(long)]
    only: Option<String>,
    /// Optimiser backend.
    #[arg(long, value_enum, default_value_t = OptimizerKind::Lm)]
    optimizer: OptimizerKind,
    /// Instead of the anchor problems: a generated stereo BA with this many cameras (seeded), solved
    /// with the dense and with the sparse reduced system, each in its own process (time, peak memory).
    #[arg(long)]
    generated: Option<usize>,
    /// Iterations of each solve of `--generated` (the dense path factorises a 6N × 6N matrix each time).
    #[arg(long, default_value_t = 3)]
    iterations: usize,
    /// Internal: run one path of `--generated` in this process and print one machine-readable line.
    #[arg(long, hide = true, value_parser = ["dense", "sparse"])]
    generated_path: Option<String>,
}

/// One anchor row: our problem and the reference numbers measured with Ceres 2.1.0 / GTSAM 4.3.0 on
/// this machine (fixtures/optim/ANCHORS.md).
struct Anchor {
    name: &'static str,
    file: &'static str,
    huber: Option<f64>,
    best_known: f64,
    reference_cost: f64,
    reference: &'static str,
    reference_seconds: f64,
}

const ANCHORS: [Anchor; 6] = [
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

fn load(dir: &std::path::Path, a: &Anchor) -> anyhow::Result<(Problem, Options)> {
    let path = dir.join(a.file);
    Ok(if a.file.ends_with(".g2o") {
        let mut p = read_g2o(&path)?;
        if let Some(&k) = p.cameras.first() {
            p.graph.fix(k);
        }
        (p, Options::pose_graph())
    } else {
        let mut p = read_bal(&path, a.huber)?;
        for &k in &p.points {
            p.graph.eliminate(k);
        }
        (p, Options::default())
    })
}

pub fn run(args: &OptimBenchArgs) -> anyhow::Result<()> {
    crate::validate::count("--reps", args.reps, 1, 1000)?;
    if let Some(n) = args.generated {
        crate::validate::count("--generated", n, 3, 100_000)?;
        crate::validate::count("--iterations", args.iterations, 1, 1000)?;
        return match &args.generated_path {
            Some(path) => generated_child(args, n, path == "dense"),
            None => generated_table(args, n),
        };
    }
    if let Some(o) = &args.only {
        if !ANCHORS.iter().any(|a| a.name.contains(o.as_str())) {
            let names: Vec<&str> = ANCHORS.iter().map(|a| a.name).collect();
            anyhow::bail!("--only {o:?} matches no problem (problems: {})", names.join(", "));
        }
    }
    let dir = args.data.clone().unwrap_or_else(|| crate::fixture("optim"));
    let optimizer = args.optimizer.build();
    println!(
        "Optimiser benchmark, backend {:?}, on {} ({} timed runs each, median; single thread)",
        optimizer.name(),
        dir.display(),
        args.reps
    );
    println!(
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
    );
    for a in ANCHORS.iter().filter(|a| args.only.as_deref().is_none_or(|o| a.name.contains(o))) {
        let mut times = Vec::new();
        let mut cpu = Vec::new();
        let mut last: Option<Summary> = None;
        for _ in 0..args.reps.max(1) {
            let (mut p, options) = load(&dir, a).with_context(|| format!("loading {}", a.file))?;
            let c0 = cpu_seconds();
            let s = optimizer
                .optimize(&p.graph, &mut p.values, &options, None)
                .with_context(|| format!("solving {}", a.name))?;
            cpu.push(cpu_seconds() - c0);
            times.push(s.elapsed);
            last = Some(s);
        }
        times.sort();
        cpu.sort_by(f64::total_cmp);
        let median: Duration = times[times.len() / 2];
        let median_cpu = cpu[cpu.len() / 2];
        let Some(s) = last else { continue };
        let vs_best = (s.final_cost - a.best_known) / a.best_known;
        println!(
            "{:<18} {:>13.6e} {:>13.6e} {:>13.6e} {:>+8.4}% {:>5} {:>9.3} {:>9} {:>4.2}s {:>6.2}x {:>13.6e} {:>7.2}",
            a.name,
            s.initial_cost,
            s.final_cost,
            a.best_known,
            100.0 * vs_best,
            s.iterations,
            median.as_secs_f64(),
            a.reference,
            a.reference_seconds,
            median.as_secs_f64() / a.reference_seconds,
            a.reference_cost,
            median_cpu
        );
    }
    println!("ratio = our median time / the anchor's single-thread median (ANCHORS.md, another day: for a ratio measured in one sitting use tools/ceres-vs-ours.sh).");
    println!("cpu s = median process CPU time of the solve (steadier than wall time on a shared machine).");
    println!("BA: Options::default() (Ceres' defaults), points eliminated by Schur; pose graphs: Options::pose_graph(), vertex 0 fixed.");
    Ok(())
}

fn cpu_seconds() -> f64 {
    slam_optim::bench::process_cpu_seconds().unwrap_or(0.0)
}

/// `--generated N --generated-path dense|sparse`: one solve in this process; one `GENERATED` line.
fn generated_child(args: &OptimBenchArgs, n: usize, dense: bool) -> anyhow::Result<()> {
    let (mut values, graph) = slam_optim::bench::generated_ba(n, GENERATED_POINTS_PER_CAMERA, GENERATED_SEED);
    let mut options = Options::with_max_iterations(args.iterations);
    // force the path asked for, whatever the size
    options.dense_limit = if dense { usize::MAX } else { 0 };
    let rss_before = slam_optim::bench::status_kib("VmRSS").unwrap_or(0);
    let c0 = cpu_seconds();
    let s = args.optimizer.build().optimize(&graph, &mut values, &options, None).context("solving the generated BA")?;
    let cpu = cpu_seconds() - c0;
    let peak = slam_optim::bench::status_kib("VmHWM").unwrap_or(0);
    println!(
        "GENERATED sparse={} reduced={} iterations={} initial={:e} final={:e} seconds={:.3} cpu={:.2} rss_before_kib={} peak_kib={}",
        s.sparse,
        s.reduced_dim,
        s.iterations,
        s.initial_cost,
        s.final_cost,
        s.elapsed.as_secs_f64(),
        cpu,
        rss_before,
        peak
    );
    Ok(())
}

const GENERATED_POINTS_PER_CAMERA: usize = 6;
const GENERATED_SEED: u64 = 11;

/// `--generated N`: the sparse then the dense path, each in a child process (so each peak memory is
/// its own), and a table.
fn generated_table(args: &OptimBenchArgs, n: usize) -> anyhow::Result<()> {
    let exe = std::env::current_exe().context("locating this program to run the child processes")?;
    println!(
        "Generated stereo BA: {n} cameras (2 fixed), {GENERATED_POINTS_PER_CAMERA} points per camera seen by 4 cameras, seed {GENERATED_SEED}, {} iterations, backend {:?}",
        args.iterations,
        args.optimizer.build().name()
    );
    println!(
        "{:<7} {:>8} {:>6} {:>13} {:>13} {:>9} {:>8} {:>12} {:>12}",
        "path", "unknowns", "iters", "initial", "final", "time s", "cpu s", "peak MiB", "solver MiB"
    );
    let mut finals = Vec::new();
    let backend = args.optimizer.build().name().to_string(); // the backends' names are their CLI names
    for path in ["sparse", "dense"] {
        let out = std::process::Command::new(&exe)
            .args(["optim-bench", "--generated", &n.to_string(), "--iterations", &args.iterations.to_string()])
            .args(["--generated-path", path, "--optimizer", &backend])
            .output()
            .with_context(|| format!("running {}", exe.display()))?;
        let text = String::from_utf8_lossy(&out.stdout);
        let Some(line) = text.lines().find(|l| l.starts_with("GENERATED ")) else {
            anyhow::bail!(
                "the {path} run gave no result (exit {:?}): {}",
                out.status.code(),
                String::from_utf8_lossy(&out.stderr).trim()
            );
        };
        let field = |name: &str| -> anyhow::Result<f64> {
            line.split_whitespace()
                .find_map(|kv| kv.strip_prefix(name)?.strip_prefix('='))
                .and_then(|v| v.parse().ok())
                .with_context(|| format!("field {name} missing in {line:?}"))
        };
        let (peak, before) = (field("peak_kib")?, field("rss_before_kib")?);
        finals.push(field("final")?);
        println!(
            "{:<7} {:>8} {:>6} {:>13.6e} {:>13.6e} {:>9.3} {:>8.2} {:>12.1} {:>12.1}",
            path,
            field("reduced")?,
            field("iterations")?,
            field("initial")?,
            field("final")?,
            field("seconds")?,
            field("cpu")?,
            peak / 1024.0,
            (peak - before) / 1024.0
        );
    }
    if let [s, d] = finals[..] {
        println!("final costs: sparse vs dense differ by {:.2e} (relative)", (s - d).abs() / d.abs());
    }
    println!("peak MiB: the process's peak resident memory (VmHWM); solver MiB: its growth during the solve.");
    Ok(())
}
