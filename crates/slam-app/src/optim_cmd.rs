//! `slam-app optim-bench`: the optimiser on the anchor problems of `fixtures/optim/ANCHORS.md`.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use slam_optim::bench::{self, GeneratedRun, ANCHORS, GENERATED_POINTS_PER_CAMERA, GENERATED_SEED};

use slam_runner::OptimizerKind;

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

pub fn run(args: &OptimBenchArgs) -> anyhow::Result<()> {
    crate::validate::count("--reps", args.reps, 1, 1000)?;
    if let Some(n) = args.generated {
        crate::validate::count("--generated", n, 3, 100_000)?;
        crate::validate::count("--iterations", args.iterations, 1, 1000)?;
        if let Some(path) = &args.generated_path {
            let optimizer = args.optimizer.build();
            println!("{}", bench::generated_solve(optimizer.as_ref(), n, args.iterations, path == "dense")?.line());
            return Ok(());
        }
        return generated_table(args, n);
    }
    let anchors = bench::anchors_matching(args.only.as_deref());
    if let (Some(o), true) = (&args.only, anchors.is_empty()) {
        let names: Vec<&str> = ANCHORS.iter().map(|a| a.name).collect();
        anyhow::bail!("--only {o:?} matches no problem (problems: {})", names.join(", "));
    }
    let dir = args.data.clone().unwrap_or_else(|| crate::fixture("optim"));
    let optimizer = args.optimizer.build();
    println!(
        "Optimiser benchmark, backend {:?}, on {} ({} timed runs each, median; single thread)",
        optimizer.name(),
        dir.display(),
        args.reps
    );
    println!("{}", bench::anchor_table_header());
    for a in &anchors {
        println!("{}", a.row(&bench::run_anchor(optimizer.as_ref(), &dir, a, args.reps)?));
    }
    println!("ratio = our median time / the anchor's single-thread median (ANCHORS.md, another day: for a ratio measured in one sitting use tools/ceres-vs-ours.sh).");
    println!("cpu s = median process CPU time of the solve (steadier than wall time on a shared machine).");
    println!("BA: Options::default() (Ceres' defaults), points eliminated by Schur; pose graphs: Options::pose_graph(), vertex 0 fixed.");
    Ok(())
}

/// `--generated N`: the sparse then the dense path, each in a child process of this program (so each
/// peak memory is its own, `--generated-path`), and a table.
fn generated_table(args: &OptimBenchArgs, n: usize) -> anyhow::Result<()> {
    let exe = std::env::current_exe().context("locating this program to run the child processes")?;
    let backend = args.optimizer.build().name().to_string(); // the backends' names are their CLI names
    println!(
        "Generated stereo BA: {n} cameras (2 fixed), {GENERATED_POINTS_PER_CAMERA} points per camera seen by 4 cameras, seed {GENERATED_SEED}, {} iterations, backend {backend:?}",
        args.iterations,
    );
    println!("{}", bench::generated_table_header());
    let mut finals = Vec::new();
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
        let r = GeneratedRun::parse(line)?;
        finals.push(r.final_cost);
        println!("{}", r.row(path));
    }
    if let [s, d] = finals[..] {
        println!("final costs: sparse vs dense differ by {:.2e} (relative)", (s - d).abs() / d.abs());
    }
    println!("peak MiB: the process's peak resident memory (VmHWM); solver MiB: its growth during the solve.");
    Ok(())
}
