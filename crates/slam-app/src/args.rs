//! Option groups shared by the commands (`#[command(flatten)]`): the sequence and its frames, the
//! detection source, the settings file and its overrides, the wiring (optimiser, associator, method) and
//! the output folder. Each group turns itself into the `slam_runner` settings it stands for.

use std::{path::PathBuf, sync::Arc};

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use slam_dataset::kitti::stereo::FrameSelection;
use slam_runner::{DetectorChoice, OverlayChoice};

use crate::{
    config::RunConfig,
    detect_cmd::ModelArgs,
    objects_cmd::Method,
    optimizer_choice::{AssociatorKind, OptimizerKind},
};

/// A KITTI stereo sequence and the frames to play.
#[derive(Args, Debug, Clone)]
pub struct SequenceArgs {
    /// A KITTI stereo sequence: odometry (`sequences/NN` or a root with `sequences/`), raw drive
    /// (`<date>/<drive>_sync`) or tracking (`training/image_02/NNNN`). Default: the shipped odometry
    /// sequence 06, frames 0–50.
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
}

/// A range of frame ids given on the command line (`--frames`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRange(Option<usize>, Option<usize>);

fn parse_frame_range(text: &str) -> Result<FrameRange, String> {
    FrameSelection::parse_range(text).map(|(a, b)| FrameRange(a, b))
}

impl SequenceArgs {
    /// The frame selection of --frames and --stride.
    pub fn selection(&self) -> FrameSelection {
        let FrameRange(first, end) = self.frames.unwrap_or(FrameRange(None, None));
        FrameSelection { first, end, stride: self.stride as usize }
    }

    /// The sequence folder (default: the shipped odometry excerpt).
    pub fn path(&self) -> PathBuf {
        self.path.clone().unwrap_or_else(|| crate::fixture("kitti_odom_06/sequences/06"))
    }
}

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
    /// on any layout (3-D boxes projected into the grey camera 0)
    #[arg(long)]
    pub labels: Option<PathBuf>,
    #[command(flatten)]
    pub model: ModelArgs,
}

impl DetectorArgs {
    /// The detection source: `--detector` when given, else the one the mode-specific options select
    /// (`--detections`: file, `--label-noise`: labels), else the shipped network. An option of another
    /// mode than the one chosen is an error that names both.
    pub fn kind(&self) -> anyhow::Result<DetectorKind> {
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

    /// The library's detector choice (the network is loaded when the run starts).
    pub fn choice(&self) -> anyhow::Result<DetectorChoice> {
        Ok(match self.kind()? {
            DetectorKind::None => DetectorChoice::None,
            DetectorKind::Dnn => network(&self.model),
            DetectorKind::File => {
                DetectorChoice::File(self.detections.clone().context("--detector file needs --detections <file.json>")?)
            }
            DetectorKind::Labels => DetectorChoice::Labels { noise: self.label_noise.unwrap_or(0.0) },
        })
    }
}

/// The network of `model`, loaded when a run starts.
pub fn network(model: &ModelArgs) -> DetectorChoice {
    let model = model.clone();
    DetectorChoice::Network(Arc::new(move || {
        model.load().map(|d| Box::new(d) as Box<dyn slam_core::DetectionSource>).map_err(Into::into)
    }))
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
        let mut cfg = read_config(self.config.as_deref())?;
        if let Some(g) = self.keyframe_gap {
            cfg.tracking.keyframe_max_gap = g as usize;
        }
        if self.no_ba {
            cfg.mapping.bundle_adjustment = false;
        }
        if let Some(n) = self.detect_every {
            cfg.system.detect_every = n as usize;
        }
        Ok(cfg)
    }
}

/// The settings file at `path` over the library defaults, or the defaults.
pub fn read_config(path: Option<&std::path::Path>) -> anyhow::Result<RunConfig> {
    path.map_or_else(|| Ok(RunConfig::default()), RunConfig::read)
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

impl Default for WiringArgs {
    fn default() -> Self {
        Self { optimizer: OptimizerKind::Lm, associator: AssociatorKind::Oda, method: Method::Refine }
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

/// The shipped sequence, every frame, the default wiring and no detector, with settings `cfg`.
pub fn shipped_run(cfg: &RunConfig, max_frames: Option<usize>) -> slam_runner::RunSettings {
    let seq = SequenceArgs { path: None, frames: None, stride: 1, max_frames };
    run_settings(&seq, cfg, &WiringArgs::default(), DetectorChoice::None, None)
}

/// The library's run settings from the option groups and the effective settings.
pub fn run_settings(
    seq: &SequenceArgs,
    cfg: &RunConfig,
    wiring: &WiringArgs,
    detector: DetectorChoice,
    labels: Option<PathBuf>,
) -> slam_runner::RunSettings {
    let (optimizer, associator) = (wiring.optimizer, wiring.associator);
    slam_runner::RunSettings {
        path: seq.path(),
        selection: seq.selection(),
        max_frames: seq.max_frames,
        tracking: cfg.tracking,
        system: cfg.system(cfg.objects.image),
        optimizer: Arc::new(move || optimizer.build()),
        associator: Arc::new(move |gate| associator.build(gate)),
        method: wiring.method.fit(),
        names: (associator.name().to_string(), wiring.method.fit().name().to_string()),
        detector,
        labels,
    }
}
