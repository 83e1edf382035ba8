//! `slam-app optim-bench`: the optimiser on the anchor problems of `fixtures/optim/ANCHORS.md`.

use std::{path::PathBuf, time::Duration};

use anyhow::Context;
use clap::Args;
use slam_optim::{
    io::{read_bal, read_g2o, Problem},
    LevenbergMarquardt, LmParams, Summary,
};

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

fn load(dir: &std::path::Path, a: &Anchor) -> anyhow::Result<(Problem, LevenbergMarquardt)> {
    let path = dir.join(a.file);
    let mut lm = LevenbergMarquardt::new(LmParams::default());
    let p = if a.file.ends_with(".g2o") {
        lm = LevenbergMarquardt::new(LmParams::pose_graph());
        let p = read_g2o(&path)?;
        if let Some(&k) = p.cameras.first() {
            lm.fix(k);
        }
        p
    } else {
        let p = read_bal(&path, a.huber)?;
        for &k in &p.points {
            lm.eliminate(k);
        }
        p
    };
    Ok((p, lm))
}

pub fn run(args: &OptimBenchArgs) -> anyhow::Result<()> {
    crate::validate::count("--reps", args.reps, 1, 1000)?;
    if let Some(o) = &args.only {
        if !ANCHORS.iter().any(|a| a.name.contains(o.as_str())) {
            let names: Vec<&str> = ANCHORS.iter().map(|a| a.name).collect();
            anyhow::bail!("--only {o:?} matches no problem (problems: {})", names.join(", "));
        }
    }
    let dir = args.data.clone().unwrap_or_else(|| crate::fixture("optim"));
    println!("Optimiser benchmark on {} ({} timed runs each, median; single thread)", dir.display(), args.reps);
    println!(
        "{:<18} {:>13} {:>13} {:>13} {:>9} {:>5} {:>9} {:>14} {:>7} {:>13}",
        "problem", "initial", "final", "best known", "vs best", "iters", "time s", "reference", "ratio", "ref. cost"
    );
    for a in ANCHORS.iter().filter(|a| args.only.as_deref().is_none_or(|o| a.name.contains(o))) {
        let mut times = Vec::new();
        let mut last: Option<Summary> = None;
        for _ in 0..args.reps.max(1) {
            let (mut p, lm) = load(&dir, a).with_context(|| format!("loading {}", a.file))?;
            let s = lm.solve(&p.graph, &mut p.values, None).with_context(|| format!("solving {}", a.name))?;
            times.push(s.elapsed);
            last = Some(s);
        }
        times.sort();
        let median: Duration = times[times.len() / 2];
        let Some(s) = last else { continue };
        let vs_best = (s.final_cost - a.best_known) / a.best_known;
        println!(
            "{:<18} {:>13.6e} {:>13.6e} {:>13.6e} {:>+8.4}% {:>5} {:>9.3} {:>9} {:>4.2}s {:>6.2}x {:>13.6e}",
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
            a.reference_cost
        );
    }
    println!("ratio = our median time / the anchor's single-thread median (ANCHORS.md, ±30 % noise there).");
    println!("BA: LmParams::default() (Ceres' defaults), points eliminated by Schur; pose graphs: LmParams::pose_graph(), vertex 0 fixed.");
    Ok(())
}
