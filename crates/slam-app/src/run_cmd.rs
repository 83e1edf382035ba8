//! `slam-app run`: the whole system on a KITTI stereo sequence; trajectory, map, objects, pictures and
//! errors. `slam-app map`: inspect and export a saved map.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use slam_core::DetectionSource;
use slam_dataset::{
    check::calibration_file,
    detections::{DetectionFile, GroundTruthDetections, GroundTruthNoise},
    kitti::{
        stereo::{open_stereo, FrameSelection, Layout, StereoSequence, TruthSource},
        tracking::{read_tracking_labels, TrackingLabel},
    },
    trajectory::{write_kitti_poses, write_tum},
};
use slam_eval::{trajectory::PoseFile, LabelGeometry};
use slam_frontend::{read_image, StereoRig, StereoVo};
use slam_pipeline::{
    eval::trajectory_errors,
    report::{frame_period, median, median_fps, stage_table, state_counts, tracking_csv, STATE_NAMES},
    map::Map,
    objects::MappedObject,
    system::{self, FrameInput, RunOutput, SystemBuilder},
};
use slam_quadric::{ImageSize, Intrinsics};

use crate::{config::RunConfig, detect_cmd::ModelArgs};

/// Where the boxes come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DetectorKind {
    /// The shipped Yolo-Fastest detector (or the model given with --cfg/--weights/--onnx).
    Dnn,
    /// A detection JSON file (--detections; format in docs/detections.md).
    File,
    /// Ground-truth boxes from the sequence's labels (tracking layout), with --label-noise.
    Labels,
    /// No detector: odometry and map points only.
    None,
}

#[derive(Args, Debug)]
pub struct RunArgs {
    /// A KITTI stereo sequence: odometry (`sequences/NN` or a root with `sequences/`), raw drive
    /// (`<date>/<drive>_sync`) or tracking (`training/image_02/NNNN`). Default: the shipped odometry
    /// sequence 06, frames 0–50.
    path: Option<PathBuf>,
    /// Output folder
    #[arg(long, default_value = "out/run")]
    out: PathBuf,
    /// Optimiser backend for the tracker's two-frame BA, local BA and object fits.
    #[arg(long, value_enum, default_value_t = crate::optimizer_choice::OptimizerKind::Lm)]
    optimizer: crate::optimizer_choice::OptimizerKind,
    /// Settings file (TOML; see --print-config for every key and its default)
    #[arg(long)]
    config: Option<PathBuf>,
    /// Print the effective settings (library defaults, overlaid by --config and the options) as commented
    /// TOML and exit
    #[arg(long)]
    print_config: bool,
    /// Take a new keyframe after at most this many frames (overrides tracking.keyframe_max_gap)
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    keyframe_gap: Option<u64>,
    /// Turn local bundle adjustment off (overrides mapping.bundle_adjustment)
    #[arg(long)]
    no_ba: bool,
    /// Detection source (default: dnn; `file` when --detections is given, `labels` when --label-noise is)
    #[arg(long, value_enum)]
    detector: Option<DetectorKind>,
    /// Detection JSON (selects --detector file)
    #[arg(long)]
    detections: Option<PathBuf>,
    /// Box noise, fraction of box size (selects --detector labels; default 0)
    #[arg(long)]
    label_noise: Option<f64>,
    /// KITTI tracking labels of this sequence (label_02.txt format): the run's objects are scored
    /// against them (printed, and objects_score.json), and `--detector labels` takes its boxes from them
    /// on any layout (3-D boxes projected into the grey camera 0)
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Ellipsoid method of the objects (baselines for comparison)
    #[arg(long, value_enum, default_value_t = crate::objects_cmd::Method::Refine)]
    method: crate::objects_cmd::Method,
    /// Object associator (the paper's ODA, or the IoU baseline)
    #[arg(long, value_enum, default_value_t = crate::optimizer_choice::AssociatorKind::Oda)]
    associator: crate::optimizer_choice::AssociatorKind,
    /// Run the detector on every n-th frame only (overrides system.detect_every)
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    detect_every: Option<u64>,
    /// Frame ids to play (the numbers in the image file names): A..B (A to B-1), A..=B, A.. or ..B.
    /// Ground truth, labels and detections follow the ids, so they stay aligned.
    #[arg(long, value_parser = parse_frame_range)]
    frames: Option<FrameRange>,
    /// Play every N-th frame id from the first selected one (N = 3 at 10 Hz looks like driving 3x as fast)
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    stride: u64,
    /// Process at most this many frames (after --frames and --stride)
    #[arg(long)]
    max_frames: Option<usize>,
    /// Write overlay images (detections, projected ellipsoids with ids, trails) into <out>/overlays
    #[arg(long)]
    overlays: bool,
    /// Overlay every n-th frame (implies --overlays; default 1)
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    overlay_every: Option<u64>,
    /// Overlay image format: png (default), or jpg for files about ten times smaller (implies --overlays)
    #[arg(long, value_parser = ["png", "jpg"])]
    overlay_format: Option<String>,
    #[command(flatten)]
    model: ModelArgs,
}

/// A range of frame ids given on the command line (`--frames`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRange(Option<usize>, Option<usize>);

fn parse_frame_range(text: &str) -> Result<FrameRange, String> {
    FrameSelection::parse_range(text).map(|(a, b)| FrameRange(a, b))
}

impl RunArgs {
    fn selection(&self) -> FrameSelection {
        let FrameRange(first, end) = self.frames.unwrap_or(FrameRange(None, None));
        FrameSelection { first, end, stride: self.stride as usize }
    }
}

