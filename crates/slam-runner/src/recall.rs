//! `slam-app detect-recall`: recall of the shipped detector on the labelled frames of drive 0052
//! ([`slam_eval::recall`]), per input mode, with the time per frame.

use std::{path::Path, time::Instant};

use slam_core::DetectionSource;
use slam_eval::recall::RecallSet;
use slam_frontend::{read_image, ModeName, ModelSpec};

use crate::error::Result;

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
