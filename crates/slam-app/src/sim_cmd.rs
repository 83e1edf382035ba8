//! `slam-app sim`: the simulation study, with tables, CSV and plots.

use std::{path::PathBuf, time::Instant};

use anyhow::Context;
use clap::Args;
use slam_sim::{breakdown_level, sweep, CellStats, Geometry, Method, NoiseKind, SweepConfig};

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
}

fn fmt(x: f64, prec: usize) -> String {
    if x.is_nan() {
        "-".into()
    } else {
        format!("{x:.prec$}")
    }
}

/// Entries `sim` writes into its output folder (a folder written before the marker file existed may be
/// replaced when it holds only these).
fn sim_output_name(name: &str) -> bool {
    name == "simulation.csv"
        || (name.starts_with("sim_") && (name.ends_with(".svg") || name.ends_with(".png")))
        || name.ends_with(".tmp")
}

pub fn run(a: &SimArgs) -> anyhow::Result<()> {
    crate::validate::count("--objects", a.objects as usize, 1, 100_000)?;
    crate::validate::count("--noise-seeds", a.noise_seeds as usize, 1, 100_000)?;
    // written beside the old folder and swapped in at the end; checked writable before the sweep
    let dir = crate::output::OutputDir::create(&a.out, "--out", "sim", sim_output_name)?;
    let config = SweepConfig { seed: a.seed, objects: a.objects, noise_seeds: a.noise_seeds, ..SweepConfig::default() };
    println!(
        "Simulation study: master seed {} ({} objects x {} noise seeds = {} trials per cell)",
        config.seed,
        config.objects,
        config.noise_seeds,
        config.objects * config.noise_seeds
    );
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} cells {elapsed_precise} eta {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let start = Instant::now();
    let cells = sweep(&config, |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    });
    bar.finish_and_clear();
    let elapsed = start.elapsed();
    for &g in &config.geometries {
        for &k in &config.noise {
            print_table(&cells, g, k, &config.methods);
        }
    }
    println!("\nBreakdown level (smallest noise level with success < 50 %; '-' = never within the sweep):");
    println!(
        "{:<9} {:<12} {}",
        "geometry",
        "noise",
        config.methods.iter().map(|m| format!("{:>15}", m.name())).collect::<String>()
    );
    for &g in &config.geometries {
        for &k in &config.noise {
            let row: String = config
                .methods
                .iter()
                .map(|&m| {
                    format!("{:>15}", breakdown_level(&cells, g, k, m).map(|l| format!("{l}%")).unwrap_or("-".into()))
                })
                .collect();
            println!("{:<9} {:<12} {row}", g.name(), k.name());
        }
    }
    write_csv(&cells, &dir.path().join("simulation.csv"))?;
    let mut plots = Vec::new();
    if !a.no_plots {
        for &g in &config.geometries {
            plots.extend(crate::plot::simulation_figure(&cells, g, &config.noise, &config.methods, dir.path())?);
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
    Ok(())
}

fn print_table(cells: &[CellStats], g: Geometry, k: NoiseKind, methods: &[Method]) {
    println!(
        "\n== {} geometry, {} noise (per method: success %, median e_trans m, median e_axe m, mean IoU2D) ==",
        g.name(),
        k.name()
    );
    let mut header = format!("{:>6}", "p%");
    for m in methods {
        header.push_str(&format!(" | {:^26}", m.name()));
    }
    println!("{header}");
    for &level in k.levels() {
        let mut row = format!("{:>6}", level);
        for &m in methods {
            if let Some(c) = cells.iter().find(|c| c.geometry == g && c.noise == k && c.level == level && c.method == m)
            {
                row.push_str(&format!(
                    " | {:>4.0} {:>6} {:>6} {:>6}",
                    100.0 * c.success,
                    fmt(c.e_trans_median, 3),
                    fmt(c.e_axe_median, 3),
                    fmt(c.iou_mean, 3)
                ));
            }
        }
        println!("{row}");
    }
}

fn write_csv(cells: &[CellStats], path: &std::path::Path) -> anyhow::Result<()> {
    let mut csv = csv::Writer::from_writer(Vec::new());
    csv.write_record([
        "geometry",
        "noise",
        "level_percent",
        "method",
        "trials",
        "success",
        "e_trans_mean",
        "e_trans_median",
        "e_axe_mean",
        "e_axe_median",
        "iou_mean",
        "iou_median",
    ])?;
    for c in cells {
        csv.write_record([
            c.geometry.name().to_string(),
            c.noise.name().to_string(),
            c.level.to_string(),
            c.method.name().to_string(),
            c.trials.to_string(),
            c.success.to_string(),
            c.e_trans_mean.to_string(),
            c.e_trans_median.to_string(),
            c.e_axe_mean.to_string(),
            c.e_axe_median.to_string(),
            c.iou_mean.to_string(),
            c.iou_median.to_string(),
        ])?;
    }
    let s = csv.into_inner().map_err(|e| e.into_error())?;
    let tmp = path.with_extension("csv.tmp");
    std::fs::write(&tmp, s).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}
