//! Does the seam cost speed? Solves a BAL problem with Levenberg–Marquardt called directly (the concrete
//! type, statically dispatched) and through `&dyn Optimizer` (the seam), alternating, and prints the
//! median wall and CPU time of each.
//!
//! `cargo run --release -p slam-lm --example bal_seam -- FILE [--huber] [--reps N]`

use std::time::Instant;

use slam_lm::LevenbergMarquardt;
use slam_optim::{io::read_bal, Optimizer, Options, Summary};

/// CPU time of this process in seconds (user + system, from `/proc/self/stat`; 0 where unavailable).
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // fields after the command name (which is in parentheses and may hold spaces)
    let Some(rest) = stat.rsplit(')').next() else { return 0.0 };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|s| s.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let file = args.first().ok_or("usage: bal_seam FILE [--huber] [--reps N]")?;
    let huber = args.iter().any(|a| a == "--huber").then_some(1.0);
    let reps: usize = match args.iter().position(|a| a == "--reps") {
        Some(i) => args.get(i + 1).ok_or("--reps needs a number")?.parse()?,
        None => 3,
    };
    let lm = LevenbergMarquardt::default();
    let seam: &dyn Optimizer = &lm;
    let (mut wall, mut cpu) = ([Vec::new(), Vec::new()], [Vec::new(), Vec::new()]);
    let mut last: [Option<Summary>; 2] = [None, None];
    for _ in 0..reps.max(1) {
        for (which, via_trait) in [(0, false), (1, true)] {
            let mut p = read_bal(std::path::Path::new(file), huber)?;
            for &k in &p.points {
                p.graph.eliminate(k);
            }
            let options = Options::default();
            let (t0, c0) = (Instant::now(), cpu_seconds());
            let s = if via_trait {
                seam.optimize(&p.graph, &mut p.values, &options, None)?
            } else {
                lm.optimize(&p.graph, &mut p.values, &options, None)?
            };
            wall[which].push(t0.elapsed().as_secs_f64());
            cpu[which].push(cpu_seconds() - c0);
            last[which] = Some(s);
        }
    }
    println!("{:<8} {:>22} {:>6} {:>10} {:>10}", "call", "final cost", "iters", "wall s", "cpu s");
    for (which, name) in [(0, "direct"), (1, "trait")] {
        let s = last[which].as_ref().ok_or("no run")?;
        println!(
            "{:<8} {:>22.15e} {:>6} {:>10.3} {:>10.2}",
            name,
            s.final_cost,
            s.iterations,
            median(wall[which].clone()),
            median(cpu[which].clone())
        );
    }
    Ok(())
}
