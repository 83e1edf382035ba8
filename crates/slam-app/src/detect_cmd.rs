//! `slam-app detect` and `slam-app detect-recall`.

use std::path::PathBuf;

use clap::Args;
use slam_core::DetectionSource;
use slam_dataset::detections::DetectionFile;
use slam_frontend::{batch::detect_images, DnnDetector, ModeName, ModelError, ModelSpec};

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
        ModelError::Invalid(v) => crate::validate::flag(v).into(),
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

/// The frame id of each image: the number in its file name when every name is one, else (arbitrary
/// names) the position in name order, said on stdout.
fn frame_ids(images: &[PathBuf]) -> Vec<usize> {
    slam_dataset::folders::frame_ids(images).unwrap_or_else(|| {
        println!("image names are not all distinct frame numbers: frames are numbered by position in name order");
        (0..images.len()).collect()
    })
}

/// Overlay files `detect` writes (a folder written before the marker file existed may be replaced when it
/// holds only these).
fn overlay_name(name: &str) -> bool {
    name.ends_with(".png")
}

pub fn detect(a: &DetectArgs) -> anyhow::Result<()> {
    let images = slam_dataset::folders::list_images(&a.input)?;
    let ids = frame_ids(&images);
    a.model.check()?;
    // both outputs are checked writable before the first image, and put in place whole at the end
    let json = slam_dataset::output::AtomicFile::new(&a.out)?;
    let overlays = a
        .overlays
        .as_ref()
        .map(|o| slam_dataset::output::OutputDir::create(o, "--overlays", "detect", overlay_name))
        .transpose()?;
    let mut det = a.model.load()?;
    let mut bar = slam_runner::console::Progress::new("detect", images.len() as u64, "frames", false);
    let frames: Vec<(usize, PathBuf)> = ids.into_iter().zip(images).collect();
    let out = detect_images(&mut det, &frames, overlays.as_ref().map(|o| o.path()), &mut || bar.inc())?;
    bar.finish();
    let file = DetectionFile { image_size: out.image_size, frames: out.frames };
    json.write_with(|tmp| file.write(tmp).map_err(anyhow::Error::from))?;
    if let Some(o) = overlays {
        o.commit()?;
    }
    println!(
        "{} frames, {} detections, {} unreadable frames skipped; wrote {}",
        frames.len(),
        out.total,
        out.skipped,
        a.out.display()
    );
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
    slam_runner::recall::detector_recall(&data, &crate::fixture("detector"), &modes, &mut |l| println!("{l}"))?;
    Ok(())
}
