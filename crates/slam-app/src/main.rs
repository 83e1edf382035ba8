//! `slam-app`: the command-line front of the quadric-SLAM workspace.

// Every module prints through these two, which shadow the standard macros of the same name (they
// are defined before the modules, so the modules see them): a reader that closed the pipe early
// (`slam-app … | head`) ends the program quietly with status 0, as Unix tools do, told apart from
// other write errors by `std::io::ErrorKind::BrokenPipe`.
macro_rules! println {
    () => {
        slam_runner::console::stdout::write(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        slam_runner::console::stdout::write(format_args!("{}\n", format_args!($($arg)*)))
    };
}
macro_rules! print {
    ($($arg:tt)*) => {
        slam_runner::console::stdout::write(format_args!($($arg)*))
    };
}

mod args;
mod assoc_cmd;
mod detect_cmd;
mod objects_cmd;
mod optim_cmd;
mod recording;
mod run_cmd;
mod sim_cmd;

use std::path::PathBuf;

use clap::{Parser, Subcommand};

/// Stereo object SLAM with ellipsoid landmarks: studies and tools.
#[derive(Parser, Debug)]
#[command(name = "slam-app", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run the whole system (stereo tracking, local mapping, detection, objects) on a KITTI stereo
    /// sequence (default: the shipped odometry sequence 06, frames 0–50); writes the trajectory, the map,
    /// the object map and pictures; prints ATE/RPE when ground truth exists.
    Run(Box<run_cmd::RunArgs>),
    /// Speed of the whole system on the shipped sequence: frames/s and per-stage medians without
    /// objects, with detections from a file, and with the shipped detector.
    RunBench(run_cmd::RunBenchArgs),
    /// Tracking accuracy on every dev case in one table (odometry 06 at strides 1-4, odometry 01 (the
    /// highway on-ramp), raw drive 0005 against OXTS at strides 1, 4 and 8, odometry 06 driven there and
    /// back (5 legs) and with frame 20 shown 2, 30 and 200 more times, and any --case PATH[:STRIDE]),
    /// without objects (with --objects: the full system): aligned ATE, path error, drift, largest step
    /// error of tracked frames, frames per tracking state, keyframes, map points, local BA median, raw
    /// ATE, median frames/s. Then the saved-map cases (a map of odometry 06 frames 0-50 saved, then
    /// `run --map` on frames 20-50, on 06 driven back, and localising only on 01): frames placed, error
    /// in the map's frame, keyframes and objects added, the file's size, its load time and the time to
    /// place a frame.
    TrackBench(run_cmd::TrackBenchArgs),
    /// The object map on every dev case in one table: raw drive 0005 (the shipped detector, our poses)
    /// scored against its KITTI labels at strides 1, 2 and 3 (census, tracks per labelled object, the
    /// parked van's errors), the image-free study's summary (17 tracking sequences, label boxes), and
    /// the main job's cars against the street they stand on.
    ObjectsBench(objects_cmd::ObjectsBenchArgs),
    /// ATE, drift and RPE of a trajectory file (KITTI or TUM) against ground truth.
    TrajectoryEval(run_cmd::TrajEvalArgs),
    /// Estimate the stereo rig's disparity offset (a rectification error that scales depth) from the
    /// sequence itself: tracks the frames, then scans offsets for the least two-view adjustment cost.
    StereoCheck(slam_runner::stereo::StereoCheckArgs),
    /// Compare the tracker's stereo depth with the Velodyne scans of a KITTI raw drive (default: the
    /// shipped drive 0005, scans of frames 0-4): our disparity minus the lidar's by depth and ORB pyramid
    /// level, at keypoints where the scan shows a plane.
    DepthCheck(run_cmd::DepthCheckArgs),
    /// List a ROS 2 bag's topics (types, message counts, rates, image encodings, camera infos) and say
    /// which stereo pair `run BAG` would read and why (--left/--right/--calib as for run).
    Inspect(run_cmd::InspectArgs),
    /// Inspect a saved map (counts, objects) and export it (PLY points, a 3-D scene, trajectory, top-down picture).
    Map(run_cmd::MapArgs),
    /// Compare object associators (ODA vs IoU-only): ID switches on simulated crossings and on real
    /// KITTI tracking annotations.
    #[command(subcommand)]
    Assoc(assoc_cmd::AssocCommand),
    /// Benchmark the optimiser on real BA and pose-graph problems against Ceres / GTSAM anchors.
    OptimBench(optim_cmd::OptimBenchArgs),
    /// The paper's simulation study: Q-SLAM, Conic, Tri, Tri+Yaw (+cc, +refine) under pose and box noise,
    /// on the 18° arc and on a drive-by; tables, CSV and plots.
    Sim(sim_cmd::SimArgs),
    /// Run a detector over a folder of images (or a KITTI sequence) and write the detection JSON
    /// (docs/detections.md) and, on request, overlay images.
    Detect(detect_cmd::DetectArgs),
    /// Recall and precision of the shipped detectors (or one given with the model options) on the
    /// labelled KITTI frames of drives 0052 (camera 2) and 0005 (camera 0, KITTI's moderate labels).
    DetectRecall(detect_cmd::RecallArgs),
    /// Image-free object mapping on a KITTI tracking folder (label_02.txt, poses_orbslam3.txt,
    /// calib.txt): association (track ids not used), DQP initialisation and object optimisation.
    Objects(objects_cmd::ObjectsArgs),
    /// The paper's object metrics (success, IoU2D, e_trans, e_axe) over KITTI tracking sequences.
    Eval(objects_cmd::EvalArgs),
}

