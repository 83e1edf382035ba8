//! Option groups shared by the commands (`#[command(flatten)]`): the sequence and its frames, the
//! detection source, the settings file and its overrides, the wiring (optimiser, associator, method) and
//! the output folder. Each group turns itself into the `slam_runner` settings it stands for.

use std::path::PathBuf;

use clap::Args;
use slam_dataset::kitti::stereo::FrameSelection;
use slam_runner::{
    AssociatorKind, DetectorChoice, DetectorKind, DetectorOptions, Method, OptimizerKind, OverlayChoice, RunConfig,
    Wiring,
};

use crate::detect_cmd::ModelArgs;

/// A KITTI stereo sequence and the frames to play.
#[derive(Args, Debug, Clone)]
pub struct SequenceArgs {
    /// A KITTI stereo sequence: odometry (`sequences/NN` or a root with `sequences/`), raw drive
    /// (`<date>/<drive>_sync`) or tracking (`training/image_02/NNNN`); a ROS 2 bag (an .mcap file or a
    /// rosbag2 folder with metadata.yaml); or a folder with left/ and right/ images (with --calib).
    /// Default: the shipped odometry sequence 06, frames 0–50.
    pub path: Option<PathBuf>,
    /// Frame ids to play (the numbers in the image file names): A..B (A to B-1), A..=B, A.. or ..B.
    /// Ground truth, labels and detections follow the ids, so they stay aligned.
    #[arg(long, value_parser = parse_frame_range)]
    pub frames: Option<FrameRange>,
    /// Play every N-th frame id from the first selected one (N = 3 at 10 Hz looks like driving 3x as fast)
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub stride: u64,
    /// Process at most this many frames (after --frames and --stride)
    #[arg(long)]
    pub max_frames: Option<usize>,
    #[command(flatten)]
    pub source: slam_runner::SourceArgs,
}

/// A range of frame ids given on the command line (`--frames`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRange(Option<usize>, Option<usize>);

/// Parse `--frames`.
pub fn parse_frame_range(text: &str) -> Result<FrameRange, String> {
    FrameSelection::parse_range(text).map(|(a, b)| FrameRange(a, b))
}

impl FrameRange {
    /// The selection of an optional range and a stride.
    pub fn selection(range: Option<FrameRange>, stride: u64) -> FrameSelection {
        let FrameRange(first, end) = range.unwrap_or(FrameRange(None, None));
        FrameSelection { first, end, stride: stride as usize }
    }
}

impl SequenceArgs {
    /// The frame selection of --frames and --stride.
    pub fn selection(&self) -> FrameSelection {
        FrameRange::selection(self.frames, self.stride)
    }

    /// The sequence folder (default: the shipped odometry excerpt).
    pub fn path(&self) -> PathBuf {
        self.path.clone().unwrap_or_else(|| crate::fixture(crate::SHIPPED))
    }
}

/// The detection source and the labels a run is scored against.
#[derive(Args, Debug, Clone)]
pub struct DetectorArgs {
    /// Detection source (default: dnn; `file` when --detections is given, `labels` when --label-noise is)
    #[arg(long, value_enum)]
    pub detector: Option<DetectorKind>,
    /// Detection JSON (selects --detector file)
    #[arg(long)]
    pub detections: Option<PathBuf>,
    /// Box noise, fraction of box size (selects --detector labels; default 0)
    #[arg(long)]
    pub label_noise: Option<f64>,
    /// KITTI tracking labels of this sequence (label_02.txt format): the run's objects are scored
    /// against them (printed, and objects_score.json), and `--detector labels` takes its boxes from them
    /// on any layout (3-D boxes projected into the grey camera 0; with a colour pair, the labels' own 2-D
    /// boxes)
    #[arg(long)]
    pub labels: Option<PathBuf>,
    #[command(flatten)]
    pub model: ModelArgs,
}

impl DetectorArgs {
    /// The detection options as the library takes them.
    pub fn options(&self) -> DetectorOptions {
        DetectorOptions {
            kind: self.detector,
            detections: self.detections.clone(),
            label_noise: self.label_noise,
            model_option: self.model.given(),
        }
    }

