//! Detector recall and precision on labelled KITTI frames (`slam-app detect-recall`): the four
//! labelled frames of drive 0052 ([`RecallSet::load`]: object-benchmark labels, camera 2) and every
//! frame of a raw drive with KITTI tracking labels seen from camera 0 ([`RecallSet::load_drive`]: the
//! protocol of issue 31), and a one-to-one match of labelled vehicles to detected ones
//! ([`RecallSet::score`]).

use std::{collections::BTreeMap, path::Path, path::PathBuf};

use nalgebra::{Matrix3x4, Vector4};
use slam_core::{geometry::BBox, ClassId, Detection};
use slam_dataset::{
    classes,
    kitti::{calib::Calib, tracking::read_tracking_labels},
};

use crate::EvalError;

/// Least IoU of a detection with a labelled box to find it (the usual detection criterion).
pub const MATCH_IOU: f64 = 0.5;

/// Least share of a prediction's area inside one DontCare region for it to count as neither right nor
/// wrong (KITTI leaves the vehicles there unlabelled).
pub const DONT_CARE_COVER: f64 = 0.5;

/// Shortest labelled box counted on a drive, pixels: KITTI's own "moderate" difficulty (at 25 px a car
/// is about 60 m away).
pub const MIN_BOX_HEIGHT_PX: f64 = 25.0;

/// Most occlusion of a labelled vehicle counted on a drive (KITTI: 0 visible, 1 partly occluded, 2
/// largely occluded, 3 unknown): KITTI's "moderate" difficulty.
pub const MAX_OCCLUSION: i32 = 1;

/// The labelled frames: their images, the vehicle boxes a detector should find, and the DontCare
/// regions where its predictions count neither way.
#[derive(Debug, Clone, PartialEq)]
pub struct RecallSet {
    /// Image of each labelled frame, in order.
    pub images: Vec<PathBuf>,
    /// Frame id of each image (the number in its file name).
    pub frame_ids: Vec<usize>,
    /// Labelled vehicle boxes per frame (index into `images`; frames without vehicles are absent).
    pub labels: BTreeMap<usize, Vec<BBox>>,
    /// DontCare regions per frame (index into `images`).
    pub dont_care: BTreeMap<usize, Vec<BBox>>,
}

/// What a detector found on a set of frames.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Labelled vehicles.
    pub labels: usize,
    /// Of those, found (one detection each).
    pub found: usize,
    /// Vehicle predictions (car, truck, bus detections).
    pub predictions: usize,
    /// Predictions matching no label and lying mostly inside a DontCare region: not counted.
    pub in_dont_care: usize,
}

impl Counts {
    /// found / labels (`None` without labels).
    pub fn recall(&self) -> Option<f64> {
        slam_core::figure::share(self.found, self.labels)
    }

    /// Right predictions over the counted ones (`None` without any: a detector that found nothing has
    /// no precision): found / (predictions − in DontCare).
    pub fn precision(&self) -> Option<f64> {
        slam_core::figure::share(self.found, self.predictions - self.in_dont_care)
    }

    /// Wrong predictions: neither a label's nor inside a DontCare region.
    pub fn wrong(&self) -> usize {
        self.predictions - self.in_dont_care - self.found
    }
}

impl std::ops::AddAssign for Counts {
    fn add_assign(&mut self, o: Self) {
        self.labels += o.labels;
        self.found += o.found;
        self.predictions += o.predictions;
        self.in_dont_care += o.in_dont_care;
    }
}

