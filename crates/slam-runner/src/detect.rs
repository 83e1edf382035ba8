//! The detector commands: `slam-app detect` (a detector over a folder of images into a detection file
//! and overlays, [`DetectPlan`]) and `slam-app detect-recall` (recall and precision of detectors on
//! the labelled frames of drives 0052 and 0005, [`recall_sets`], [`detector_recall`]).

use std::{
    path::{Path, PathBuf},
    time::Instant,
};

use slam_core::{figure::cell, DetectionSource};
use slam_dataset::{
    detections::DetectionFile,
    output::{refuse_overwriting_inputs, AtomicFile, OutputDir, Written},
};
use slam_detect::batch::detect_images;
use slam_eval::recall::{Counts, RecallSet};
use slam_frontend::read_image;

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

/// The labelled frames a detector is measured on (`slam-app detect-recall`): the four frames of drive
/// 0052 (`kitti_raw_0052`, object-benchmark labels on camera 2) and drive 0005's 91 frames of camera 0
/// with the KITTI tracking labels of sequence 0000 (`kitti_raw_0005`, `kitti_tracking/0000`; the
/// protocol of [`RecallSet::load_drive`]), found under `fixtures`.
pub fn recall_sets(fixtures: &Path) -> Result<Vec<(String, RecallSet)>> {
    let d0052 = RecallSet::load(&fixtures.join("kitti_raw_0052"))?;
    let drive = fixtures.join("kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync");
    let (d0005, _) = RecallSet::load_drive(&drive, &fixtures.join("kitti_tracking/0000/label_02.txt"))?;
    Ok(vec![
        (format!("drive 0052, frames 7/14/21/31, camera 2: {} Car/Van labels", d0052.label_count()), d0052),
        (
            format!(
                "drive 0005, frames 0-90, camera 0: {} Car/Van/Truck labels of occlusion <= 1, >= 25 px tall",
                d0005.label_count()
            ),
            d0005,
        ),
    ])
}

/// Loads a detector for [`detector_recall`].
pub type DetectorLoader = Box<dyn FnMut() -> Result<Box<dyn DetectionSource>>>;

/// Run each detector (`name`, loader) over every frame of each set and give `print` the table: the
/// protocol, then one row per detector with found / labels, recall and precision per set, the median
/// milliseconds per frame over all frames, and the median of the network's forward passes in them.
pub fn detector_recall(
    sets: &[(String, RecallSet)],
    detectors: &mut [(String, DetectorLoader)],
    print: &mut dyn FnMut(String),
) -> Result<()> {
    // each set's images, read once (colour as stored: camera 2 colour, camera 0 grey)
    let images: Vec<Vec<_>> = sets
        .iter()
        .map(|(_, s)| s.images.iter().map(|p| read_image(p, true)).collect::<std::result::Result<Vec<_>, _>>())
        .collect::<std::result::Result<_, _>>()?;
    print("Detector recall and precision: a label is found by one car/truck/bus detection overlapping it with IoU >= 0.5 \
           (one to one, best overlaps first); a prediction matching no label and lying at least half inside a \
           DontCare region is not counted (vehicles KITTI left unlabelled elsewhere count as wrong: precision is a \
           lower bound)"
        .into());
    for (k, (name, _)) in sets.iter().enumerate() {
        print(format!("set {}: {name}", k + 1));
    }
    let mut header = format!("| {:<56} |", "detector");
    let mut rule = format!("|{}|", "-".repeat(58));
    for k in 1..=sets.len() {
        header.push_str(&format!(" set {k}: found | recall | precision |"));
        rule.push_str("---:|---:|---:|");
    }
    header.push_str(" ms / frame (median) | of which forward pass |");
    rule.push_str("---:|---:|");
    print(header);
    print(rule);
    for (name, load) in detectors.iter_mut() {
        let mut det = load()?;
        let mut row = format!("| {name:<56} |");
        let (mut times, mut forward) = (Vec::new(), Vec::new());
        for ((_, set), imgs) in sets.iter().zip(&images) {
            let mut c = Counts::default();
            for (i, img) in imgs.iter().enumerate() {
                let start = Instant::now();
                let d = det.detect(set.frame_ids[i], Some(img)).map_err(crate::RunnerError::other)?;
                times.push(start.elapsed().as_secs_f64() * 1000.0);
                forward.extend(det.forward_ms());
                c += set.score(i, &d);
            }
            row.push_str(&format!(
                " {}/{} | {} | {} |",
                c.found,
                c.labels,
                cell(c.recall(), 3),
                cell(c.precision(), 3)
            ));
        }
        row.push_str(&format!(
            " {} | {} |",
            cell(slam_core::figure::median(&mut times), 0),
            cell(slam_core::figure::median(&mut forward), 0)
        ));
        print(row);
    }
    Ok(())
}
