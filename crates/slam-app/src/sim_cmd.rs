//! `slam-app sim`: the simulation study, with tables, CSV and plots.

use std::path::PathBuf;

use clap::Args;
use slam_runner::{
    console::Progress,
    simulation::{run_simulation, SimPlan},
};
use slam_sim::SweepConfig;

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
    let config = SweepConfig { seed: a.seed, objects: a.objects, noise_seeds: a.noise_seeds, ..SweepConfig::default() };
    let plan = SimPlan { config, plots: !a.no_plots, seeds: a.seeds };
    let mut cells = Some(Progress::new("sim", 0, "cells", false));
    let mut seeds: Option<Progress> = None;
    run_simulation(
        &plan,
        &a.out,
        &mut |text| print!("{text}"),
        &mut |done, total| {
            if let Some(bar) = &mut cells {
                bar.set(done as u64, total as u64);
            }
            if done == total {
                cells.take().into_iter().for_each(Progress::finish);
            }
        },
        &mut |done, total| {
            seeds.get_or_insert_with(|| Progress::new("seeds", total, "seeds", false)).inc();
            if done == total {
                seeds.take().into_iter().for_each(Progress::finish);
            }
        },
    )?;
    Ok(())
}
