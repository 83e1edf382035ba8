//! The detector commands: `slam-app detect` (a detector over a folder of images into a detection file
//! and overlays, [`DetectPlan`]) and `slam-app detect-recall` (recall of the shipped detector on the
//! labelled frames of drive 0052, per input mode, [`detector_recall`]).

use std::{
    path::{Path, PathBuf},
    time::Instant,
};

use slam_core::DetectionSource;
use slam_dataset::{
    detections::DetectionFile,
    output::{refuse_overwriting_inputs, AtomicFile, OutputDir, Written},
};
use slam_eval::recall::RecallSet;
use slam_frontend::{batch::detect_images, read_image, ModeName, ModelSpec};

use crate::error::{Result, RunnerError};

/// A detection run over a folder of images whose outputs are checked writable: the detection JSON
/// and, on request, an overlay folder, each put in place whole at the end.
pub struct DetectPlan {
    /// The images with their frame ids.
    pub frames: Vec<(usize, PathBuf)>,
    /// A note on how the frames are numbered, when not by the numbers in their names.
    pub note: Option<String>,
    json: AtomicFile,
    shown: PathBuf,
    overlays: Option<OutputDir>,
}

impl DetectPlan {
    /// The images of `input` (any KITTI layout or a folder of images) numbered by the numbers in their
    /// file names (by position in name order when those are not distinct numbers), and the outputs
    /// `out` and `overlays` checked writable; `models` are the model files the detector will read
    /// (`--cfg`, `--weights`, `--onnx`), which no output may replace either.
    pub fn new(input: &Path, out: &Path, overlays: Option<&Path>, models: &[(&str, &Path)]) -> Result<Self> {
        let images = slam_dataset::folders::list_images(input)?;
        let (ids, note) = match slam_dataset::folders::frame_ids(&images) {
            Some(ids) => (ids, None),
            None => (
                (0..images.len()).collect(),
                Some(
                    "image names are not all distinct frame numbers: frames are numbered by position in name order"
                        .into(),
                ),
            ),
        };
        // nothing it reads may be written over: an image, the input folder (inside an overlay folder)
        let mut inputs: Vec<(&str, &Path)> = vec![("the input folder", input)];
        inputs.extend(images.iter().map(|p| ("an input image", p.as_path())));
        inputs.extend(models.iter().copied());
        let mut outputs = vec![Written::File("--out", out)];
        outputs.extend(overlays.map(|o| Written::Folder("--overlays", o)));
        refuse_overwriting_inputs(&inputs, &outputs)?;
        let json = AtomicFile::new(out)?;
        let overlays = overlays.map(|o| OutputDir::create(o, "--overlays", "detect")).transpose()?;
        Ok(Self { frames: ids.into_iter().zip(images).collect(), note, json, shown: out.to_path_buf(), overlays })
    }

    /// Run `detector` on every frame (`tick` after each), write the outputs; returns the summary line.
    pub fn run(self, detector: &mut dyn DetectionSource, tick: &mut dyn FnMut()) -> Result<String> {
        let dir = self.overlays.as_ref().map(|o| o.path());
        let out = detect_images(detector, &self.frames, dir, tick).map_err(RunnerError::other)?;
        let file = DetectionFile { image_size: out.image_size, frames: out.frames };
        let text = file.to_json(&self.shown)?;
        self.json.write_with(|tmp| std::fs::write(tmp, text))?;
        if let Some(o) = self.overlays {
            o.commit()?;
        }
        Ok(format!(
            "{} frames, {} detections, {} unreadable frames skipped; wrote {}",
            self.frames.len(),
            out.total,
            out.skipped,
            self.shown.display()
        ))
    }
}

/// Load the labelled frames in `data`, run the shipped model (its files in `shipped`) in each of `modes`
/// and give `print` the table: header lines, then one row per mode (found, recall, ms per frame).
pub fn detector_recall(data: &Path, shipped: &Path, modes: &[ModeName], print: &mut dyn FnMut(String)) -> Result<()> {
    let set = RecallSet::load(data)?;
    let n_labels = set.label_count();
    let images: Vec<_> = set.images.iter().map(|p| read_image(p, true)).collect::<std::result::Result<_, _>>()?;
    print(format!(
        "Detector recall on KITTI raw 2011_09_26_drive_0052, frames 7/14/21/31: {n_labels} labelled vehicles (Car, Van)"
    ));
    print("A label counts as found when a car/truck/bus detection overlaps it with IoU > 0.5 (one-to-one).".into());
    print(format!("{:<12} {:>7} {:>10} {:>12}", "mode", "found", "recall", "ms / frame"));
    for &m in modes {
        let mut det = ModelSpec::shipped(m).load(shipped)?;
        let mut found = 0;
        let start = Instant::now();
        for (i, img) in images.iter().enumerate() {
            found += set.found(i, &det.detect(i, Some(img)).map_err(crate::RunnerError::other)?);
        }
        let ms = start.elapsed().as_secs_f64() * 1000.0 / images.len().max(1) as f64;
        let recall = found as f64 / n_labels.max(1) as f64;
        print(format!("{:<12} {found:>4}/{n_labels:<2} {recall:>10.2} {ms:>12.0}", m.name()));
    }
    Ok(())
}