impl RecallSet {
    /// Read the drive-0052 fixture folder: `object/drive_0052_frame_to_object_id.txt` (one `raw-frame
    /// object-id` pair a line, `#` comments) maps raw frames to KITTI object labels
    /// (`object/training/label_2/<id>.txt`), whose Car and Van boxes (any size and occlusion) are the
    /// targets, on the left colour image. Errors name the file and line.
    pub fn load(data: &Path) -> Result<Self, EvalError> {
        let map_path = data.join("object/drive_0052_frame_to_object_id.txt");
        let map = slam_core::files::read_text(&map_path, &slam_core::files::TABLE)?;
        let mut set = RecallSet {
            images: Vec::new(),
            frame_ids: Vec::new(),
            labels: BTreeMap::new(),
            dont_care: BTreeMap::new(),
        };
        for line in map.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty()) {
            let f: Vec<&str> = line.split_whitespace().collect();
            let frame = (f.len() == 2).then(|| f[0].parse::<usize>().ok()).flatten();
            let Some(frame) = frame else {
                return Err(EvalError::Invalid(format!(
                    "malformed line in drive_0052_frame_to_object_id.txt: '{line}'"
                )));
            };
            let i = set.images.len();
            set.images.push(data.join(format!("2011_09_26/2011_09_26_drive_0052_sync/image_02/data/{}.png", f[0])));
            set.frame_ids.push(frame);
            let (boxes, dont_care) = object_labels(&data.join(format!("object/training/label_2/{}.txt", f[1])))?;
            if !boxes.is_empty() {
                set.labels.insert(i, boxes);
            }
            if !dont_care.is_empty() {
                set.dont_care.insert(i, dont_care);
            }
        }
        Ok(set)
    }

    /// Every frame of a raw drive's camera 0 (`image_00/data`, grey) with its KITTI tracking labels
    /// (`label_02.txt`): the targets are the Car, Van and Truck labels of at most [`MAX_OCCLUSION`] whose
    /// box is at least [`MIN_BOX_HEIGHT_PX`] tall. The labels' 2-D boxes belong to camera 2; each is
    /// moved into camera 0 by the shift of its 3-D box's centre between the two cameras' projections
    /// (`P_rect_02` and `P_rect_00` of the date's `calib_cam_to_cam.txt`: 44.9 px / depth in metres
    /// leftwards, 4 px at 10 m). Frames without an image are skipped and counted (the count is returned).
    pub fn load_drive(drive: &Path, labels: &Path) -> Result<(Self, usize), EvalError> {
        let calib_path = drive.parent().unwrap_or(drive).join("calib_cam_to_cam.txt");
        let calib = Calib::read(&calib_path)?;
        let (p0, p2) = (calib.matrix3x4("P_rect_00")?, calib.matrix3x4("P_rect_02")?);
        let all = read_tracking_labels(labels)?;
        let last = all.iter().map(|l| l.frame).max().unwrap_or(0);
        let mut set = RecallSet {
            images: Vec::new(),
            frame_ids: Vec::new(),
            labels: BTreeMap::new(),
            dont_care: BTreeMap::new(),
        };
        let mut missing = 0;
        for frame in 0..=last {
            let image = drive.join(format!("image_00/data/{frame:010}.png"));
            if !image.is_file() {
                missing += 1;
                continue;
            }
            let i = set.images.len();
            set.images.push(image);
            set.frame_ids.push(frame);
            for l in all.iter().filter(|l| l.frame == frame) {
                if l.is_dont_care() {
                    set.dont_care.entry(i).or_default().push(l.bbox);
                    continue;
                }
                let vehicle = matches!(l.kind.as_str(), "Car" | "Van" | "Truck");
                if !vehicle || l.occluded > MAX_OCCLUSION || l.bbox.height() < MIN_BOX_HEIGHT_PX {
                    continue;
                }
                let centre = Vector4::new(l.location[0], l.location[1] - l.dimensions[0] / 2.0, l.location[2], 1.0);
                let (Some(a), Some(b)) = (project(&p2, &centre), project(&p0, &centre)) else { continue };
                let (du, dv) = (b[0] - a[0], b[1] - a[1]);
                let bb = l.bbox;
                set.labels.entry(i).or_default().push(BBox::new(
                    bb.xmin + du,
                    bb.ymin + dv,
                    bb.xmax + du,
                    bb.ymax + dv,
                ));
            }
        }
        Ok((set, missing))
    }

    /// Number of labelled vehicles.
    pub fn label_count(&self) -> usize {
        self.labels.values().map(|v| v.len()).sum()
    }

    /// Vehicles of frame `i` found among `detections` (car, truck and bus detections count).
    pub fn found(&self, i: usize, detections: &[Detection]) -> usize {
        self.score(i, detections).found
    }

    /// Frame `i` scored: its labels, the vehicle predictions (car, truck and bus detections), those
    /// matched one-to-one at IoU ≥ [`MATCH_IOU`] (best overlaps first), and of the unmatched ones those
    /// lying at least [`DONT_CARE_COVER`] inside one DontCare region.
    pub fn score(&self, i: usize, detections: &[Detection]) -> Counts {
        let vehicles: Vec<BBox> = detections.iter().filter(|d| is_vehicle(d.class)).map(|d| d.bbox).collect();
        let labels = self.labels.get(&i).map(|v| v.as_slice()).unwrap_or(&[]);
        let pairs = matched_pairs(labels, &vehicles, |iou| iou >= MATCH_IOU);
        let mut used = vec![false; vehicles.len()];
        for &(_, j) in &pairs {
            used[j] = true;
        }
        let regions = self.dont_care.get(&i).map(|v| v.as_slice()).unwrap_or(&[]);
        let in_dont_care = vehicles
            .iter()
            .zip(&used)
            .filter(|(v, u)| {
                !**u && regions
                    .iter()
                    .any(|r| v.intersection(r).is_some_and(|x| x.area() >= DONT_CARE_COVER * v.area()))
            })
            .count();
        Counts { labels: labels.len(), found: pairs.len(), predictions: vehicles.len(), in_dont_care }
    }
}

