//! `slam-app assoc …`: association accuracy studies.

use std::path::PathBuf;

use clap::{Args, Subcommand};
use slam_assoc::{
    eval::SimConfig,
    study::{id_switches_on_labels, simulated_totals, BoxNoise, LabelledFrames},
    IouAssociator, Oda,
};
use slam_core::{Associator, Detection};
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

/// Builds a fresh associator.
type Make = fn() -> Box<dyn Associator>;

fn associators() -> [(&'static str, Make); 2] {
    [("ODA", || Box::new(Oda::default())), ("IoU", || Box::new(IouAssociator::default()))]
}

fn sim(a: &SimArgs) -> anyhow::Result<()> {
    crate::validate::count("--scenes", a.scenes as usize, 1, 100_000)?;
    crate::validate::count("--frames", a.frames, 1, 1_000_000)?;
    let variants = [
        ("masks, 5-12 px/frame", SimConfig { frames: a.frames, ..SimConfig::default() }),
        ("boxes only", SimConfig { frames: a.frames, masks: false, ..SimConfig::default() }),
        ("slow, 2-7 px/frame", SimConfig { frames: a.frames, speed: (2.0, 7.0), ..SimConfig::default() }),
        ("no dropout, no clutter", SimConfig { frames: a.frames, dropout: 0.0, clutter: 0.0, ..SimConfig::default() }),
    ];
    println!("Simulated association, {} scenes x {} frames, 8 objects of one class in two lanes", a.scenes, a.frames);
    println!("{:<24} {:>10} {:>8} {:>10} {:>8}", "scene", "ODA IDSW", "ODA MOTA", "IoU IDSW", "IoU MOTA");
    for (name, cfg) in variants {
        let [oda, iou] = associators().map(|(_, make)| simulated_totals(&cfg, a.scenes, make));
        println!(
            "{:<24} {:>10} {:>8.4} {:>10} {:>8.4}",
            name,
            oda.id_switches,
            oda.mota(),
            iou.id_switches,
            iou.mota()
        );
    }
    Ok(())
}

/// Noise settings of one KITTI condition.
struct Condition {
    name: &'static str,
    noise_frac: f64,
    dropout: f64,
}

const CONDITIONS: [Condition; 3] = [
    Condition { name: "clean", noise_frac: 0.0, dropout: 0.0 },
    Condition { name: "noise 5%", noise_frac: 0.05, dropout: 0.0 },
    Condition { name: "noise 5% + drop 20%", noise_frac: 0.05, dropout: 0.2 },
];

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
        let mut frames = LabelledFrames::new();
        let n_frames = labels.iter().map(|l| l.frame + 1).max().unwrap_or(0);
        let mut objects = std::collections::BTreeSet::new();
        for l in &labels {
            if let (Some(class), true) = (l.class, l.track_id >= 0) {
                frames.entry(l.frame).or_default().push((l.track_id as u64, Detection::new(class, 1.0, l.bbox)));
                objects.insert(l.track_id);
            }
        }
        let mut row = format!("{:<6} {:>7}", name, objects.len());
        for (ci, cond) in CONDITIONS.iter().enumerate() {
            let mut cells = Vec::new();
            for (k, (aname, make)) in associators().iter().enumerate() {
                let noise = BoxNoise { noise_frac: cond.noise_frac, dropout: cond.dropout };
                let seed = a.seed.wrapping_mul(1000).wrapping_add(ci as u64);
                let r = id_switches_on_labels(&frames, n_frames, noise, seed, make());
                totals[ci][k] += r.id_switches;
                cells.push(r.id_switches);
                csv.write_record([
                    name.clone(),
                    objects.len().to_string(),
                    r.detections.to_string(),
                    cond.name.to_string(),
                    aname.to_string(),
                    r.id_switches.to_string(),
                ])?;
            }
            row.push_str(&format!(" | {:>20}", format!("{} / {}", cells[0], cells[1])));
        }
        println!("{row}");
    }
    let mut row = format!("{:<6} {:>7}", "total", "");
    for t in &totals {
        row.push_str(&format!(" | {:>20}", format!("{} / {}", t[0], t[1])));
    }
    println!("{row}");
    if let Some(path) = &a.csv {
        crate::output::write_file(path, &csv.into_inner().map_err(|e| e.into_error())?)?;
        println!("CSV written to {}", path.display());
    }
    Ok(())
}