/// The frames a run plays: the sequence at `path` (default: the shipped odometry excerpt) with the
/// selection and `max_frames` applied; the sequence's input warnings are logged.
fn played_sequence(
    path: Option<&PathBuf>,
    sel: &FrameSelection,
    max_frames: Option<usize>,
) -> anyhow::Result<StereoSequence> {
    let path = path.cloned().unwrap_or_else(|| crate::fixture("kitti_odom_06/sequences/06"));
    let full = open_stereo(&path)?;
    for w in &full.warnings {
        tracing::warn!("{w}");
    }
    let mut seq = full.select(sel)?;
    if let Some(n) = max_frames {
        if n == 0 {
            bail!("nothing to run: --max-frames 0");
        }
        seq.truncate(n);
    }
    Ok(seq)
}

/// Which frames a trajectory file holds, for the run's summary.
fn played_ids(seq: &StereoSequence, sel: &FrameSelection) -> String {
    let (first, last) = (seq.ids[0], seq.ids[seq.ids.len() - 1]);
    let stride = if sel.stride > 1 { format!(" every {} ids", sel.stride) } else { String::new() };
    format!("frame ids {first}..={last}{stride}")
}

impl RunArgs {
    /// The detection source: `--detector` when given, else the one the mode-specific options select
    /// (`--detections`: file, `--label-noise`: labels), else the shipped network. An option of another
    /// mode than the one chosen is an error that names both.
    pub(crate) fn detector_kind(&self) -> anyhow::Result<DetectorKind> {
        let implied = match (&self.detections, self.label_noise) {
            (Some(_), Some(_)) => bail!("--detections (detector file) and --label-noise (detector labels) conflict"),
            (Some(_), None) => Some((DetectorKind::File, "--detections")),
            (None, Some(_)) => Some((DetectorKind::Labels, "--label-noise")),
            (None, None) => self.model.given().map(|flag| (DetectorKind::Dnn, flag)),
        };
        match (self.detector, implied) {
            (None, None) => Ok(DetectorKind::Dnn),
            (None, Some((kind, _))) => Ok(kind),
            (Some(kind), None) => Ok(kind),
            (Some(kind), Some((wanted, _))) if kind == wanted => Ok(kind),
            (Some(kind), Some((wanted, flag))) => {
                bail!("{flag} is an option of --detector {}, but --detector {} was given", wanted.name(), kind.name())
            }
        }
    }

    fn overlays_on(&self) -> bool {
        self.overlays || self.overlay_every.is_some() || self.overlay_format.is_some()
    }
}

impl DetectorKind {
    fn name(self) -> &'static str {
        match self {
            DetectorKind::Dnn => "dnn",
            DetectorKind::File => "file",
            DetectorKind::Labels => "labels",
            DetectorKind::None => "none",
        }
    }
}

/// The detection source of a run; `notes` collects reports of detections no frame of the run uses.
fn detector(
    a: &RunArgs,
    seq: &StereoSequence,
    image: ImageSize,
    labels: Option<&(Vec<TrackingLabel>, LabelGeometry)>,
    notes: &mut Vec<String>,
) -> anyhow::Result<Option<Box<dyn DetectionSource>>> {
    Ok(match a.detector_kind()? {
        DetectorKind::None => None,
        // the mapped classes are kept by `ClassFilter`, for every source alike
        DetectorKind::Dnn => Some(Box::new(a.model.load().context("loading the detector")?)),
        DetectorKind::File => {
            let path = a.detections.as_ref().context("--detector file needs --detections <file.json>")?;
            let file = DetectionFile::read(path)?;
            if let Some([w, h]) = file.image_size {
                if (w as f64, h as f64) != (image.width, image.height) {
                    bail!(
                        "{}: detections for {w}×{h} images, but {} is {}×{}",
                        path.display(),
                        seq.left.iter().find(|p| p.is_file()).unwrap_or(&seq.left[0]).display(),
                        image.width,
                        image.height
                    );
                }
            }
            let per_frame = file.frames.iter().map(|(&f, d)| (f, d.len()));
            notes.extend(slam_frontend::detectors::unused_frames(&path.display().to_string(), per_frame, &seq.ids));
            Some(Box::new(file))
        }
        DetectorKind::Labels => {
            let (labels, geometry) = labels.with_context(|| {
                format!(
                    "--detector labels: {} has no labels (tracking layout with label_02/): give --labels <label_02.txt>",
                    seq.dir.display()
                )
            })?;
            let truth = geometry.detections(labels);
            let per_frame = truth.iter().map(|(&f, d)| (f, d.len()));
            notes.extend(slam_frontend::detectors::unused_frames("labels", per_frame, &seq.ids));
            let noise = GroundTruthNoise { box_sigma: a.label_noise.unwrap_or(0.0), ..GroundTruthNoise::default() };
            Some(Box::new(GroundTruthDetections::new(truth, noise, [image.width, image.height])))
        }
    })
}

/// A finished run and what is needed to report on it.
struct Outcome {
    out: RunOutput,
    /// The labels (`--labels`, or the tracking layout's own) and their geometry in the run's camera.
    labels: Option<(Vec<TrackingLabel>, LabelGeometry)>,
    seq: StereoSequence,
    elapsed: f64,
    k: Intrinsics,
    image: ImageSize,
    colour: bool,
    /// What the detection guard changed, and reports of detections no frame used.
    detections: Option<std::sync::Arc<slam_frontend::detectors::DetectionCounts>>,
    notes: Vec<String>,
}

