//! `slam-app assoc …`: association accuracy studies (`slam_studies::assoc_study`).

use std::path::PathBuf;

use clap::{Args, Subcommand};

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
    slam_core::check::count("--scenes", a.scenes as usize, 1, 100_000)?;
    slam_core::check::count("--frames", a.frames, 1, 1_000_000)?;
    slam_studies::assoc_study::simulated_table(a.scenes, a.frames, &mut |l| println!("{l}"));
    Ok(())
}

fn kitti(a: &KittiArgs) -> anyhow::Result<()> {
    let dir = a.dir.clone().unwrap_or_else(|| crate::fixture("kitti_tracking"));
    let seqs = slam_dataset::folders::tracking_sequences(&dir)?;
    if let Some(p) = &a.csv {
        // every file of a sequence, read or not: the csv must not replace any of the dataset
        let files: Vec<PathBuf> =
            seqs.iter().flat_map(|s| slam_eval::labelled::SEQUENCE_FILES.map(|f| s.join(f))).collect();
        let inputs: Vec<(&str, &std::path::Path)> = files.iter().map(|l| ("the sequence file", l.as_path())).collect();
        slam_dataset::output::refuse_overwriting_inputs(&inputs, &[slam_dataset::output::Written::File("--csv", p)])?;
        // checked writable before the study runs
        drop(slam_dataset::output::AtomicFile::new(p)?);
    }
    println!("{}", slam_eval::assoc::kitti_table_header(seqs.len(), &dir, a.seed));
    let csv = slam_eval::assoc::kitti_assoc_study(&seqs, a.seed, &mut |row| println!("{row}"))?;
    if let Some(path) = &a.csv {
        slam_dataset::output::write_file(path, csv.as_bytes())?;
        println!("CSV written to {}", path.display());
    }
    Ok(())
}
