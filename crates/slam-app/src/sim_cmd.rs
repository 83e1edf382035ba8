//! `slam-app sim`: the simulation study, with tables, CSV and plots.

use std::{path::PathBuf, time::Instant};

use clap::Args;
use slam_sim::{report, sweep, SweepConfig};

#[derive(Args, Debug)]
pub struct SimArgs {
    /// Master seed (printed; the default reproduces docs/simulation.md).
    #[arg(long, default_value_t = 20220601)]
    seed: u64,
    /// Objects per cell.
    #[arg(long, default_value_t = 10)]
    objects: u64,
    /// Noise seeds per object.
    #[arg(long, default_value_t = 10)]
    noise_seeds: u64,
    /// Output folder for simulation.csv and the plots.
    #[arg(long, default_value = "out/sim")]
    out: PathBuf,
    /// Skip the plots.
    #[arg(long)]
    no_plots: bool,
    /// Also run Tri+Yaw+refine alone with the next N-1 master seeds (--seed + 1, + 2, ...) and print how
    /// its target cells vary over the N seeds (mean ± sd, least, largest)
    #[arg(long, default_value_t = 1)]
    seeds: u64,
}

pub fn run(a: &SimArgs) -> anyhow::Result<()> {
    slam_core::check::count("--objects", a.objects as usize, 1, 100_000)?;
    slam_core::check::count("--noise-seeds", a.noise_seeds as usize, 1, 100_000)?;
    slam_core::check::count("--seeds", a.seeds as usize, 1, 1000)?;
    // written beside the old folder and swapped in at the end; checked writable before the sweep
    let dir = slam_dataset::output::OutputDir::create(&a.out, "--out", "sim")?;
    let config = SweepConfig { seed: a.seed, objects: a.objects, noise_seeds: a.noise_seeds, ..SweepConfig::default() };
    println!("{}", report::title(&config));
    let mut bar = slam_runner::console::Progress::new("sim", 0, "cells", false);
    let start = Instant::now();
    let cells = sweep(&config, |done, total| {
        bar.set(done as u64, total as u64);
    });
    bar.finish();
    let elapsed = start.elapsed();
    print!("{}", report::tables(&cells, &config));
    slam_dataset::output::write_file(&dir.path().join("simulation.csv"), report::csv(&cells)?.as_bytes())?;
    let mut plots = Vec::new();
    if !a.no_plots {
        for &g in &config.geometries {
            plots.extend(slam_viz::simulation_figure(&cells, g, &config.noise, &config.methods, dir.path())?);
        }
    }
    dir.commit()?;
    println!(
        "\n{} cells in {:.1} s; CSV: {}",
        cells.len(),
        elapsed.as_secs_f64(),
        a.out.join("simulation.csv").display()
    );
    for f in plots {
        println!("plot: {}", a.out.join(f.file_name().unwrap_or_default()).display());
    }
    if a.seeds > 1 {
        let mut runs = vec![(a.seed, cells)];
        let mut bar = slam_runner::console::Progress::new("seeds", a.seeds - 1, "seeds", false);
        for k in 1..a.seeds {
            let seed = a.seed.wrapping_add(k);
            let config = SweepConfig { seed, methods: vec![slam_sim::Method::TriYawRefine], ..config.clone() };
            runs.push((seed, sweep(&config, |_, _| {})));
            bar.inc();
        }
        bar.finish();
        print!("{}", report::seed_spread(&runs));
    }
    Ok(())
}
