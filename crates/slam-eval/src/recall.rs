//! Detector recall on labelled KITTI raw frames (`slam-app detect-recall`): the labelled frames of the
//! drive-0052 fixture ([`RecallSet::load`]) and a one-to-one match of labelled vehicles to detected
//! ones ([`matched`]).

use std::{collections::BTreeMap, path::Path, path::PathBuf};

use slam_core::{geometry::BBox, ClassId, Detection};
use slam_dataset::classes;

use crate::EvalError;

/// Least IoU of a detection with a labelled box to find it (the usual detection criterion).
pub const MATCH_IOU: f64 = 0.5;

/// The labelled frames: their left colour images and the Car / Van boxes of their object labels.
#[derive(Debug, Clone, PartialEq)]
pub struct RecallSet {
    /// Left colour image of each labelled frame, in the frame map's order.
    pub images: Vec<PathBuf>,
    /// Labelled vehicle boxes per frame (index into `images`; frames without vehicles are absent).
    pub labels: BTreeMap<usize, Vec<BBox>>,
}

impl RecallSet {
    /// Read the drive-0052 fixture folder: `object/drive_0052_frame_to_object_id.txt` (one `raw-frame
    /// object-id` pair a line, `#` comments) maps raw frames to KITTI object labels
    /// (`object/training/label_2/<id>.txt`). Errors name the file and line.
    pub fn load(data: &Path) -> Result<Self, EvalError> {
        let map_path = data.join("object/drive_0052_frame_to_object_id.txt");
        let map = slam_core::files::read_text(&map_path, &slam_core::files::TABLE)?;
        let mut set = RecallSet { images: Vec::new(), labels: BTreeMap::new() };
        for line in map.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty()) {
            let f: Vec<&str> = line.split_whitespace().collect();
            if f.len() != 2 {
                return Err(EvalError::Invalid(format!(
                    "malformed line in drive_0052_frame_to_object_id.txt: '{line}'"
                )));
            }
            let i = set.images.len();
            set.images.push(data.join(format!("2011_09_26/2011_09_26_drive_0052_sync/image_02/data/{}.png", f[0])));
            let boxes = vehicle_labels(&data.join(format!("object/training/label_2/{}.txt", f[1])))?;
            if !boxes.is_empty() {
                set.labels.insert(i, boxes);
            }
        }
        Ok(set)
    }

    /// Number of labelled vehicles.
    pub fn label_count(&self) -> usize {
        self.labels.values().map(|v| v.len()).sum()
    }

    /// Vehicles of frame `i` found among `detections` (car, truck and bus detections count).
    pub fn found(&self, i: usize, detections: &[Detection]) -> usize {
        let vehicles: Vec<BBox> = detections.iter().filter(|d| is_vehicle(d.class)).map(|d| d.bbox).collect();
        matched(self.labels.get(&i).map(|v| v.as_slice()).unwrap_or(&[]), &vehicles)
    }
}

/// Whether a detected class counts as a vehicle for the Car / Van labels.
pub fn is_vehicle(class: ClassId) -> bool {
    [classes::CAR, classes::TRUCK, classes::BUS].contains(&class)
}

/// The Car and Van boxes of a KITTI object label file.
fn vehicle_labels(label: &Path) -> Result<Vec<BBox>, EvalError> {
    let text = slam_core::files::read_text(label, &slam_core::files::TABLE)?;
    let mut boxes = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 8 {
            return Err(EvalError::Invalid(format!("{}:{}: expected a KITTI object label", label.display(), ln + 1)));
        }
        if f[0] == "Car" || f[0] == "Van" {
            let v: Vec<f64> = f[4..8]
                .iter()
                .map(|s| s.parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| EvalError::Invalid(format!("{}:{}: bad box: {e}", label.display(), ln + 1)))?;
            boxes.push(BBox::new(v[0], v[1], v[2], v[3]));
        }
    }
    Ok(boxes)
}

/// Greedy one-to-one matching of labelled boxes to detections at IoU > [`MATCH_IOU`], best overlaps
/// first (ties by index, so the count is deterministic); returns the matched count.
pub fn matched(labels: &[BBox], dets: &[BBox]) -> usize {
    matched_pairs(labels, dets, |iou| iou > MATCH_IOU).len()
}

/// Greedy one-to-one matching of labelled boxes to detections whose IoU `accept`s, best overlaps first
/// (ties by label, then detection index, so the result is deterministic): `(label, detection)` index
/// pairs, best first.
pub fn matched_pairs(labels: &[BBox], dets: &[BBox], accept: impl Fn(f64) -> bool) -> Vec<(usize, usize)> {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, l) in labels.iter().enumerate() {
        for (j, d) in dets.iter().enumerate() {
            let iou = l.iou(d);
            if accept(iou) {
                pairs.push((iou, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let (mut used_l, mut used_d) = (vec![false; labels.len()], vec![false; dets.len()]);
    let mut out = Vec::new();
    for (_, i, j) in pairs {
        if !used_l[i] && !used_d[j] {
            used_l[i] = true;
            used_d[j] = true;
            out.push((i, j));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matching_is_one_to_one_above_half_overlap() {
        let a = BBox::new(0.0, 0.0, 100.0, 50.0);
        let b = BBox::new(200.0, 0.0, 300.0, 50.0);
        let near_a = BBox::new(5.0, 0.0, 100.0, 50.0);
        assert_eq!(matched(&[a, b], &[near_a]), 1, "one detection finds one label");
        assert_eq!(matched(&[a], &[near_a, a]), 1, "two detections of one label count once");
        assert_eq!(matched(&[a, b], &[a, b]), 2);
        assert_eq!(matched(&[a], &[BBox::new(50.0, 0.0, 150.0, 50.0)]), 0, "IoU 1/3 is not a match");
    }

    #[test]
    fn the_shipped_fixture_loads_with_its_labels_and_bad_lines_are_named() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/kitti_raw_0052");
        let set = RecallSet::load(&data).expect("fixture loads");
        assert_eq!(set.images.len(), 4);
        assert!(set.label_count() > 0 && set.images.iter().all(|p| p.is_file()));
        let car = Detection::new(classes::CAR, 0.9, set.labels.values().next().expect("labels")[0]);
        let i = *set.labels.keys().next().expect("a labelled frame");
        assert_eq!(set.found(i, std::slice::from_ref(&car)), 1);
        assert_eq!(set.found(i, &[Detection { class: ClassId(0), ..car }]), 0, "a person is not a vehicle");
        let dir = std::env::temp_dir().join(format!("recall-bad-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("object")).expect("dir");
        std::fs::write(dir.join("object/drive_0052_frame_to_object_id.txt"), "7\n").expect("write");
        let e = RecallSet::load(&dir).expect_err("malformed").to_string();
        assert!(e.contains("malformed line") && e.contains("'7'"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
