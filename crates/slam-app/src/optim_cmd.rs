//! `slam-app optim-bench`: the optimiser on the anchor problems of `fixtures/optim/ANCHORS.md`.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use slam_studies::optim_bench::{self as bench, ANCHORS};

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
    slam_core::check::count("--reps", args.reps, 1, 1000)?;
    if let Some(n) = args.generated {
        slam_core::check::count("--generated", n, 3, 100_000)?;
        slam_core::check::count("--iterations", args.iterations, 1, 1000)?;
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
    bench::anchor_table(args.optimizer.build().as_ref(), &dir, &anchors, args.reps, &mut |l| println!("{l}"))?;
    Ok(())
}

/// `--generated N`: the sparse then the dense path, each in a child process of this program (so each
/// peak memory is its own, `--generated-path`), and a table.
fn generated_table(args: &OptimBenchArgs, n: usize) -> anyhow::Result<()> {
    let exe = std::env::current_exe().context("locating this program to run the child processes")?;
    let backend = args.optimizer.build().name().to_string(); // the backends' names are their CLI names
    let child = |path: &str| -> Vec<String> {
        let (n, it) = (n.to_string(), args.iterations.to_string());
        ["optim-bench", "--generated", &n, "--iterations", &it, "--generated-path", path, "--optimizer", &backend]
            .map(String::from)
            .to_vec()
    };
    bench::generated_table(&exe, &child, (n, args.iterations, &backend), &mut |l| println!("{l}"))?;
    Ok(())
}
