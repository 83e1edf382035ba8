//! Detection files (round trip, malformed input) and ground-truth sources.

use std::{collections::BTreeMap, path::PathBuf};

use slam_core::{geometry::BBox, ClassId, Detection, DetectionSource, Mask};
use slam_dataset::{
    detections::{DetectionFile, GroundTruthDetections, GroundTruthNoise},
    kitti::tracking::read_tracking_labels,
    DatasetError,
};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("slam-dataset-det-{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("dir");
    d.join(name)
}

#[test]
fn file_round_trip_with_masks() {
    let mut frames = BTreeMap::new();
    let mut with_mask = Detection::new(ClassId(2), 0.9, BBox::new(10.0, 5.0, 20.0, 9.0));
    with_mask.mask = Some(Mask::from_box(&with_mask.bbox));
    frames.insert(0, vec![with_mask.clone(), Detection::new(ClassId(0), 0.4, BBox::new(1.0, 1.0, 4.0, 8.0))]);
    frames.insert(7, vec![]);
    let file = DetectionFile { image_size: Some([64, 32]), frames };
    file.write(tmp("d.json")).expect("write");
    let mut back = DetectionFile::read(tmp("d.json")).expect("read");
    assert_eq!(back.frames.len(), 2);
    let d0 = back.detect(0, None).expect("frame 0");
    assert_eq!(d0[0].bbox, with_mask.bbox);
    let m = d0[0].mask.as_ref().expect("mask");
    assert_eq!(m.area(), with_mask.mask.as_ref().expect("mask").area());
    assert!(back.detect(3, None).expect("absent frame").is_empty());
}

#[test]
fn malformed_files_are_errors() {
    let cases = [
        ("syntax", r#"{"version": 1, "frames": [ {"frame": 0, "detections": [}"#),
        (
            "nanbox",
            r#"{"version": 1, "frames": [{"frame": 0, "detections": [{"class": 2, "score": 0.5, "box": [5, 5, 1, 9]}]}]}"#,
        ),
        (
            "score",
            r#"{"version": 1, "frames": [{"frame": 0, "detections": [{"class": 2, "score": 1.5, "box": [1, 1, 5, 9]}]}]}"#,
        ),
        (
            "rle",
            r#"{"version": 1, "frames": [{"frame": 0, "detections": [{"class": 2, "score": 0.5, "box": [1, 1, 5, 9], "mask": {"rle": {"size": [3, 4], "counts": [1, 2]}}}]}]}"#,
        ),
        ("version", r#"{"version": 9, "frames": []}"#),
        ("unknown", r#"{"version": 1, "frames": [], "extra": 1}"#),
        ("dup", r#"{"version": 1, "frames": [{"frame": 0, "detections": []}, {"frame": 0, "detections": []}]}"#),
        ("missing", r#"{"version": 1, "frames": [{"frame": 0, "detections": [{"class": 2, "box": [1, 1, 5, 9]}]}]}"#),
    ];
    for (name, text) in cases {
        std::fs::write(tmp(name), text).expect("write");
        let e = DetectionFile::read(tmp(name)).expect_err(name);
        assert!(
            e.to_string().contains(name) || matches!(e, DatasetError::Parse { .. } | DatasetError::Invalid { .. }),
            "{name}: {e}"
        );
    }
    std::fs::write(tmp("empty"), "").expect("write");
    assert!(DetectionFile::read(tmp("empty")).is_err());
    // a top-level array (the frames without their object) is named as such, with the line
    std::fs::write(tmp("array"), "\n [{\"frame\": 0, \"detections\": []}]").expect("write");
    let e = DetectionFile::read(tmp("array")).expect_err("array").to_string();
    assert!(e.contains("array:2: the file is an array: a detection file is one object"), "{e}");
    // a UTF-8 byte-order mark, as some editors write it, is no error
    std::fs::write(tmp("bom"), "\u{feff}{\"version\": 1, \"frames\": [{\"frame\": 3, \"detections\": []}]}")
        .expect("write");
    assert_eq!(DetectionFile::read(tmp("bom")).expect("a BOM").frames.len(), 1);
}

#[test]
fn ground_truth_source_is_seeded_and_noisy() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/kitti_tracking/0000/label_02.txt");
    let labels = read_tracking_labels(path).expect("labels");
    let clean = GroundTruthNoise::default();
    let mut s = GroundTruthDetections::from_tracking_labels(&labels, clean, [1242.0, 375.0]);
    let d = s.detect(0, None).expect("frame 0");
    assert_eq!(d.len(), 3); // frame 0: Van, Cyclist, Pedestrian (2 DontCare dropped)
    let noisy = GroundTruthNoise { box_sigma: 0.05, dropout: 0.3, false_positives: 1.0, seed: 7 };
    let mut a = GroundTruthDetections::from_tracking_labels(&labels, noisy, [1242.0, 375.0]);
    let mut b = GroundTruthDetections::from_tracking_labels(&labels, noisy, [1242.0, 375.0]);
    let (mut total, mut kept) = (0, 0);
    for f in (0..150).rev() {
        let x = a.detect(f, None).expect("a");
        assert_eq!(x, b.detect(f, None).expect("b"), "frame {f}");
        total += s.detect(f, None).expect("clean").len();
        kept += x.len();
        assert!(x.iter().all(|d| d.bbox.validated().is_ok() && d.bbox.xmax <= 1242.0));
    }
    // 30 % dropout, about one false box per frame
    assert!(kept > total / 2 && kept < total + 200, "kept {kept} of {total}");
}

#[test]
fn tracklets_as_detections() {
    use slam_dataset::kitti::{raw::RawCalib, tracklets::read_tracklets};
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/kitti_raw_0001/2011_09_26");
    let t = read_tracklets(root.join("2011_09_26_drive_0001_sync/tracklet_labels.xml")).expect("tracklets");
    let calib = RawCalib::read(&root).expect("calib");
    let mut s = GroundTruthDetections::from_tracklets(&t, &calib, GroundTruthNoise::default());
    // frame 0: the first car is 25 m ahead and 8.6 m to the left: a box left of the image centre
    let d = s.detect(0, None).expect("frame 0");
    assert!(!d.is_empty());
    assert!(d.iter().all(|x| x.bbox.validated().is_ok() && x.bbox.xmax <= 1242.0 && x.bbox.ymax <= 375.0));
    assert!(d.iter().any(|x| x.bbox.xmax < 609.0), "{d:?}");
}
