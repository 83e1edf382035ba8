//! `slam-app run` and the run-related commands (run-bench, track-bench, trajectory-eval, stereo-check,
//! map): arguments, their conversion into `slam_runner` settings, the calls, and printing.

use std::path::{Path, PathBuf};

use clap::Args;
use slam_dataset::output::{refuse_overwriting_inputs, Written};
use slam_pipeline::{saved_map::SavedMap, system::FrameView};
use slam_runner::{
    bench,
    console::{catch_interrupt, interrupted, Interrupted, Progress},
    inspect, stereo, RunConfig, RunObserver, RunSettings,
};

use crate::args::{DetectorArgs, OutputArgs, SequenceArgs, SettingsArgs, WiringArgs};

#[derive(Args, Debug)]
pub struct RunArgs {
    #[command(flatten)]
    seq: SequenceArgs,
    #[command(flatten)]
    output: OutputArgs,
    /// Write a rerun recording of the run to this file as it goes (the `frame` timeline: images with
    /// boxes and projected ellipsoids, camera, trajectories, map points, ellipsoids, tracking state);
    /// needs slam-app built with the feature `rerun`. Open it with `rerun FILE.rrd`
    #[arg(long, value_name = "FILE.rrd")]
    rerun: Option<PathBuf>,
    /// Start from the map of an earlier run (its map.json, with map.features beside it): localise in
    /// it by keyframe retrieval, then track against it; frames not yet placed in it are `lost` and get
    /// no pose. A run that starts off the mapped road tracks on its own after 0.5 s and joins the map
    /// where it reaches it (those frames then get their poses too). What this run adds extends it
    /// (the new map.json holds both), poses are in its frame, and its objects keep their ids. The
    /// camera must be the one it was made with
    #[arg(long, value_name = "MAP.json")]
    map: Option<PathBuf>,
    /// With --map: localise only, add nothing to the map (no keyframes, points or objects). A map made
    /// with another calibration of the rig is accepted then, its keyframes re-expressed in this camera
    #[arg(long, requires = "map")]
    localise_only: bool,
    #[command(flatten)]
    settings: SettingsArgs,
    #[command(flatten)]
    wiring: WiringArgs,
    #[command(flatten)]
    detector: DetectorArgs,
}

impl RunArgs {
    /// The effective settings, after the range checks of the options.
    fn settings(&self) -> anyhow::Result<RunConfig> {
        if let Some(n) = self.seq.max_frames {
            slam_core::check::count("--max-frames", n, 1, usize::MAX)?;
        }
        self.detector.options().checked(self.localise_only)?;
        self.detector.model.check()?;
        self.settings.load()
    }
}

/// A finished run and, when one was asked for, its recording (finished with the run).
type Played = (slam_runner::Outcome, Option<Box<dyn RunObserver>>);

/// Run the system with a progress bar, after printing the run's header; with `rerun`, recorded there.
fn run_with_progress(s: &RunSettings, rerun: Option<&Path>) -> anyhow::Result<Played> {
    let prepared = slam_runner::prepare(s)?;
    println!("{}", prepared.header(s));
    let mut recording = rerun.map(|path| crate::recording::recorder(path, &prepared)).transpose()?;
    let mut bar = Progress::new("run", prepared.len() as u64, "frames", false);
    let (mut keyframes, mut lost) = (0usize, 0usize);
    let mut on_frame = |v: &FrameView<'_>| {
        let r = v.record;
        keyframes += usize::from(r.keyframe);
        lost += usize::from(r.state == Some(slam_core::TrackState::Lost));
        bar.set_message(format!("{keyframes} keyframes, {lost} frames lost"));
        bar.inc();
        if let Some(rec) = &mut recording {
            rec.frame(v);
        }
    };
    let outcome = prepared.run(s, &mut on_frame, interrupted)?;
    bar.finish();
    Ok((outcome, recording))
}