fn settings(a: &RunArgs) -> anyhow::Result<RunConfig> {
    use crate::validate::{count, number, Range};
    if let Some(noise) = a.label_noise {
        number("--label-noise", noise, Range::closed(0.0, 1.0), "(σ as a share of the box size)")?;
    }
    if let Some(n) = a.max_frames {
        count("--max-frames", n, 1, usize::MAX)?;
    }
    a.model.check()?;
    let mut cfg = match &a.config {
        Some(p) => RunConfig::read(p)?,
        None => RunConfig::default(),
    };
    if let Some(g) = a.keyframe_gap {
        cfg.tracking.keyframe_max_gap = g as usize;
    }
    if a.no_ba {
        cfg.mapping.bundle_adjustment = false;
    }
    if let Some(n) = a.detect_every {
        cfg.system.detect_every = n as usize;
    }
    Ok(cfg)
}

fn run_system(a: &RunArgs, cfg: &RunConfig, quiet: bool) -> anyhow::Result<Outcome> {
    let sel = a.selection();
    let seq = played_sequence(a.path.as_ref(), &sel, a.max_frames)?;
    let n = seq.len();
    // sizes and calibration are checked before the first frame: a right camera of another size would
    // make every frame unreadable
    let (l0, r0) = crate::validate::first_pair(&seq.left, &seq.right)?;
    let size = crate::validate::stereo_pair(l0, r0)?;
    crate::validate::calibration(&calibration_file(&seq), seq.intrinsics, seq.baseline, l0, size)?;
    crate::validate::declared_size(&calibration_file(&seq), l0, size)?;
    let [fx, fy, cx, cy] = seq.intrinsics;
    let k = Intrinsics::new(fx, fy, cx, cy);
    let rig = StereoRig { k, baseline: seq.baseline };
    let kind = a.detector_kind()?;
    if !quiet {
        let source = match (kind, &a.detections) {
            (DetectorKind::File, Some(f)) => format!("detections from {}", f.display()),
            (DetectorKind::Labels, _) => format!("label boxes, noise {}", a.label_noise.unwrap_or(0.0)),
            (DetectorKind::Dnn, _) => "the network (dnn)".to_string(),
            (k, _) => k.name().to_string(),
        };
        println!(
            "quadric SLAM on {} ({:?} layout, {n} frames: {}, fx {fx:.1} px, baseline {:.4} m, detector: {source}, \
             association: {}, ellipsoids: {})",
            seq.dir.display(),
            seq.layout,
            played_ids(&seq, &sel),
            seq.baseline,
            a.associator.name(),
            a.method.fit().name(),
        );
        if !(seq.gaps.is_empty() && seq.one_camera.is_empty()) {
            println!(
                "input: {} frame(s) missing in both cameras (skipped, ids kept), {} with one image missing (played as unreadable); see the warnings",
                seq.gaps.len(),
                seq.one_camera.len()
            );
        }
    }
    let colour = seq.layout != Layout::Odometry;
    // the image size comes from the first frame whose left image exists
    let first_left = seq.left.iter().find(|p| p.is_file()).unwrap_or(&seq.left[0]);
    let first = read_image(first_left, colour).with_context(|| format!("first frame {}", first_left.display()))?;
    let image = ImageSize::new(first.width as f64, first.height as f64);
    let mut tracking = cfg.tracking;
    if tracking.frame_period_s <= 0.0 {
        let stamped: Vec<(usize, f64)> = (0..n.min(seq.times.len())).map(|i| (seq.ids[i], seq.times[i])).collect();
        tracking.frame_period_s = frame_period(&stamped);
    }
    let optimizer = a.optimizer.build();
    let tracker = Box::new(StereoVo::new(rig, tracking, optimizer.clone())?);
    let labels = match (&a.labels, &seq.labels) {
        (Some(p), _) => Some(read_tracking_labels(p)?),
        (None, Some(l)) => Some(l.clone()),
        (None, None) => None,
    };
    let labels = match labels {
        Some(l) => Some((l, LabelGeometry::of_sequence(&seq, image)?)),
        None => None,
    };
    let mut notes = Vec::new();
    let mut counts = None;
    let det = detector(a, &seq, image, labels.as_ref(), &mut notes)?.map(|d| {
        let (g, c) = slam_frontend::detectors::DetectionGuard::new(
            Box::new(slam_frontend::detectors::ClassFilter(d)),
            [image.width, image.height],
            cfg.system.max_detections,
        );
        counts = Some(c);
        Box::new(g) as Box<dyn DetectionSource>
    });
    for note in &notes {
        tracing::warn!("{note}");
    }
    let pairs: Vec<(usize, PathBuf, PathBuf)> =
        (0..n).map(|k| (seq.ids[k], seq.left[k].clone(), seq.right[k].clone())).collect();
    let first_size = (first.width, first.height);
    // Ctrl-C ends the input: the system finishes the frames it has, and the caller discards the run
    let frames = Box::new(pairs.into_iter().take_while(|_| !crate::output::interrupted()).map(move |(i, l, r)| {
        let images = read_image(&l, colour)
            .and_then(|li| read_image(&r, colour).map(|ri| (li, ri)))
            .map_err(|e| e.to_string())
            .and_then(|(li, ri)| {
                if (li.width, li.height) != (ri.width, ri.height) {
                    Err(format!(
                        "left {} is {}×{}, right {} is {}×{}",
                        l.display(),
                        li.width,
                        li.height,
                        r.display(),
                        ri.width,
                        ri.height
                    ))
                } else if (li.width, li.height) != first_size {
                    Err(format!(
                        "{} is {}×{}, the sequence's first frame {}×{}",
                        l.display(),
                        li.width,
                        li.height,
                        first_size.0,
                        first_size.1
                    ))
                } else {
                    Ok((li, ri))
                }
            });
        FrameInput { index: i, images }
    }));
    let mut bar = crate::progress::Progress::new("run", n as u64, "frames", quiet);
    let start = std::time::Instant::now();
    let (mut keyframes, mut lost) = (0usize, 0usize);
    let mut on_frame = |r: &system::FrameRecord| {
        keyframes += usize::from(r.keyframe);
        lost += usize::from(r.state == Some(slam_core::TrackState::Lost));
        bar.set_message(format!("{keyframes} keyframes, {lost} frames lost"));
        bar.inc();
    };
    let sys = cfg.system(image);
    let out = SystemBuilder::new(k, seq.baseline)
        .config(sys)
        .source(frames)
        .tracker(tracker)
        .detector(det)
        .associator(a.associator.build(sys.projected_gate))
        .optimizer(optimizer)
        .method(a.method.fit())
        .build()?
        .run(&mut on_frame)?;
    bar.finish();
    Ok(Outcome { out, labels, seq, elapsed: start.elapsed().as_secs_f64(), k, image, colour, detections: counts, notes })
}

