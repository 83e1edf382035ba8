//! `slam-app sim`: the paper's simulation sweep ([`slam_sim`]) into an output folder (its tables,
//! `simulation.csv` and the figures), and the spread of the refined method over further master seeds.

use std::{path::Path, time::Instant};

use slam_sim::{report, sweep, SweepConfig};

use crate::error::{Result, RunnerError};

/// How a simulation study is run and what it writes.
#[derive(Debug, Clone)]
pub struct SimPlan {
    /// The sweep (master seed, objects per cell, noise seeds per object, …).
    pub config: SweepConfig,
    /// Draw the figures.
    pub plots: bool,
    /// Master seeds in all: with more than one, Tri+Yaw+refine alone is run again with the next ones.
    pub seeds: u64,
}

/// Run `plan` into the output folder `out` (written beside the old one and swapped in at the end,
/// checked writable before the sweep). `print` takes the text as it is to be written (line ends
/// included), `cells_done` the sweep's progress (done, total), `seeds_done` each further seed's.
pub fn run_simulation(
    plan: &SimPlan,
    out: &Path,
    print: &mut dyn FnMut(String),
    cells_done: &mut dyn FnMut(usize, usize),
    seeds_done: &mut dyn FnMut(u64, u64),
) -> Result<()> {
    let dir = slam_dataset::output::OutputDir::create(out, "--out", "sim")?;
    let config = &plan.config;
    print(format!("{}\n", report::title(config)));
    let start = Instant::now();
    let cells = sweep(config, &mut *cells_done);
    let elapsed = start.elapsed();
    print(report::tables(&cells, config));
    let csv = report::csv(&cells).map_err(RunnerError::other)?;
    slam_dataset::output::write_file(&dir.path().join("simulation.csv"), csv.as_bytes())?;
    let mut plots = Vec::new();
    if plan.plots {
        for &g in &config.geometries {
            plots.extend(slam_viz::simulation_figure(&cells, g, &config.noise, &config.methods, dir.path())?);
        }
    }
    dir.commit()?;
    let csv_path = out.join("simulation.csv");
    print(format!("\n{} cells in {:.1} s; CSV: {}\n", cells.len(), elapsed.as_secs_f64(), csv_path.display()));
    for f in plots {
        print(format!("plot: {}\n", out.join(f.file_name().unwrap_or_default()).display()));
    }
    if plan.seeds > 1 {
        let mut runs = vec![(config.seed, cells)];
        for k in 1..plan.seeds {
            let seed = config.seed.wrapping_add(k);
            let config = SweepConfig { seed, methods: vec![slam_sim::Method::TriYawRefine], ..config.clone() };
            runs.push((seed, sweep(&config, |_, _| {})));
            seeds_done(k, plan.seeds - 1);
        }
        print(report::seed_spread(&runs));
    }
    Ok(())
}