pub fn run(a: &RunArgs) -> anyhow::Result<()> {
    let cfg = a.settings()?;
    if a.settings.print_config {
        print!("{}", cfg.to_commented_toml());
        return Ok(());
    }
    let out = &a.output.out;
    crate::recording::check(a.rerun.as_deref(), Some(out))?;
    // the output folder is written beside the old one and swapped in at the end; checked writable now
    catch_interrupt();
    // nothing a run reads may lie in the folder it replaces, nor be its recording
    let seq = a.seq.path();
    let mut inputs = vec![("the sequence", seq.as_path())];
    inputs.extend(a.settings.config.as_deref().map(|p| ("--config", p)));
    inputs.extend(a.map.as_deref().map(|p| ("--map", p)));
    inputs.extend(a.detector.detections.as_deref().map(|p| ("--detections", p)));
    inputs.extend(a.detector.labels.as_deref().map(|p| ("--labels", p)));
    inputs.extend(a.detector.model.files());
    inputs.extend(a.seq.source.files());
    let mut outputs = vec![Written::Folder("--out", out)];
    outputs.extend(a.rerun.as_deref().map(|p| Written::File("--rerun", p)));
    outputs.extend(a.output.mcap.as_deref().map(|p| Written::File("--mcap", p)));
    refuse_overwriting_inputs(&inputs, &outputs)?;
    let dir = slam_dataset::output::OutputDir::create(out, "--out", "run")?;
    let mut s = a.seq.run_settings(&cfg, &a.wiring, a.detector.choice()?, a.detector.labels.clone());
    (s.map, s.localise_only) = (a.map.clone(), a.localise_only);
    let played = run_with_progress(&s, a.rerun.as_deref());
    let stop = |done: usize| Interrupted::nothing_written(done, out, dir.target().exists());
    if interrupted() {
        // a recording stops with the run, unfinished: its temporary file is removed and a previous recording stays
        return Err(stop(played.as_ref().map_or(0, |o| o.0.out.counts.frames)).into());
    }
    let (o, recording) = played?;
    let recorded = recording.map(|r| r.finish(&o)).transpose()?;
    let last = o.write_all(dir.path(), out, cfg.system.max_detections, a.output.overlays().as_ref(), &mut |t| {
        println!("{t}")
    })?;
    if interrupted() {
        return Err(stop(o.out.counts.frames).into());
    }
    dir.commit()?;
    println!("{last}");
    if let Some(line) = recorded {
        println!("{line}");
    }
    if let Some(path) = &a.output.mcap {
        println!("{}", slam_runner::ros_output::write_results_mcap(&o, path)?);
    }
    // the output is written, but a run that tracked no frame failed
    o.nothing_tracked().map_or(Ok(()), |e| Err(e.into()))
}

#[derive(Args, Debug)]
pub struct RunBenchArgs {
    /// Runs per configuration (the table shows medians)
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Frames per run (default: the whole shipped sequence)
    #[arg(long)]
    max_frames: Option<usize>,
    /// One more row: the shipped detector's configuration with a rerun recording written to this file
    /// (rewritten by each run), and what recording costs in median frame time; needs the feature `rerun`
    #[arg(long, value_name = "FILE.rrd")]
    rerun: Option<PathBuf>,
}