/// The entries `slam-app run` writes into its output folder (a folder written before the marker file
/// existed may be replaced when it holds only these).
fn run_output_name(name: &str) -> bool {
    matches!(
        name,
        "trajectory.kitti.txt"
            | "trajectory.tum.txt"
            | "map.json"
            | "objects.json"
            | "map.svg"
            | "map.png"
            | "overlays"
            | "camera.json"
            | "objects_score.json"
            | "tracking.csv"
    ) || name.ends_with(".tmp")
}


pub fn run(a: &RunArgs) -> anyhow::Result<()> {
    let cfg = settings(a)?;
    if a.print_config {
        print!("{}", cfg.to_commented_toml());
        return Ok(());
    }
    a.detector_kind()?;
    // the output folder is written beside the old one and swapped in at the end; checked writable now
    crate::output::catch_interrupt();
    let dir = crate::output::OutputDir::create(&a.out, "--out", "run", run_output_name)?;
    let outcome = run_system(a, &cfg, false);
    let stop = |done: usize| {
        let kept = if dir.target().exists() {
            format!("{} keeps the previous run unchanged", a.out.display())
        } else {
            format!("{} was not created", a.out.display())
        };
        crate::output::Interrupted(format!("Ctrl-C after {done} frames: nothing written, {kept}"))
    };
    if crate::output::interrupted() {
        return Err(stop(outcome.as_ref().map_or(0, |o| o.out.counts.frames)).into());
    }
    let Outcome { out, labels, seq, elapsed, k, image, colour, detections, notes } = outcome?;
    let w = dir.path();
    // one pose per played frame, in id order; TUM lines carry the frames' own times
    write_kitti_poses(w.join("trajectory.kitti.txt"), &out.poses)?;
    write_tum(w.join("trajectory.tum.txt"), &seq.times, &out.poses)?;
    std::fs::write(w.join("tracking.csv"), tracking_csv(&out)?).with_context(|| format!("writing {}", w.join("tracking.csv").display()))?;
    out.map.save(&w.join("map.json"))?;
    let objects: Vec<&MappedObject> = out.objects.iter().collect();
    slam_pipeline::objects::write_object_map_in(&w.join("objects.json"), &objects, slam_pipeline::map::MAP_WORLD)
        .with_context(|| format!("writing {}", a.out.join("objects.json").display()))?;
    let c = out.counts;
    println!(
        "{} frames in {elapsed:.2} s: {:.1} frames/s overall, {:.1} frames/s median (all threads, incl. image decoding)",
        c.frames,
        c.frames as f64 / elapsed,
        median_fps(&out)
    );
    println!(
        "keyframes {}, lost {}, relocalised {}, new map segments {}, unreadable {}, detector errors {}, culled observations {}, duplicate or part boxes suppressed {}, ellipsoids of impossible size refused {}",
        c.keyframes, c.lost, c.relocalised, c.new_segments, c.unreadable, c.detector_errors, c.culled_observations, c.suppressed_boxes, c.implausible_fits
    );
    println!(
        "tracking states: tracked {}, weak {}, relocalised {}, lost {}, predicted {}, unreadable {} (tracking.csv has one row per frame)",
        c.tracked, c.weak, c.relocalised, c.lost, c.predicted, c.unreadable
    );
    let st = out.map.stats();
    let dets: usize = out.frames.iter().map(|f| f.detections.len()).sum();
    println!(
        "map: {} keyframes, {} points, {} observations; objects: {} with an ellipsoid ({} dynamic) from {dets} detections",
        st.keyframes, st.points, st.observations, st.objects, st.dynamic_objects
    );
    println!("\n| stage | median ms | frames |\n|---|---:|---:|");
    for (name, ms, count) in stage_table(&out) {
        println!("| {name} | {ms:.1} | {count} |");
    }
    if let Some(gt) = seq.truth_from_first() {
        if let Some(e) = trajectory_errors(&out.poses, &gt, &[10.0, 20.0, 40.0]) {
            if let Some(TruthSource::Oxts { median_pos_accuracy_m }) = seq.truth_source {
                println!(
                    "\nground truth from the drive's OXTS packets (differential GPS + IMU; median position accuracy {median_pos_accuracy_m:.2} m from the packets' pos_accuracy): position errors below that are not meaningful"
                );
            }
            println!(
                "\nground truth: path {:.1} m over {} frames; ATE {:.3} m (aligned {:.3} m); end-point drift {:.2} %; scale {:.4}",
                e.path_m, e.frames, e.ate_m, e.ate_aligned_m, e.end_drift_pct, e.scale
            );
            for (len, t, r, count) in e.rpe {
                println!("RPE over {len:.0} m segments ({count}): {t:.2} % translation, {r:.2} deg/100 m");
            }
        }
    }
    if let Some(d) = &detections {
        println!("{}", d.summary(cfg.system.max_detections));
    }
    for note in &notes {
        println!("unused detections: {note}");
    }
    LabelGeometry::of_sequence(&seq, image)?.write(&w.join("camera.json"))?;
    let mut scored = String::new();
    if let Some((labels, geometry)) = &labels {
        let objects: Vec<slam_eval::ScoredInput> = out
            .objects
            .iter()
            .filter_map(|o| {
                Some(slam_eval::ScoredInput {
                    id: o.id.0,
                    class: o.class.0,
                    ellipsoid: o.ellipsoid?,
                    frames: o.observations.iter().map(|x| x.frame).collect(),
                    dynamic: o.dynamic,
                })
            })
            .collect();
        let ids: Vec<usize> = out.frames.iter().map(|r| r.index).collect();
        let score =
            slam_eval::score_run(labels, &out.poses, &ids, geometry, &objects, &slam_eval::ScoreConfig::default());
        println!("\n{}", score.report());
        score.write_json(&w.join("objects_score.json"))?;
        scored.push_str("objects_score.json, ");
    }
    let pictures = pictures(a, w, &seq, &out, k, image, colour)?;
    if crate::output::interrupted() {
        return Err(stop(out.counts.frames).into());
    }
    dir.commit()?;
    println!(
        "\nwrote {}: trajectory.kitti.txt (one line per played frame), trajectory.tum.txt (frame times), tracking.csv (one row per played frame), map.json, objects.json, camera.json, {scored}{pictures}; {}",
        a.out.display(),
        played_ids(&seq, &a.selection())
    );
    Ok(())
}

