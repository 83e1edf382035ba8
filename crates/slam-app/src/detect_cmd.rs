//! `slam-app detect` and `slam-app detect-recall`.

use std::{path::PathBuf, time::Instant};

use anyhow::bail;
use clap::{Args, ValueEnum};
use slam_core::DetectionSource;
use slam_dataset::detections::DetectionFile;
use slam_eval::recall::RecallSet;
use slam_frontend::{batch::detect_images, read_image, DetectorConfig, DnnDetector, InputMode};

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum Mode {
    /// Resize to the square input, ignoring the aspect ratio.
    Squash,
    /// Keep the aspect ratio, pad.
    Letterbox,
    /// Overlapping tiles across the width plus the whole frame.
    Tiles,
}

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
    mode: Option<Mode>,
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
    /// Range checks of the model options (before any model is loaded).
    pub(crate) fn check(&self) -> anyhow::Result<()> {
        use crate::validate::{count, number, Range, MAX_INPUT_SIZE};
        let input_size = self.input_size.unwrap_or(320);
        if !(32..=MAX_INPUT_SIZE).contains(&input_size) || input_size % 32 != 0 {
            bail!("--input-size {input_size}: must be a multiple of 32 in [32, {MAX_INPUT_SIZE}] (memory grows with its square)");
        }
        // more tiles than 16 across a KITTI frame would be narrower than the objects they should hold
        count("--tiles", self.tiles.unwrap_or(3) as usize, 1, 16)?;
        number("--score", self.score.unwrap_or(0.2) as f64, Range::closed(0.0, 1.0), "")?;
        Ok(())
    }

    /// The shipped model in one input mode, every other setting at its default.
    fn shipped(mode: Mode) -> Self {
        Self { cfg: None, weights: None, onnx: None, mode: Some(mode), tiles: None, input_size: None, score: None }
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
        self.check()?;
        let mode = match (self.mode, self.tiles) {
            (None | Some(Mode::Tiles), t) => InputMode::Tiles(t.unwrap_or(3)),
            (Some(m), Some(_)) => {
                bail!("--tiles is an option of --mode tiles, but --mode {} was given", format!("{m:?}").to_lowercase())
            }
            (Some(Mode::Squash), None) => InputMode::Squash,
            (Some(Mode::Letterbox), None) => InputMode::Letterbox,
        };
        let config = DetectorConfig {
            input_size: self.input_size.unwrap_or(320),
            mode,
            score_threshold: self.score.unwrap_or(0.2),
            ..DetectorConfig::default()
        };
        Ok(match &self.onnx {
            Some(m) => DnnDetector::from_onnx(m, config)?,
            None => {
                let cfg = self.cfg.clone().unwrap_or_else(|| crate::fixture("detector/yolo-fastest-1.1.cfg"));
                let weights =
                    self.weights.clone().unwrap_or_else(|| crate::fixture("detector/yolo-fastest-1.1.weights"));
                DnnDetector::from_darknet(cfg, weights, config)?
            }
        })
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
    let json = crate::output::AtomicFile::new(&a.out)?;
    let overlays = a
        .overlays
        .as_ref()
        .map(|o| crate::output::OutputDir::create(o, "--overlays", "detect", overlay_name))
        .transpose()?;
    let mut det = a.model.load()?;
    let mut bar = crate::progress::Progress::new("detect", images.len() as u64, "frames", false);
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
    mode: Option<Mode>,
}

pub fn recall(a: &RecallArgs) -> anyhow::Result<()> {
    let data = a.data.clone().unwrap_or_else(|| crate::fixture("kitti_raw_0052"));
    let set = RecallSet::load(&data)?;
    let n_labels = set.label_count();
    let images: Vec<_> = set.images.iter().map(|p| read_image(p, true)).collect::<Result<_, _>>()?;
    println!("Detector recall on KITTI raw 2011_09_26_drive_0052, frames 7/14/21/31: {n_labels} labelled vehicles (Car, Van)");
    println!("A label counts as found when a car/truck/bus detection overlaps it with IoU > 0.5 (one-to-one).");
    println!("{:<12} {:>7} {:>10} {:>12}", "mode", "found", "recall", "ms / frame");
    let modes: Vec<Mode> = match a.mode {
        Some(m) => vec![m],
        None => vec![Mode::Squash, Mode::Letterbox, Mode::Tiles],
    };
    for m in modes {
        let mut det = ModelArgs::shipped(m).load()?;
        let mut found = 0;
        let start = Instant::now();
        for (i, img) in images.iter().enumerate() {
            found += set.found(i, &det.detect(i, Some(img))?);
        }
        let ms = start.elapsed().as_secs_f64() * 1000.0 / images.len() as f64;
        let name = format!("{m:?}").to_lowercase();
        println!("{name:<12} {found:>4}/{n_labels:<2} {:>10.2} {ms:>12.0}", found as f64 / n_labels as f64);
    }
    Ok(())
}