    /// The library's detector choice (the network is loaded when the run starts).
    pub fn choice(&self) -> anyhow::Result<DetectorChoice> {
        Ok(self.options().choice(self.model.loader())?)
    }
}

/// The settings file and the options that override its keys.
#[derive(Args, Debug, Clone)]
pub struct SettingsArgs {
    /// Settings file (TOML; see --print-config for every key and its default)
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print the effective settings (library defaults, overlaid by --config and the options) as commented
    /// TOML and exit
    #[arg(long)]
    pub print_config: bool,
    /// Take a new keyframe after at most this many frames (overrides tracking.keyframe_max_gap)
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub keyframe_gap: Option<u64>,
    /// Turn local bundle adjustment off (overrides mapping.bundle_adjustment)
    #[arg(long)]
    pub no_ba: bool,
    /// Run the detector on every n-th frame only (overrides system.detect_every)
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub detect_every: Option<u64>,
}

impl SettingsArgs {
    /// The library defaults, overlaid by --config and the overriding options.
    pub fn load(&self) -> anyhow::Result<RunConfig> {
        let (gap, every) = (self.keyframe_gap.map(|g| g as usize), self.detect_every.map(|n| n as usize));
        Ok(RunConfig::load(self.config.as_deref())?.with_overrides(gap, self.no_ba, every))
    }
}

/// Which implementations behind the seams a run wires together.
#[derive(Args, Debug, Clone)]
pub struct WiringArgs {
    /// Optimiser backend for the tracker's two-frame BA, local BA and object fits.
    #[arg(long, value_enum, default_value_t = OptimizerKind::Lm)]
    pub optimizer: OptimizerKind,
    /// Object associator (the paper's ODA, or the IoU baseline)
    #[arg(long, value_enum, default_value_t = AssociatorKind::Oda)]
    pub associator: AssociatorKind,
    /// Ellipsoid method of the objects (baselines for comparison)
    #[arg(long, value_enum, default_value_t = Method::Refine)]
    pub method: Method,
}

impl WiringArgs {
    /// The implementations chosen.
    pub fn wiring(&self) -> Wiring {
        Wiring { optimizer: self.optimizer, associator: self.associator, method: self.method }
    }
}

/// The output folder and the pictures written into it.
#[derive(Args, Debug, Clone)]
pub struct OutputArgs {
    /// Output folder
    #[arg(long, default_value = "out/run")]
    pub out: PathBuf,
    /// Write overlay images (detections, projected ellipsoids with ids, trails) into <out>/overlays
    #[arg(long)]
    pub overlays: bool,
    /// Overlay every n-th frame (implies --overlays; default 1)
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub overlay_every: Option<u64>,
    /// Overlay image format: png (default), or jpg for files about ten times smaller (implies --overlays)
    #[arg(long, value_parser = ["png", "jpg"])]
    pub overlay_format: Option<String>,
    /// Also write the run as an MCAP file for ROS tools (Foxglove): /tf of the camera, the trajectory
    /// (nav_msgs/Path), the objects (visualization_msgs/MarkerArray: ellipsoids with class and id) and
    /// the map points (sensor_msgs/PointCloud2), on the input's own time line (a bag's stamps)
    #[arg(long, value_name = "FILE.mcap")]
    pub mcap: Option<PathBuf>,
}

impl OutputArgs {
    /// The overlays asked for, if any.
    pub fn overlays(&self) -> Option<OverlayChoice> {
        (self.overlays || self.overlay_every.is_some() || self.overlay_format.is_some()).then(|| OverlayChoice {
            every: self.overlay_every.unwrap_or(1),
            format: self.overlay_format.clone().unwrap_or_else(|| "png".into()),
        })
    }
}

impl SequenceArgs {
    /// The library's run settings of this sequence with the effective settings and the other groups.
    pub fn run_settings(
        &self,
        cfg: &RunConfig,
        wiring: &WiringArgs,
        detector: DetectorChoice,
        labels: Option<PathBuf>,
    ) -> slam_runner::RunSettings {
        let mut s = slam_runner::RunSettings::new(
            self.path(),
            self.selection(),
            self.max_frames,
            cfg,
            wiring.wiring(),
            detector,
            labels,
        );
        s.source = self.source.options();
        s
    }
}