/// Pixel of a homogeneous camera-0 point under a rectified projection matrix (`None` behind it).
fn project(p: &Matrix3x4<f64>, x: &Vector4<f64>) -> Option<[f64; 2]> {
    let h = p * x;
    (h.z > 1e-6).then(|| [h.x / h.z, h.y / h.z])
}

/// Whether a detected class counts as a vehicle for the Car / Van / Truck labels.
pub fn is_vehicle(class: ClassId) -> bool {
    [classes::CAR, classes::TRUCK, classes::BUS].contains(&class)
}

/// The Car and Van boxes and the DontCare regions of a KITTI object label file.
fn object_labels(label: &Path) -> Result<(Vec<BBox>, Vec<BBox>), EvalError> {
    let text = slam_core::files::read_text(label, &slam_core::files::TABLE)?;
    let (mut boxes, mut dont_care) = (Vec::new(), Vec::new());
    for (ln, line) in text.lines().enumerate() {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 8 {
            return Err(EvalError::Invalid(format!("{}:{}: expected a KITTI object label", label.display(), ln + 1)));
        }
        if f[0] == "Car" || f[0] == "Van" || f[0] == "DontCare" {
            let v: Vec<f64> = f[4..8]
                .iter()
                .map(|s| s.parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| EvalError::Invalid(format!("{}:{}: bad box: {e}", label.display(), ln + 1)))?;
            let b = BBox::new(v[0], v[1], v[2], v[3]);
            if f[0] == "DontCare" {
                dont_care.push(b)
            } else {
                boxes.push(b)
            }
        }
    }
    Ok((boxes, dont_care))
}

/// Greedy one-to-one matching of labelled boxes to detections at IoU ≥ [`MATCH_IOU`], best overlaps
/// first (ties by index, so the count is deterministic); returns the matched count.
pub fn matched(labels: &[BBox], dets: &[BBox]) -> usize {
    matched_pairs(labels, dets, |iou| iou >= MATCH_IOU).len()
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

    #[test]
    fn predictions_count_as_right_wrong_or_in_a_dont_care_region() {
        let car = |b: [f64; 4]| Detection::new(classes::CAR, 0.9, BBox::from_array(b));
        let set = RecallSet {
            images: vec![PathBuf::from("a.png")],
            frame_ids: vec![0],
            labels: BTreeMap::from([(0, vec![BBox::new(100.0, 100.0, 200.0, 160.0)])]),
            dont_care: BTreeMap::from([(0, vec![BBox::new(600.0, 100.0, 800.0, 200.0)])]),
        };
        let c = set.score(
            0,
            &[
                car([102.0, 101.0, 199.0, 160.0]),                                      // the label
                car([104.0, 100.0, 200.0, 158.0]),                                      // the same car again: wrong
                car([650.0, 120.0, 700.0, 150.0]), // inside the DontCare region: not counted
                car([790.0, 120.0, 840.0, 150.0]), // a fifth of it inside: wrong
                Detection::new(ClassId(0), 0.9, BBox::new(300.0, 100.0, 320.0, 160.0)), // a person: no vehicle
            ],
        );
        assert_eq!(c, Counts { labels: 1, found: 1, predictions: 4, in_dont_care: 1 });
        assert_eq!((c.wrong(), c.recall(), c.precision()), (2, Some(1.0), Some(1.0 / 3.0)));
        assert_eq!(Counts::default().precision(), None, "no prediction: no precision, not NaN");
    }

    #[test]
    fn drive_0005_targets_follow_the_protocol_and_sit_in_camera_0() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures");
        let drive = root.join("kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync");
        let (set, missing) =
            RecallSet::load_drive(&drive, &root.join("kitti_tracking/0000/label_02.txt")).expect("fixture loads");
        // the 91 grey frames of the excerpt; the labels of the tracking sequence go on to frame 153
        assert_eq!((set.images.len(), set.frame_ids[90]), (91, 90));
        assert_eq!(missing, 154 - 91);
        // issue 31's count: Car/Van/Truck, occlusion <= 1, >= 25 px tall, frames 0-90
        assert_eq!(set.label_count(), 133);
        assert!(!set.dont_care.is_empty());
        // camera 2 sits 0.06 m left of camera 0 (P_rect_02's 44.86 px m): seen from camera 0 a box lies
        // 44.86 px / depth further left, a few pixels here
        let labels = read_tracking_labels(root.join("kitti_tracking/0000/label_02.txt")).expect("labels");
        let van = labels.iter().find(|l| l.frame == 60 && l.track_id == 0).expect("the van ahead at frame 60");
        let i = set.frame_ids.iter().position(|&f| f == 60).expect("frame 60");
        let moved = set.labels[&i].iter().find(|b| b.iou(&van.bbox) > 0.8).expect("its box");
        let expected = -44.85728 / van.location[2];
        assert!((moved.xmin - van.bbox.xmin - expected).abs() < 0.3, "{moved:?} vs {:?}", van.bbox);
    }
}