#[derive(Args, Debug)]
pub struct RunBenchArgs {
    /// Runs per configuration (the table shows medians)
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Frames per run (default: the whole shipped sequence)
    #[arg(long)]
    max_frames: Option<usize>,
}

/// `slam-app run-bench`: the system on the shipped sequence without objects, with detections from the
/// shipped file, and with the shipped detector on every frame; medians over repeated runs.
pub fn run_bench(b: &RunBenchArgs) -> anyhow::Result<()> {
    #[derive(clap::Parser)]
    struct Wrap {
        #[command(flatten)]
        run: RunArgs,
    }
    use clap::Parser;
    let file = crate::fixture("kitti_odom_06/detections/yolo_fastest_tiles3.json");
    let file = file.to_string_lossy().to_string();
    let configs: [(&str, Vec<&str>); 3] = [
        ("no objects (--detector none)", vec!["--detector", "none"]),
        ("detections from a file", vec!["--detector", "file", "--detections", &file]),
        ("shipped detector, every frame", vec!["--detector", "dnn"]),
    ];
    let frames = b.max_frames.map(|n| n.to_string());
    println!("| configuration | frames/s (median) | frames/s (overall) | detection | extraction | stereo | tracking | flow | association | local BA | objects | ATE m |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut fps_of = Vec::new();
    for (name, extra) in configs {
        let mut argv = vec!["run"];
        argv.extend(extra.iter().copied());
        if let Some(n) = &frames {
            argv.extend(["--max-frames", n.as_str()]);
        }
        let a = Wrap::try_parse_from(argv)?.run;
        let cfg = settings(&a)?;
        let mut fps = Vec::new();
        let mut fps_median = Vec::new();
        let mut stages: Vec<Vec<f64>> = vec![Vec::new(); 8];
        let mut ate = Vec::new();
        for r in 0..b.repeat.max(1) {
            let o = run_system(&a, &cfg, true)?;
            fps.push(o.out.counts.frames as f64 / o.elapsed);
            fps_median.push(median_fps(&o.out));
            for (k, (_, ms, _)) in stage_table(&o.out).into_iter().enumerate() {
                stages[k].push(ms);
            }
            if let Some(e) = o.seq.truth_from_first().and_then(|g| trajectory_errors(&o.out.poses, &g, &[])) {
                ate.push(e.ate_m);
            }
            eprintln!("{name}: run {} of {}: {:.1} frames/s", r + 1, b.repeat.max(1), fps[fps.len() - 1]);
        }
        let f = median(&mut fps);
        let fm = median(&mut fps_median);
        fps_of.push(fm);
        let cells: Vec<String> = stages.iter_mut().map(|v| format!("{:.1}", median(v))).collect();
        println!("| {name} | {fm:.1} | {f:.1} | {} | {:.3} |", cells.join(" | "), median(&mut ate));
    }
    println!(
        "\nmedians of {} runs each. frames/s (median): 1000 / median interval between consecutive frames; (overall): frames / wall time, start-up and drain included. Stage times: medians over frames (local BA and objects: over keyframes, on the mapping thread), ms. Targets (median): >= 30 frames/s with detections from a file ({:.1}), >= 10 with the detector ({:.1}).",
        b.repeat.max(1),
        fps_of[1],
        fps_of[2]
    );
    Ok(())
}

fn pictures(
    a: &RunArgs,
    out_dir: &std::path::Path,
    seq: &StereoSequence,
    out: &RunOutput,
    k: Intrinsics,
    image: ImageSize,
    colour: bool,
) -> anyhow::Result<String> {
    slam_viz::map_picture(&out.map, &out.poses, seq.truth_from_first().as_deref(), out_dir)?;
    let mut written = "map.svg, map.png".to_string();
    if !a.overlays_on() {
        return Ok(written);
    }
    let format = a.overlay_format.as_deref().unwrap_or("png");
    let every = a.overlay_every.unwrap_or(1);
    let opts = slam_viz::OverlayOptions { left: &seq.left, colour, k, image, every, format };
    let count = slam_viz::write_overlays(out, &opts, &out_dir.join("overlays"))?;
    written.push_str(&format!(", {count} overlays in overlays/"));
    Ok(written)
}

#[derive(Args, Debug)]
pub struct MapArgs {
    /// A map file written by `slam-app run` (map.json)
    map: PathBuf,
    /// Export the map points as a PLY point cloud
    #[arg(long)]
    ply: Option<PathBuf>,
    /// Export the 3-D scene as a PLY mesh (MeshLab, Blender, CloudCompare): ellipsoids coloured by state,
    /// keyframe camera frusta, the trajectory as a tube-free polyline of edges, and the map points
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Export the per-frame trajectory (KITTI format)
    #[arg(long)]
    trajectory: Option<PathBuf>,
    /// Draw the top-down map (SVG + PNG) into this folder
    #[arg(long)]
    picture: Option<PathBuf>,
}

pub fn map(a: &MapArgs) -> anyhow::Result<()> {
    let map = Map::load(&a.map)?;
    let s = map.stats();
    println!("{} (format {} v{})", a.map.display(), map.format, map.version);
    println!(
        "frames {}, keyframes {} in {} segment(s), keyframe path {:.1} m, points {}, observations {} ({:.1} per point), objects {} ({} dynamic)",
        s.frames,
        s.keyframes,
        s.segments,
        s.keyframe_path_m,
        s.points,
        s.observations,
        s.observations as f64 / s.points.max(1) as f64,
        s.objects,
        s.dynamic_objects
    );
    for o in &map.objects {
        println!(
            "object {:>3} class {:>2} {:<10} centre [{:7.2} {:6.2} {:7.2}] m, semi-axes [{:.2} {:.2} {:.2}] m, frames {:>3}{}",
            o.id,
            o.class,
            slam_core::ClassId(o.class).name(),
            o.center[0],
            o.center[1],
            o.center[2],
            o.semi_axes[0],
            o.semi_axes[1],
            o.semi_axes[2],
            o.frames.len(),
            match slam_viz::ObjectState::of(o.dynamic, o.moving) {
                slam_viz::ObjectState::Static => "",
                slam_viz::ObjectState::Dynamic => " dynamic",
                slam_viz::ObjectState::Moving => " moving (not mapped)",
            }
        );
    }
    let parent_of = |p: &std::path::Path| -> anyhow::Result<()> {
        if let Some(d) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
        }
        Ok(())
    };
    if let Some(p) = &a.ply {
        parent_of(p)?;
        map.export_ply(p)?;
        println!("wrote {}", p.display());
    }
    if let Some(p) = &a.scene {
        parent_of(p)?;
        let s = map.export_scene_ply(p)?;
        println!(
            "wrote {}: {} ellipsoids, {} camera frusta, {} trajectory vertices, {} points ({} vertices, {} faces, {} edges)",
            p.display(),
            s.ellipsoids,
            s.cameras,
            s.trajectory,
            s.points,
            s.vertices,
            s.faces,
            s.edges
        );
    }
    let poses: Vec<nalgebra::Isometry3<f64>> = map.frame_poses().into_iter().flatten().collect();
    if let Some(p) = &a.trajectory {
        parent_of(p)?;
        if poses.len() != map.trajectory.len() {
            bail!("{}: {} frames refer to missing keyframes", a.map.display(), map.trajectory.len() - poses.len());
        }
        write_kitti_poses(p, &poses)?;
        println!("wrote {}", p.display());
    }
    if let Some(dir) = &a.picture {
        // each picture is written whole (beside its final name, then renamed): the folder may hold other files
        for f in crate::output::write_files_into(dir, |tmp| {
            slam_viz::map_picture(&map, &poses, None, tmp).map(|_| ()).map_err(anyhow::Error::from)
        })? {
            println!("wrote {}", f.display());
        }
    }
    Ok(())
}

