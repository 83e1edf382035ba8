//! `slam-app assoc …`: association accuracy studies.

use std::{collections::BTreeMap, path::PathBuf};

use clap::{Args, Subcommand};
use slam_assoc::{
    eval::{run as run_sim, simulate, IdSwitchCounter, MotCounts, SimRng, SimConfig},
    IouAssociator, ObjectTracker, Oda, TrackerConfig, TrackerInput,
};
use slam_core::{geometry::BBox, Associator, Detection};
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
        let mut totals = [MotCounts::default(), MotCounts::default()];
        for seed in 0..a.scenes {
            let frames = simulate(&cfg, seed);
            for (k, (_, make)) in associators().iter().enumerate() {
                let mut tracker = ObjectTracker::new(make(), TrackerConfig::default());
                let c = run_sim(&mut tracker, &frames);
                totals[k].ground_truth += c.ground_truth;
                totals[k].misses += c.misses;
                totals[k].false_positives += c.false_positives;
                totals[k].id_switches += c.id_switches;
            }
        }
        println!(
            "{:<24} {:>10} {:>8.4} {:>10} {:>8.4}",
            name,
            totals[0].id_switches,
            totals[0].mota(),
            totals[1].id_switches,
            totals[1].mota()
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
        let mut frames: BTreeMap<usize, Vec<(u64, Detection)>> = BTreeMap::new();
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
                let mut rng = SimRng::new(a.seed.wrapping_mul(1000).wrapping_add(ci as u64));
                let mut tracker = ObjectTracker::new(make(), TrackerConfig::default());
                let mut ids = IdSwitchCounter::default();
                let mut n_det = 0;
                let projected = BTreeMap::new();
                for f in 0..n_frames {
                    let mut truth = Vec::new();
                    let mut dets = Vec::new();
                    for (id, d) in frames.get(&f).map(|v| v.as_slice()).unwrap_or(&[]) {
                        if rng.unit() < cond.dropout {
                            continue;
                        }
                        let b = d.bbox;
                        let (sx, sy) = (cond.noise_frac * b.width(), cond.noise_frac * b.height());
                        let nb = BBox::new(
                            b.xmin + sx * rng.normal(),
                            b.ymin + sy * rng.normal(),
                            b.xmax + sx * rng.normal(),
                            b.ymax + sy * rng.normal(),
                        );
                        let nb = if nb.validated().is_ok() { nb } else { b };
                        dets.push(Detection::new(d.class, 1.0, nb));
                        truth.push(*id);
                    }
                    n_det += dets.len();
                    let out = tracker.step(&TrackerInput {
                        detections: &dets,
                        projected: &projected,
                        flow: &[],
                        keyframe: true,
                    });
                    ids.frame(truth.iter().zip(&out.tracks).filter_map(|(t, k)| Some((*t, (*k)?))));
                }
                totals[ci][k] += ids.switches;
                cells.push(ids.switches);
                csv.write_record([
                    name.clone(),
                    objects.len().to_string(),
                    n_det.to_string(),
                    cond.name.to_string(),
                    aname.to_string(),
                    ids.switches.to_string(),
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
