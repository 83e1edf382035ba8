//! `slam-app detect` and `slam-app detect-recall`.

use std::{
    collections::BTreeMap,
    path::PathBuf,
    time::Instant,
};

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use slam_core::{geometry::BBox, DetectionSource};
use slam_dataset::{classes, detections::DetectionFile};
use slam_frontend::{draw_detections, read_image, write_image, DetectorConfig, DnnDetector, InputMode};

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
    let mut file = DetectionFile::default();
    let (mut skipped, mut total) = (0usize, 0usize);
    for (&i, path) in ids.iter().zip(&images) {
        let img = match read_image(path, true) {
            Ok(img) => img,
            Err(e) => {
                tracing::warn!("frame {i} skipped: {e}");
                skipped += 1;
                bar.inc();
                continue;
            }
        };
        file.image_size.get_or_insert([img.width, img.height]);
        let d = det.detect(i, Some(&img)).with_context(|| format!("detecting in {}", path.display()))?;
        total += d.len();
        if let Some(o) = overlays.as_ref().map(|o| o.path()) {
            let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| format!("{i:06}"));
            write_image(o.join(format!("{name}.png")), &draw_detections(&img, &d, |c| c.name().to_string())?)?;
        }
        file.frames.insert(i, d);
        bar.inc();
    }
    bar.finish();
    json.write_with(|tmp| file.write(tmp).map_err(anyhow::Error::from))?;
    if let Some(o) = overlays {
        o.commit()?;
    }
    println!(
        "{} frames, {total} detections, {skipped} unreadable frames skipped; wrote {}",
        images.len(),
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

/// Greedy one-to-one matching of labelled boxes to detections at IoU > 0.5; returns the matched count.
fn matched(labels: &[BBox], dets: &[BBox]) -> usize {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, l) in labels.iter().enumerate() {
        for (j, d) in dets.iter().enumerate() {
            let iou = l.iou(d);
            if iou > 0.5 {
                pairs.push((iou, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let (mut used_l, mut used_d) = (vec![false; labels.len()], vec![false; dets.len()]);
    let mut n = 0;
    for (_, i, j) in pairs {
        if !used_l[i] && !used_d[j] {
            used_l[i] = true;
            used_d[j] = true;
            n += 1;
        }
    }
    n
}

pub fn recall(a: &RecallArgs) -> anyhow::Result<()> {
    let data = a.data.clone().unwrap_or_else(|| crate::fixture("kitti_raw_0052"));
    let map = std::fs::read_to_string(data.join("object/drive_0052_frame_to_object_id.txt"))
        .with_context(|| format!("cannot read the frame map in {}", data.display()))?;
    let mut frames = Vec::new();
    for line in map.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty()) {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() != 2 {
            bail!("malformed line in drive_0052_frame_to_object_id.txt: '{line}'");
        }
        let img = data.join(format!("2011_09_26/2011_09_26_drive_0052_sync/image_02/data/{}.png", f[0]));
        let label = data.join(format!("object/training/label_2/{}.txt", f[1]));
        frames.push((img, label));
    }
    let mut labelled: BTreeMap<usize, Vec<BBox>> = BTreeMap::new();
    for (i, (_, label)) in frames.iter().enumerate() {
        let text = std::fs::read_to_string(label).with_context(|| format!("cannot read {}", label.display()))?;
        for (ln, line) in text.lines().enumerate() {
            let f: Vec<&str> = line.split_whitespace().collect();
            if f.len() < 8 {
                bail!("{}:{}: expected a KITTI object label", label.display(), ln + 1);
            }
            if f[0] == "Car" || f[0] == "Van" {
                let v: Result<Vec<f64>, _> = f[4..8].iter().map(|s| s.parse::<f64>()).collect();
                let v = v.with_context(|| format!("{}:{}: bad box", label.display(), ln + 1))?;
                labelled.entry(i).or_default().push(BBox::new(v[0], v[1], v[2], v[3]));
            }
        }
    }
    let n_labels: usize = labelled.values().map(|v| v.len()).sum();
    let images: Vec<_> = frames.iter().map(|(p, _)| read_image(p, true)).collect::<Result<_, _>>()?;
    println!("Detector recall on KITTI raw 2011_09_26_drive_0052, frames 7/14/21/31: {n_labels} labelled vehicles (Car, Van)");
    println!("A label counts as found when a car/truck/bus detection overlaps it with IoU > 0.5 (one-to-one).");
    println!("{:<12} {:>7} {:>10} {:>12}", "mode", "found", "recall", "ms / frame");
    let modes: Vec<Mode> = match a.mode {
        Some(m) => vec![m],
        None => vec![Mode::Squash, Mode::Letterbox, Mode::Tiles],
    };
    for m in modes {
        let args = ModelArgs::shipped(m);
        let mut det = args.load()?;
        let mut found = 0;
        let start = Instant::now();
        for (i, img) in images.iter().enumerate() {
            let d = det.detect(i, Some(img))?;
            let vehicles: Vec<BBox> = d
                .iter()
                .filter(|d| [classes::CAR, classes::TRUCK, classes::BUS].contains(&d.class))
                .map(|d| d.bbox)
                .collect();
            found += matched(labelled.get(&i).map(|v| v.as_slice()).unwrap_or(&[]), &vehicles);
        }
        let ms = start.elapsed().as_secs_f64() * 1000.0 / images.len() as f64;
        println!(
            "{:<12} {:>4}/{:<2} {:>10.2} {:>12.0}",
            format!("{m:?}").to_lowercase(),
            found,
            n_labels,
            found as f64 / n_labels as f64,
            ms
        );
    }
    Ok(())
}