#[derive(Args, Debug)]
pub struct TrajEvalArgs {
    /// Estimated poses, camera to world: KITTI (12 numbers per line, 3×4 row-major) or TUM
    /// (`time tx ty tz qx qy qz qw`)
    estimate: PathBuf,
    /// Ground-truth poses, same formats. Two TUM files are matched by timestamp (nearest within
    /// --max-diff, as evo does); otherwise pose i of one file is pose i of the other
    ground_truth: PathBuf,
    /// Largest time difference of a TUM match, seconds
    #[arg(long, default_value_t = 0.01)]
    max_diff: f64,
}

/// `slam-app trajectory-eval`: ATE, drift and RPE of any trajectory file against ground truth.
pub fn trajectory_eval(a: &TrajEvalArgs) -> anyhow::Result<()> {
    let est = PoseFile::read(&a.estimate)?;
    let gt = PoseFile::read(&a.ground_truth)?;
    let c = slam_eval::trajectory::compare(&est, &gt, a.max_diff, &[10.0, 20.0, 40.0, 100.0, 200.0, 400.0, 800.0]);
    println!(
        "matched {} of {} estimated poses to the {} ground-truth poses {}",
        c.pairs.len(),
        est.poses().len(),
        gt.poses().len(),
        c.how
    );
    let e = c.errors.with_context(|| format!("fewer than two matched poses ({} matched)", c.pairs.len()))?;
    println!("| metric | value |\n|---|---:|");
    println!("| poses compared | {} |\n| path (ground truth) | {:.1} m |", e.frames, e.path_m);
    println!("| ATE (first poses aligned) | {:.3} m |\n| ATE (rigid alignment) | {:.3} m |", e.ate_m, e.ate_aligned_m);
    println!("| end-point drift | {:.2} % |\n| scale (similarity fit) | {:.4} |", e.end_drift_pct, e.scale);
    for (len, t, r, count) in e.rpe {
        println!("| RPE {len:.0} m ({count} segments) | {t:.2} % / {r:.2} deg/100 m |");
    }
    Ok(())
}

