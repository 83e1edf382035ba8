//! `slam-app assoc kitti`: the associators compared on KITTI tracking labels (true track ids hidden),
//! per sequence and condition ([`slam_studies::assoc_study`]), as a table and CSV.

use std::path::PathBuf;

use slam_dataset::kitti::tracking::read_tracking_labels;
use slam_studies::assoc_study::{compared_associators, label_study, labelled_frames, CONDITIONS};

use crate::EvalError;

/// The study's title and notes (`dir` holds the `seqs` sequences, noise seeded from `seed`), then the
/// table's header: sequence, objects, and `ODA / IoU` ID switches per condition.
pub fn kitti_table_header(seqs: usize, dir: &std::path::Path, seed: u64) -> String {
    let mut header = format!(
        "KITTI tracking labels as detections ({seqs} sequences in {}), seed {seed}\n\
         DontCare and Misc dropped; noise: Gaussian, sigma = fraction of box width/height per coordinate.\n\
         Cues available: Kalman prediction only (no images: no flow; no ellipsoids).\n{:<6} {:>7}",
        dir.display(),
        "seq",
        "objects"
    );
    for c in &CONDITIONS {
        header.push_str(&format!(" | {:>20}", format!("{} ODA/IoU", c.name)));
    }
    header
}

/// The `ODA / IoU` cells of one table row.
fn cells(row: &mut String, pairs: impl Iterator<Item = [usize; 2]>) {
    for [oda, iou] in pairs {
        row.push_str(&format!(" | {:>20}", format!("{oda} / {iou}")));
    }
}

/// Every sequence folder of `seqs` (each with `label_02.txt`) under every condition with both
/// associators, noise seeded from `seed`; `on_row` gets each table row as it is made, the totals row
/// last. Returns the CSV (one record per sequence, condition and associator).
pub fn kitti_assoc_study(seqs: &[PathBuf], seed: u64, on_row: &mut dyn FnMut(String)) -> Result<String, EvalError> {
    let csv_error = |e: csv::Error| EvalError::Invalid(format!("writing the study's CSV: {e}"));
    let mut csv = csv::Writer::from_writer(Vec::new());
    let columns = ["sequence", "objects", "detections", "condition", "associator", "id_switches"];
    csv.write_record(columns).map_err(csv_error)?;
    let mut totals = vec![[0usize; 2]; CONDITIONS.len()];
    for seq in seqs {
        let name = seq.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let labels = read_tracking_labels(seq.join("label_02.txt"))?;
        // the poses, when given, say how many frames the sequence has (one per line)
        let poses_path = seq.join("poses_orbslam3.txt");
        if poses_path.exists() {
            let n = slam_dataset::kitti::poses::read_kitti_poses(&poses_path)?.len();
            let source = format!("the {n} poses of {} (line k is frame k)", poses_path.display());
            slam_dataset::kitti::tracking::check_label_frames(&seq.join("label_02.txt"), &labels, n, &source)?;
        }
        let (frames, n_frames, objects) =
            labelled_frames(labels.iter().map(|l| (l.frame, l.track_id, l.class, l.bbox)));
        let runs = label_study(&frames, n_frames, seed);
        for ((cond, pair), total) in CONDITIONS.iter().zip(&runs).zip(&mut totals) {
            for ((aname, _), (r, t)) in compared_associators().iter().zip(pair.iter().zip(total.iter_mut())) {
                *t += r.id_switches;
                let (o, d, s) = (objects.to_string(), r.detections.to_string(), r.id_switches.to_string());
                csv.write_record([name.as_str(), &o, &d, cond.name, aname, &s]).map_err(csv_error)?;
            }
        }
        let mut row = format!("{:<6} {:>7}", name, objects);
        cells(&mut row, runs.iter().map(|p| p.map(|r| r.id_switches)));
        on_row(row);
    }
    let mut row = format!("{:<6} {:>7}", "total", "");
    cells(&mut row, totals.iter().copied());
    on_row(row);
    let bytes = csv.into_inner().map_err(|e| csv_error(e.into_error().into()))?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_and_csv_cover_every_sequence_condition_and_associator() {
        let dir = std::env::temp_dir().join(format!("slam-eval-assoc-{}", std::process::id()));
        let seq = dir.join("0000");
        std::fs::create_dir_all(&seq).expect("tmp");
        // two cars crossing over 6 frames (KITTI tracking label format)
        let mut text = String::new();
        for f in 0..6 {
            let (x1, x2) = (100.0 + 40.0 * f as f64, 500.0 - 40.0 * f as f64);
            for (id, x) in [(0, x1), (1, x2)] {
                text.push_str(&format!("{f} {id} Car 0 0 0 {x} 150 {} 200 1.5 1.6 4.0 0 1.6 20 0\n", x + 80.0));
            }
        }
        std::fs::write(seq.join("label_02.txt"), text).expect("labels");
        let mut rows = Vec::new();
        let csv = kitti_assoc_study(std::slice::from_ref(&seq), 1, &mut |r| rows.push(r)).expect("study");
        assert_eq!(rows.len(), 2, "one sequence row and the totals: {rows:?}");
        assert!(rows[0].starts_with("0000") && rows[1].starts_with("total"), "{rows:?}");
        assert_eq!(csv.lines().count(), 1 + CONDITIONS.len() * 2, "{csv}");
        assert!(csv.lines().nth(1).is_some_and(|l| l.starts_with("0000,2,12,clean,")), "{csv}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
