//! `slam-app assoc …`: association accuracy studies (`slam_assoc::study`).

use std::path::PathBuf;

use clap::{Args, Subcommand};
use slam_assoc::study::{compared_associators, sim_variants, simulated_totals};

#[derive(Subcommand, Debug)]
pub enum AssocCommand {
    /// Simulated scenes with crossing, occluding objects, dropouts and clutter.
    Sim(SimArgs),
    /// KITTI tracking label boxes as detections (true track ids hidden), with optional noise and dropout.
    Kitti(KittiArgs),
}

#[derive(Args, Debug)]
pub struct SimArgs {
    /// Number of scenes (seeds 0..N).
    #[arg(long, default_value_t = 10)]
    scenes: u64,
    /// Frames per scene.
    #[arg(long, default_value_t = 300)]
    frames: usize,
}

#[derive(Args, Debug)]
pub struct KittiArgs {
    /// Folder holding one sub-folder per sequence with `label_02.txt`
    /// (default: the shipped fixtures/kitti_tracking).
    dir: Option<PathBuf>,
    /// Master seed of the noise and dropout.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also write the table as CSV to this file.
    #[arg(long)]
    csv: Option<PathBuf>,
}

pub fn run(cmd: AssocCommand) -> anyhow::Result<()> {
    match cmd {
        AssocCommand::Sim(a) => sim(&a),
        AssocCommand::Kitti(a) => kitti(&a),
    }
}

fn sim(a: &SimArgs) -> anyhow::Result<()> {
    crate::validate::count("--scenes", a.scenes as usize, 1, 100_000)?;
    crate::validate::count("--frames", a.frames, 1, 1_000_000)?;
    println!("Simulated association, {} scenes x {} frames, 8 objects of one class in two lanes", a.scenes, a.frames);
    println!("{:<24} {:>10} {:>8} {:>10} {:>8}", "scene", "ODA IDSW", "ODA MOTA", "IoU IDSW", "IoU MOTA");
    for (name, cfg) in sim_variants(a.frames) {
        let [oda, iou] = compared_associators().map(|(_, make)| simulated_totals(&cfg, a.scenes, make));
        println!("{name:<24} {:>10} {:>8.4} {:>10} {:>8.4}", oda.id_switches, oda.mota(), iou.id_switches, iou.mota());
    }
    Ok(())
}

fn kitti(a: &KittiArgs) -> anyhow::Result<()> {
    if let Some(p) = &a.csv {
        // checked writable before the study runs
        drop(slam_dataset::output::AtomicFile::new(p)?);
    }
    let dir = a.dir.clone().unwrap_or_else(|| crate::fixture("kitti_tracking"));
    let seqs = crate::tracking_sequences(&dir)?;
    println!("KITTI tracking labels as detections ({} sequences in {}), seed {}", seqs.len(), dir.display(), a.seed);
    println!("DontCare and Misc dropped; noise: Gaussian, sigma = fraction of box width/height per coordinate.");
    println!("Cues available: Kalman prediction only (no images: no flow; no ellipsoids).");
    println!("{}", slam_eval::assoc::kitti_table_header());
    let csv = slam_eval::assoc::kitti_assoc_study(&seqs, a.seed, &mut |row| println!("{row}"))?;
    if let Some(path) = &a.csv {
        slam_dataset::output::write_file(path, csv.as_bytes())?;
        println!("CSV written to {}", path.display());
    }
    Ok(())
}
