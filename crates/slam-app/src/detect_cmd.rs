//! `slam-app detect` and `slam-app detect-recall`.

use std::path::PathBuf;

use clap::Args;
use slam_core::DetectionSource;
use slam_frontend::{DnnDetector, ModeName, ModelError, ModelSpec};

#[derive(Args, Debug, Clone, Default)]
pub struct ModelArgs {
    /// Darknet .cfg (default: the shipped Yolo-Fastest 1.1)
    #[arg(long)]
    cfg: Option<PathBuf>,
    /// Darknet .weights (default: the shipped Yolo-Fastest 1.1)
    #[arg(long)]
    weights: Option<PathBuf>,
    /// ONNX model instead of Darknet
    #[arg(long, conflicts_with_all = ["cfg", "weights"])]
    onnx: Option<PathBuf>,
    /// Input mode (default: tiles)
    #[arg(long, value_enum)]
    mode: Option<ModeName>,
    /// Number of tiles across the width (selects --mode tiles; default 3)
    #[arg(long)]
    tiles: Option<u32>,
    /// Network input size, a multiple of 32 (default 320)
    #[arg(long)]
    input_size: Option<i32>,
    /// Smallest score kept (default 0.2)
    #[arg(long)]
    score: Option<f32>,
}

impl ModelArgs {
    fn spec(&self) -> ModelSpec {
        let ModelArgs { cfg, weights, onnx, mode, tiles, input_size, score } = self.clone();
        ModelSpec { cfg, weights, onnx, mode, tiles, input_size, score }
    }

    /// Range checks of the model options (before any model is loaded).
    pub(crate) fn check(&self) -> anyhow::Result<()> {
        self.spec().check().map_err(model_error)
    }

    /// The model files given, as inputs of a command.
    pub(crate) fn files(&self) -> Vec<(&'static str, &std::path::Path)> {
        [("--cfg", &self.cfg), ("--weights", &self.weights), ("--onnx", &self.onnx)]
            .into_iter()
            .filter_map(|(option, p)| p.as_deref().map(|p| (option, p)))
            .collect()
    }

    /// The first of these options given on the command line (they only make sense with the network).
    pub(crate) fn given(&self) -> Option<&'static str> {
        [
            (self.cfg.is_some(), "--cfg"),
            (self.weights.is_some(), "--weights"),
            (self.onnx.is_some(), "--onnx"),
            (self.mode.is_some(), "--mode"),
            (self.tiles.is_some(), "--tiles"),
            (self.input_size.is_some(), "--input-size"),
            (self.score.is_some(), "--score"),
        ]
        .into_iter()
        .find_map(|(given, flag)| given.then_some(flag))
    }

    pub(crate) fn load(&self) -> anyhow::Result<DnnDetector> {
        self.spec().load(&crate::fixture("detector")).map_err(model_error)
    }
}

impl ModelArgs {
    /// The network as a run loads it when it starts.
    pub(crate) fn loader(&self) -> slam_runner::NetworkLoader {
        let model = self.clone();
        std::sync::Arc::new(move || model.load().map(|d| Box::new(d) as Box<dyn DetectionSource>).map_err(Into::into))
    }
}

/// A model error under the options' names.
fn model_error(e: ModelError) -> anyhow::Error {
    match e {
        ModelError::Invalid(v) => v.as_flag().into(),
        ModelError::TilesWithoutTiling(m) => {
            anyhow::anyhow!("--tiles is an option of --mode tiles, but --mode {m} was given")
        }
        ModelError::Load(e) => e.into(),
    }
}

#[derive(Args, Debug)]
pub struct DetectArgs {
    /// A KITTI stereo sequence in any layout `run` accepts (its left images, numbered as `run` numbers
    /// frames, so the file feeds `run --detections`), or a folder of images (sorted by name)
    input: PathBuf,
    /// Output detection JSON
    #[arg(long, default_value = "out/detections.json")]
    out: PathBuf,
    /// Also write overlay PNGs into this folder
    #[arg(long)]
    overlays: Option<PathBuf>,
    #[command(flatten)]
    model: ModelArgs,
}

pub fn detect(a: &DetectArgs) -> anyhow::Result<()> {
    // both outputs are checked writable before the first image, and put in place whole at the end
    let plan = slam_runner::detect::DetectPlan::new(&a.input, &a.out, a.overlays.as_deref(), &a.model.files())?;
    if let Some(note) = &plan.note {
        println!("{note}");
    }
    a.model.check()?;
    let mut det = a.model.load()?;
    let mut bar = slam_runner::console::Progress::new("detect", plan.frames.len() as u64, "frames", false);
    let summary = plan.run(&mut det, &mut || bar.inc())?;
    bar.finish();
    println!("{summary}");
    Ok(())
}

#[derive(Args, Debug)]
pub struct RecallArgs {
    /// The drive-0052 fixture folder (default: fixtures/kitti_raw_0052)
    #[arg(long)]
    data: Option<PathBuf>,
    /// Only this mode (default: compare squash, letterbox and tiles)
    #[arg(long, value_enum)]
    mode: Option<ModeName>,
}

pub fn recall(a: &RecallArgs) -> anyhow::Result<()> {
    let data = a.data.clone().unwrap_or_else(|| crate::fixture("kitti_raw_0052"));
    let modes = a.mode.map_or_else(|| vec![ModeName::Squash, ModeName::Letterbox, ModeName::Tiles], |m| vec![m]);
    slam_runner::detect::detector_recall(&data, &crate::fixture("detector"), &modes, &mut |l| println!("{l}"))?;
    Ok(())
}