/// `slam-app run-bench`: the system on the shipped sequence without objects, with detections from the
/// shipped file, and with the shipped detector on every frame; medians over repeated runs.
pub fn run_bench(b: &RunBenchArgs) -> anyhow::Result<()> {
    if let Some(n) = b.max_frames {
        slam_core::check::count("--max-frames", n, 1, usize::MAX)?;
    }
    crate::recording::check(b.rerun.as_deref(), None)?;
    let base = RunSettings::odometry_only(crate::fixture(crate::SHIPPED), &RunConfig::default(), b.max_frames);
    let file = crate::fixture("kitti_odom_06/detections/yolo_fastest_tiles3.json");
    let network = slam_runner::DetectorChoice::Network(crate::detect_cmd::ModelArgs::default().loader());
    let mut record = |p: &slam_runner::Prepared| match &b.rerun {
        Some(path) => crate::recording::recorder(path, p),
        None => Err(slam_runner::RunnerError::Invalid("no --rerun file".into())),
    };
    let record = b.rerun.is_some().then_some(&mut record as &mut slam_runner::ObserverFactory<'_>);
    bench::run_bench(&base, file, network, b.repeat, record, &mut |l| println!("{l}"), &mut |l| eprintln!("{l}"))?;
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
    /// Run the full system on every case: the shipped detector on every frame, objects found moving
    /// masked out of tracking (default: tracking only, no detector)
    #[arg(long)]
    objects: bool,
}

/// `slam-app track-bench`: the tracking dev table of issue 14 in one command, every case with
/// `--detector none`, or with `--objects` the full system with the shipped detector. Accuracy figures
/// are deterministic; frames/s depends on the machine's load.
pub fn track_bench(b: &TrackBenchArgs) -> anyhow::Result<()> {
    let (odometry, highway, raw) =
        (crate::fixture(crate::SHIPPED), crate::fixture(crate::HIGHWAY), crate::fixture(crate::RAW_0005));
    let dev = (!b.only_cases).then(|| bench::TrackCase::dev_cases(odometry.clone(), highway.clone(), raw));
    let mut cases = dev.unwrap_or_default();
    cases.extend(b.cases.iter().map(|c| bench::TrackCase::parse(c)).collect::<Result<Vec<_>, _>>()?);
    let mut base =
        RunSettings::odometry_only(crate::fixture(crate::SHIPPED), &RunConfig::load(b.config.as_deref())?, None);
    if b.objects {
        base.detector = slam_runner::DetectorChoice::Network(crate::detect_cmd::ModelArgs::default().loader());
    }
    bench::track_bench(&base, &cases, b.objects, &mut |l| println!("{l}"))?;
    // the saved-map cases (issue 38) go with the dev cases
    if !b.only_cases {
        slam_runner::map_bench::map_bench(&base, &odometry, &highway, &mut |l| println!("{l}"))?;
    }
    Ok(())
}

#[derive(Args, Debug)]
pub struct TrajEvalArgs {
    /// Estimated poses, camera to world: KITTI (12 numbers per line, 3×4 row-major) or TUM
    /// (`time tx ty tz qx qy qz qw`)
    estimate: PathBuf,
    /// Ground-truth poses, same formats. Two TUM files are matched by timestamp (nearest within
    /// --max-diff, as evo does); a TUM estimate and a KITTI ground truth by time too, the ground truth's
    /// line k being frame k at line k of sequences/NN/times.txt beside poses/NN.txt (else 0.1 s × k);
    /// two KITTI files pose i with pose i
    ground_truth: PathBuf,
    /// Largest time difference of a TUM match, seconds
    #[arg(long, default_value_t = 0.01, value_parser = slam_core::check::non_negative_text)]
    max_diff: f64,
    /// Compare with these ground-truth lines only, line k being frame id k (A..B, A..=B, A.., ..B): for
    /// a run of a subset of frames matched by line, give the run's own --frames (and --stride). Pairs
    /// by line: a run that skipped unreadable frames lines up only by time (TUM files)
    #[arg(long, value_parser = crate::args::parse_frame_range)]
    frames: Option<crate::args::FrameRange>,
    /// ... and every N-th line from the first of --frames (from line 0 without --frames: a run whose
    /// first frame id is not 0 needs its --frames too)
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    stride: u64,
}

/// `slam-app trajectory-eval`: ATE, drift and RPE of any trajectory file against ground truth.
pub fn trajectory_eval(a: &TrajEvalArgs) -> anyhow::Result<()> {
    let selection = crate::args::FrameRange::selection(a.frames, a.stride);
    println!("{}", inspect::trajectory_eval(&a.estimate, &a.ground_truth, a.max_diff, &selection)?);
    Ok(())
}

#[derive(Args, Debug)]
pub struct InspectArgs {
    /// A ROS 2 bag: an .mcap file or a rosbag2 folder (metadata.yaml beside its .mcap files)
    bag: PathBuf,
    #[command(flatten)]
    source: slam_runner::SourceArgs,
}

/// `slam-app inspect`: a bag's topics and the pair a run would read.
pub fn inspect_bag(a: &InspectArgs) -> anyhow::Result<()> {
    println!("{}", slam_runner::ros_output::inspect_bag(&a.bag, &a.source.options())?);
    Ok(())
}

/// `slam-app stereo-check`: estimate the rig's disparity offset from the sequence itself, in rounds
/// (`slam_runner::stereo`).
pub fn stereo_check(a: &stereo::StereoCheckArgs) -> anyhow::Result<()> {
    Ok(a.run(crate::fixture(crate::SHIPPED), &mut |line| println!("{line}"))?)
}

/// Arguments of `slam-app depth-check`.
#[derive(clap::Args, Debug)]
pub struct DepthCheckArgs {
    /// KITTI raw drive folder (…/YYYY_MM_DD_drive_NNNN_sync) with velodyne_points/; default: the shipped
    /// drive 0005
    pub path: Option<PathBuf>,
    /// Settings file (its `[tracking]` table sets the stereo matching, e.g. `disparity_offset`)
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Reference: depths triangulated from the left images of frame pairs 5 m apart with the
    /// ground-truth poses, instead of the Velodyne (any sequence with measured ground truth)
    #[arg(long)]
    pub motion: bool,
    /// With --motion: the first frame id used (e.g. 12 on odometry 06, whose first 12 poses are
    /// interpolated)
    #[arg(long, default_value_t = 0, requires = "motion")]
    pub from: usize,
    /// With --motion: every N-th frame is paired
    #[arg(long, default_value_t = 1, requires = "motion", value_parser = clap::value_parser!(u64).range(1..))]
    pub every: u64,
    /// With --motion: check another front end's stereo keypoints instead of ours, read from this
    /// folder (NNNNNN.csv per frame id; columns u, v, octave, ur, desc as 64 hex digits)
    #[arg(long, requires = "motion")]
    pub keypoints: Option<PathBuf>,
}

/// `slam-app depth-check`: our stereo disparities against the Velodyne's (`slam_runner::depth`).
pub fn depth_check(a: &DepthCheckArgs) -> anyhow::Result<()> {
    let cfg = RunConfig::load(a.config.as_deref())?;
    let path = a.path.clone().unwrap_or_else(|| crate::fixture(crate::RAW_0005));
    let report = if a.motion {
        slam_runner::depth::motion_check(&path, &cfg.tracking, (a.from, a.every as usize), a.keypoints.as_deref())?
    } else {
        slam_runner::depth::depth_check(&path, &cfg.tracking)?
    };
    println!("{}", report.frames_text(a.motion));
    println!("{}", report.tables());
    Ok(())
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
    /// Write the map as a rerun recording (the `frame` timeline: camera poses and states, each keyframe's
    /// points, the ellipsoids from the frame they were first seen; no images); needs slam-app built
    /// with the feature `rerun`
    #[arg(long, value_name = "FILE.rrd")]
    rerun: Option<PathBuf>,
}

/// `slam-app map`: a saved map's counts and objects, and its exports.
pub fn map(a: &MapArgs) -> anyhow::Result<()> {
    crate::recording::check(a.rerun.as_deref(), None)?;
    let exports = inspect::MapExports {
        ply: a.ply.clone(),
        scene: a.scene.clone(),
        trajectory: a.trajectory.clone(),
        picture: a.picture.clone(),
    };
    exports.refuse_overwriting(&a.map, a.rerun.as_deref())?;
    let exports = exports.prepare()?;
    let map = SavedMap::load_without_features(&a.map)?;
    println!("{}", inspect::map_summary(&map, &a.map));
    inspect::export_map(&map, &a.map, exports, &mut |line| println!("{line}"))?;
    if let Some(path) = &a.rerun {
        println!("{}", crate::recording::record_map(&map, path)?);
    }
    Ok(())
}