/// Arguments of `slam-app stereo-check`.
#[derive(clap::Args, Debug)]
pub struct StereoCheckArgs {
    /// KITTI stereo sequence folder (odometry, raw or tracking layout); default: the shipped sequence.
    pub path: Option<PathBuf>,
    /// Frames tracked to collect frame pairs.
    #[arg(long, default_value_t = 51)]
    pub frames: usize,
    /// Largest residual offset scanned either side of zero, pixels.
    #[arg(long, default_value_t = 0.6)]
    pub range: f64,
    /// Scan step, pixels.
    #[arg(long, default_value_t = 0.05)]
    pub step: f64,
    /// Most rounds of (track with the offset found so far, estimate the residual).
    #[arg(long, default_value_t = 4)]
    pub rounds: usize,
    /// Print the cost curve of the last round.
    #[arg(long)]
    pub curve: bool,
    /// Settings file (its `[tracking]` table is used; its `disparity_offset` is the starting point).
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// `slam-app stereo-check`: estimate the rig's disparity offset from the sequence itself
/// (`slam_frontend::disparity`). The scan's response to an offset is below one on real images (about
/// 0.7 on KITTI 06, docs/system.md), so the offset is found by rounds: track with the offset found so
/// far, estimate the residual, add it, until the residual is below 0.02 px.
pub fn stereo_check(a: &StereoCheckArgs) -> anyhow::Result<()> {
    if a.frames < 2 {
        bail!("--frames must be at least 2 (got {})", a.frames);
    }
    use crate::validate::{count, number, Range};
    // a rectification error of more than 10 px is a wrong calibration, not an offset to estimate
    number("--range", a.range, Range::above(0.0, 10.0), "px")?;
    number(
        "--step",
        a.step,
        Range::above(a.range / 10_000.0, a.range),
        "px (at most --range, at least --range / 10000)",
    )?;
    count("--rounds", a.rounds, 1, 100)?;
    let cfg = match &a.config {
        Some(p) => RunConfig::read(p)?,
        None => RunConfig::default(),
    };
    let path = a.path.clone().unwrap_or_else(|| crate::fixture("kitti_odom_06/sequences/06"));
    let seq = open_stereo(&path)?;
    let (l0, r0) = crate::validate::first_pair(&seq.left, &seq.right)?;
    let size = crate::validate::stereo_pair(l0, r0)?;
    crate::validate::calibration(&calibration_file(&seq), seq.intrinsics, seq.baseline, l0, size)?;
    let [fx, fy, cx, cy] = seq.intrinsics;
    let rig = StereoRig { k: Intrinsics::new(fx, fy, cx, cy), baseline: seq.baseline };
    let colour = seq.layout != Layout::Odometry;
    let n = a.frames.min(seq.len());
    for w in &seq.warnings {
        tracing::warn!("{w}");
    }
    // images are read again in every round rather than held: a whole sequence would not fit
    let read =
        |i: usize| read_image(&seq.left[i], colour).and_then(|l| read_image(&seq.right[i], colour).map(|r| (l, r)));
    let readable: Vec<usize> = (0..n)
        .filter(|&i| match read(i) {
            Ok(_) => true,
            Err(e) => {
                tracing::warn!(frame = seq.ids[i], "skipped: {e}");
                false
            }
        })
        .collect();
    println!(
        "{}: {n} frames ({} unreadable), fx {fx:.1} px, baseline {:.4} m",
        seq.dir.display(),
        n - readable.len(),
        seq.baseline
    );
    println!("| round | offset applied (px) | frame pairs | correspondences | residual estimate (px) |");
    println!("|---:|---:|---:|---:|---:|");
    let mut applied = cfg.tracking.disparity_offset;
    let mut last = None;
    for round in 1..=a.rounds {
        let mut tracking = cfg.tracking;
        tracking.keep_disparity_pairs = usize::MAX;
        tracking.disparity_offset = applied;
        // far points carry most of what the disparities say about an offset: the calibration tracks
        // with their disparity at full weight (tracking.far_baselines off)
        tracking.far_baselines = f64::INFINITY;
        let optimizer = crate::optimizer_choice::OptimizerKind::default().build();
        let mut vo = StereoVo::new(rig, tracking, optimizer.clone())?;
        for &i in &readable {
            let (l, r) = read(i).with_context(|| format!("frame {i} became unreadable"))?;
            vo.process(seq.ids[i], &l, &r, &[])?;
        }
        let pairs = vo.disparity_pairs();
        let Some(e) =
            slam_frontend::disparity::estimate_disparity_offset(&rig, pairs, (-a.range, a.range), a.step, &*optimizer)
        else {
            bail!("no tracked frame pairs in {n} frames of {}", seq.dir.display());
        };
        println!("| {round} | {applied:+.3} | {} | {} | {:+.3} |", e.pairs, e.points, e.offset);
        let done = e.offset.abs() < 0.02 || !e.interior;
        applied += e.offset;
        last = Some(e);
        if done {
            break;
        }
    }
    let Some(e) = last else { bail!("no rounds ran") };
    if a.curve {
        let min = e.curve.iter().map(|c| c.1).fold(f64::INFINITY, f64::min);
        println!("\n| residual offset (px) | robust cost − least |\n|---:|---:|");
        for (o, c) in &e.curve {
            println!("| {o:+.3} | {:.2} |", c - min);
        }
    }
    if !e.interior {
        println!("(the last residual lay at the end of the scanned range: widen --range)");
    }
    println!(
        "estimated rig disparity offset: {applied:+.3} px (tracking.disparity_offset); without it, depths at 20 m err by {:+.2} %",
        100.0 * applied / (fx * seq.baseline / 20.0)
    );
    Ok(())
}

#[derive(Args, Debug)]
pub struct TrackBenchArgs {
    /// Another KITTI stereo sequence as a case, PATH or PATH:STRIDE (repeatable): e.g. a held-out drive
    #[arg(long = "case")]
    cases: Vec<String>,
    /// Only the --case sequences, not the shipped dev cases
    #[arg(long)]
    only_cases: bool,
    /// Settings file used for every case (TOML, as for `run --config`)
    #[arg(long)]
    config: Option<PathBuf>,
}

/// One row of `track-bench`.
struct BenchCase {
    name: String,
    path: PathBuf,
    stride: u64,
}

fn parse_case(text: &str) -> anyhow::Result<BenchCase> {
    let (path, stride) = match text.rsplit_once(':') {
        Some((p, s)) if !p.is_empty() && s.chars().all(|c| c.is_ascii_digit()) && !s.is_empty() => {
            let stride: u64 = s.parse().with_context(|| format!("--case {text}: stride '{s}'"))?;
            if stride == 0 {
                bail!("--case {text}: the stride must be at least 1");
            }
            (p, stride)
        }
        _ => (text, 1),
    };
    Ok(BenchCase { name: format!("{path}, stride {stride}"), path: PathBuf::from(path), stride })
}

/// `slam-app track-bench`: the tracking dev table of issue 14 in one command, every case with
/// `--detector none`. Accuracy figures are deterministic; frames/s depends on the machine's load.
pub fn track_bench(b: &TrackBenchArgs) -> anyhow::Result<()> {
    #[derive(clap::Parser)]
    struct Wrap {
        #[command(flatten)]
        run: RunArgs,
    }
    use clap::Parser;
    let mut cases = Vec::new();
    if !b.only_cases {
        let odo = crate::fixture("kitti_odom_06/sequences/06");
        for stride in 1..=4 {
            cases.push(BenchCase {
                name: format!("odometry 06, frames 0-50, stride {stride}"),
                path: odo.clone(),
                stride,
            });
        }
        let raw = crate::fixture("kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync");
        cases.push(BenchCase { name: "raw drive 0005, frames 0-90 (vs OXTS)".into(), path: raw, stride: 1 });
    }
    for c in &b.cases {
        cases.push(parse_case(c)?);
    }
    if cases.is_empty() {
        bail!("no cases: --only-cases needs at least one --case PATH[:STRIDE]");
    }
    println!(
        "| case | frames | ATE m | ATE aligned m | end drift % | largest step error m (frame), tracked frames | {} | median frames/s |",
        STATE_NAMES.join(" | ")
    );
    println!("|---|---:|---:|---:|---:|---:|{}---:|", "---:|".repeat(STATE_NAMES.len()));
    let mut notes = Vec::new();
    for c in &cases {
        let path = c.path.to_string_lossy().to_string();
        let stride = c.stride.to_string();
        let mut argv = vec!["run", path.as_str(), "--detector", "none", "--stride", stride.as_str()];
        let config = b.config.as_ref().map(|p| p.to_string_lossy().to_string());
        if let Some(cfg) = &config {
            argv.extend(["--config", cfg.as_str()]);
        }
        let a = Wrap::try_parse_from(argv)?.run;
        let cfg = settings(&a)?;
        let o = run_system(&a, &cfg, true).with_context(|| format!("case {}", c.name))?;
        let (out, seq) = (&o.out, &o.seq);
        let truth = seq.truth_from_first();
        let errors = truth.as_ref().and_then(|g| trajectory_errors(&out.poses, g, &[]));
        // only frames the tracker marked "tracked" (not initialised, lost, relocalised or any weaker state)
        let tracked: Vec<bool> =
            out.frames.iter().map(|f| matches!(f.state, Some(slam_core::TrackState::Tracked { .. }))).collect();
        let step = truth.as_ref().and_then(|g| slam_pipeline::eval::largest_step_error(&out.poses, g, &tracked));
        let cell = |v: Option<f64>, digits: usize| v.map_or("–".to_string(), |v| format!("{v:.digits$}"));
        let states: Vec<String> = state_counts(&out.frames).iter().map(|n| n.to_string()).collect();
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {:.1} |",
            c.name,
            out.frames.len(),
            cell(errors.as_ref().map(|e| e.ate_m), 3),
            cell(errors.as_ref().map(|e| e.ate_aligned_m), 3),
            cell(errors.as_ref().map(|e| e.end_drift_pct), 2),
            step.map_or("–".to_string(), |(e, k)| format!("{e:.3} ({})", seq.ids[k])),
            states.join(" | "),
            median_fps(out)
        );
        if let Some(TruthSource::Oxts { median_pos_accuracy_m }) = seq.truth_source {
            notes.push(format!(
                "{}: ground truth from OXTS (differential GPS + IMU), median pos_accuracy {median_pos_accuracy_m:.2} m: errors below that are not meaningful.",
                c.name
            ));
        }
        if truth.is_none() {
            notes.push(format!("{}: no ground truth, errors not computed.", c.name));
        }
    }
    println!(
        "\nATE: RMS position error, both trajectories starting at the identity (\"aligned\": after the best rigid alignment). Step error: |t(est step) - t(true step)| over steps ending at a frame marked tracked; the frame id in brackets. State columns: frames per state as tracking.csv names them (each frame in exactly one). Frames/s: 1000 / median interval between frames (machine load matters; accuracy figures are deterministic)."
    );
    for n in notes {
        println!("{n}");
    }
    Ok(())
}