/// The shipped stereo sequence (odometry 06, frames 0–50), under `fixtures/`.
pub(crate) const SHIPPED: &str = "kitti_odom_06/sequences/06";

/// The shipped raw drive 0005 (frames 0–90, OXTS, Velodyne scans of frames 0–4), under `fixtures/`.
pub(crate) const RAW_0005: &str = "kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync";

/// The shipped highway excerpt (odometry 01, frames 0–50), under `fixtures/`.
pub(crate) const HIGHWAY: &str = "kitti_odom_01/sequences/01";

/// A path inside the repository's `fixtures/`: relative to the working directory if it exists there,
/// else relative to this source tree.
pub(crate) fn fixture(rel: &str) -> PathBuf {
    in_repository("fixtures").join(rel)
}

/// The folder where tools/setup.sh records ONNX Runtime's library (`.ort/` at the repository's root).
pub(crate) fn ort_setup() -> PathBuf {
    in_repository(".ort")
}

/// A folder at the repository's root: relative to the working directory if it exists there, else relative
/// to this source tree.
fn in_repository(folder: &str) -> PathBuf {
    let local = PathBuf::from(folder);
    if local.exists() {
        return local;
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..").join(folder)
}

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) if e.downcast_ref::<slam_runner::console::Interrupted>().is_some() => {
            eprintln!("interrupted: {e}");
            std::process::ExitCode::from(130)
        }
        Err(e) => {
            eprintln!("error: {}", slam_runner::console::error_text(e.as_ref()));
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<()> {
    slam_runner::console::init_logs();
    let cli = Cli::parse();
    // Ctrl-C removes this process's temporary files and folders (`run` polls it instead and stops)
    slam_runner::console::handle_interrupts();
    match cli.command {
        Command::Run(a) => run_cmd::run(&a),
        Command::Map(a) => run_cmd::map(&a),
        Command::Inspect(a) => run_cmd::inspect_bag(&a),
        Command::StereoCheck(a) => run_cmd::stereo_check(&a),
        Command::DepthCheck(a) => run_cmd::depth_check(&a),
        Command::TrajectoryEval(a) => run_cmd::trajectory_eval(&a),
        Command::RunBench(a) => run_cmd::run_bench(&a),
        Command::TrackBench(a) => run_cmd::track_bench(&a),
        Command::ObjectsBench(a) => objects_cmd::objects_bench(&a),
        Command::Assoc(cmd) => assoc_cmd::run(cmd),
        Command::OptimBench(a) => optim_cmd::run(&a),
        Command::Sim(a) => sim_cmd::run(&a),
        Command::Detect(a) => detect_cmd::detect(&a),
        Command::DetectRecall(a) => detect_cmd::recall(&a),
        Command::Objects(a) => objects_cmd::objects(&a),
        Command::Eval(a) => objects_cmd::eval(&a),
    }
}
