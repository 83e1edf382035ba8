//! `slam-app detect` and `slam-app detect-recall`.

use std::path::PathBuf;

use clap::Args;
use slam_core::DetectionSource;
use slam_detect::{
    parse_input_size, Device, DnnDetector, FamilyName, InputSize, ModeName, ModelError, ModelSpec, ShippedModel,
};

#[derive(Args, Debug, Clone, Default)]
pub struct ModelArgs {
    /// A shipped detector: yolox-nano (YOLOX-nano, ONNX; the default) or yolo-fastest (Yolo-Fastest
    /// 1.1, Darknet)
    #[arg(long, value_enum, conflicts_with_all = ["cfg", "weights", "onnx"])]
    model: Option<ShippedModel>,
    /// Darknet .cfg of a model giving YOLO rows (default: the shipped Yolo-Fastest 1.1's)
    #[arg(long)]
    cfg: Option<PathBuf>,
    /// Darknet .weights (default: the shipped Yolo-Fastest 1.1's)
    #[arg(long)]
    weights: Option<PathBuf>,
    /// An ONNX model instead; its output layout is --family
    #[arg(long, conflicts_with_all = ["cfg", "weights"])]
    onnx: Option<PathBuf>,
    /// Output layout of the --onnx model: yolox (YOLOX's grid cells of strides 8/16/32, input BGR
    /// 0-255; default) or rows (Darknet-style YOLO rows, normalised boxes, input RGB 0-1)
    #[arg(long, value_enum, requires = "onnx")]
    family: Option<FamilyName>,
    /// Input mode (default: letterbox for YOLOX, tiles for rows)
    #[arg(long, value_enum)]
    mode: Option<ModeName>,
    /// Number of tiles across the width (selects --mode tiles; default 3)
    #[arg(long)]
    tiles: Option<u32>,
    /// Network input, WIDTHxHEIGHT or N for a square, multiples of 32 (default: 736x224 for YOLOX,
    /// 320 for rows)
    #[arg(long, value_parser = parse_input_size)]
    input_size: Option<InputSize>,
    /// Smallest score kept (default: 0.4 for YOLOX, 0.2 for rows)
    #[arg(long)]
    score: Option<f32>,
    /// Where ONNX Runtime runs an ONNX model: cpu (default) or cuda (the onnxruntime-gpu runtime, which
    /// tools/setup.sh installs where nvidia-smi lists a GPU, and an NVIDIA GPU)
    #[arg(long, value_enum)]
    device: Option<Device>,
    /// ONNX Runtime's intra-op threads on the CPU (default 1: on two cores tracking needs the other one;
    /// docs/detections.md, "Thread budget")
    #[arg(long)]
    detector_threads: Option<usize>,
}

impl ModelArgs {
    pub(crate) fn spec(&self) -> ModelSpec {
        let ModelArgs { model, cfg, weights, onnx, family, mode, tiles, input_size, score, device, detector_threads } =
            self.clone();
        ModelSpec {
            model,
            cfg,
            weights,
            onnx,
            family,
            mode,
            tiles,
            input_size,
            score,
            device,
            threads: detector_threads,
        }
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
        self.spec().first_given()
    }

    pub(crate) fn load(&self) -> anyhow::Result<DnnDetector> {
        self.spec().load(&crate::fixture(""), &crate::ort_setup()).map_err(model_error)
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
    e.as_options().into()
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
    /// Also the other input modes of both shipped models (squash, letterbox, tiles)
    #[arg(long)]
    all: bool,
    /// One detector only, as these options name it (default: the shipped YOLOX-nano and Yolo-Fastest
    /// with their own settings)
    #[command(flatten)]
    model: ModelArgs,
}

pub fn recall(a: &RecallArgs) -> anyhow::Result<()> {
    let sets = slam_runner::detect::recall_sets(&crate::fixture(""))?;
    let specs: Vec<ModelSpec> = if a.model.given().is_some() {
        a.model.check()?;
        vec![a.model.spec()]
    } else {
        ModelSpec::recall_candidates(a.all)
    };
    use slam_runner::detect::DetectorLoader as Loader;
    let mut detectors: Vec<(String, Loader)> = specs
        .into_iter()
        .map(|spec| {
            let name = spec.describe().map_err(model_error)?;
            let load: Loader = Box::new(move || {
                let d = spec.load(&crate::fixture(""), &crate::ort_setup()).map_err(slam_runner::RunnerError::other)?;
                Ok(Box::new(d) as Box<dyn DetectionSource>)
            });
            Ok((name, load))
        })
        .collect::<anyhow::Result<_>>()?;
    slam_runner::detect::detector_recall(&sets, &mut detectors, &mut |l| println!("{l}"))?;
    Ok(())
}
