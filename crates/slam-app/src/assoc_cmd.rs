//! `slam-app assoc …`: association accuracy studies (`slam_assoc::study`).

use std::path::PathBuf;

use clap::{Args, Subcommand};
use slam_assoc::study::{
    compared_associators, label_study, labelled_frames, sim_variants, simulated_totals, CONDITIONS,
};
use slam_dataset::kitti::tracking::read_tracking_labels;

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

/// The `ODA / IoU` cells of one table row.
fn cells(row: &mut String, pairs: impl Iterator<Item = [usize; 2]>) {
    for [oda, iou] in pairs {
        row.push_str(&format!(" | {:>20}", format!("{oda} / {iou}")));
    }
}

fn kitti(a: &KittiArgs) -> anyhow::Result<()> {
    if let Some(p) = &a.csv {
        // checked writable before the study runs
        drop(crate::output::AtomicFile::new(p)?);
    }
    let dir = a.dir.clone().unwrap_or_else(|| crate::fixture("kitti_tracking"));
    let seqs = crate::tracking_sequences(&dir)?;
    println!("KITTI tracking labels as detections ({} sequences in {}), seed {}", seqs.len(), dir.display(), a.seed);
    println!("DontCare and Misc dropped; noise: Gaussian, sigma = fraction of box width/height per coordinate.");
    println!("Cues available: Kalman prediction only (no images: no flow; no ellipsoids).");
    let mut header = format!("{:<6} {:>7}", "seq", "objects");
    for c in &CONDITIONS {
        header.push_str(&format!(" | {:>20}", format!("{} ODA/IoU", c.name)));
    }
    println!("{header}");
    let mut csv = csv::Writer::from_writer(Vec::new());
    csv.write_record(["sequence", "objects", "detections", "condition", "associator", "id_switches"])?;
    let mut totals = vec![[0usize; 2]; CONDITIONS.len()];
    for seq in &seqs {
        let name = seq.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let labels = read_tracking_labels(seq.join("label_02.txt"))?;
        let (frames, n_frames, objects) =
            labelled_frames(labels.iter().map(|l| (l.frame, l.track_id, l.class, l.bbox)));
        let runs = label_study(&frames, n_frames, a.seed);
        for ((cond, pair), total) in CONDITIONS.iter().zip(&runs).zip(&mut totals) {
            for ((aname, _), (r, t)) in compared_associators().iter().zip(pair.iter().zip(total.iter_mut())) {
                *t += r.id_switches;
                let (o, d, s) = (objects.to_string(), r.detections.to_string(), r.id_switches.to_string());
                csv.write_record([name.as_str(), &o, &d, cond.name, aname, &s])?;
            }
        }
        let mut row = format!("{:<6} {:>7}", name, objects);
        cells(&mut row, runs.iter().map(|p| p.map(|r| r.id_switches)));
        println!("{row}");
    }
    let mut row = format!("{:<6} {:>7}", "total", "");
    cells(&mut row, totals.iter().copied());
    println!("{row}");
    if let Some(path) = &a.csv {
        crate::output::write_file(path, &csv.into_inner().map_err(|e| e.into_error())?)?;
        println!("CSV written to {}", path.display());
    }
    Ok(())
}
