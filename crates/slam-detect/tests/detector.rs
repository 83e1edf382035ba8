//! The detector on the shipped fixtures (Yolo-Fastest on OpenCV's dnn module, YOLOX-nano on ONNX
//! Runtime), missing and broken models as errors naming the file, and non-maximum suppression.

use std::path::PathBuf;

use slam_core::{geometry::BBox, ClassId, Detection, DetectionSource, Image};
use slam_detect::{
    detector::{nms, nms_by_group},
    DetectorConfig, DetectorError, DnnDetector, InputMode, RuntimeOptions,
};
use slam_frontend::read_image;

fn fixture(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures").join(rel)
}

/// ONNX Runtime as `tools/setup.sh` installs it (the CPU, one thread).
fn runtime() -> RuntimeOptions {
    RuntimeOptions::cpu(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../.ort"))
}

fn frame7() -> PathBuf {
    fixture("kitti_raw_0052/2011_09_26/2011_09_26_drive_0052_sync/image_02/data/0000000007.png")
}

fn detector(mode: InputMode) -> DnnDetector {
    DnnDetector::from_darknet(
        fixture("detector/yolo-fastest-1.1.cfg"),
        fixture("detector/yolo-fastest-1.1.weights"),
        DetectorConfig { mode, ..DetectorConfig::yolo_fastest() },
    )
    .expect("model loads")
}

#[test]
fn detector_finds_the_car_ahead() {
    let img = read_image(frame7(), true).expect("reads");
    let mut det = detector(InputMode::Tiles(3));
    let d = det.detect(7, Some(&img)).expect("runs");
    // the labelled car ahead at frame 7: [556, 185, 714, 335]
    let ahead = BBox::new(556.06, 185.21, 714.24, 334.53);
    assert!(d.iter().any(|x| x.class == ClassId(2) && x.bbox.iou(&ahead) > 0.7), "{d:?}");
    assert!(d.iter().all(|x| x.bbox.validated().is_ok() && x.bbox.xmax <= 1242.0 && (0.0..=1.0).contains(&x.score)));
    // deterministic
    assert_eq!(d, det.detect(7, Some(&img)).expect("runs"));
    // needs the image; a black frame gives no car
    assert!(det.detect(0, None).is_err());
    let black = Image::new(1242, 375, 3, vec![0; 1242 * 375 * 3]).expect("image");
    assert!(det.detect(1, Some(&black)).expect("runs").iter().all(|x| x.score < 0.5));
}

/// The shipped YOLOX-nano on ONNX Runtime, on drive 0005's grey frame 50 (camera 0), finds the parked van,
/// labelled at [844, 151, 990, 225] in camera 2 (1.8 px further right than in camera 0 at its 25 m).
#[test]
fn yolox_finds_the_parked_van_on_a_grey_frame() {
    let frame = fixture("kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync/image_00/data/0000000050.png");
    let img = read_image(frame, false).expect("reads");
    assert_eq!(img.channels, 1, "the grey camera");
    let model = fixture("yolox_nano/yolox_nano.onnx");
    let mut det = DnnDetector::from_onnx(model, DetectorConfig::yolox(), &runtime()).expect("loads");
    assert!(det.on_onnx_runtime() && det.forward_ms().is_none());
    let start = std::time::Instant::now();
    let d = det.detect(50, Some(&img)).expect("runs");
    let whole = start.elapsed().as_secs_f64() * 1e3;
    // the forward pass is timed apart from the pre- and post-processing around it
    let forward = det.forward_ms().expect("timed");
    assert!(forward > 0.0 && forward < whole, "forward {forward} ms of {whole} ms");
    let van = BBox::new(844.1 - 1.8, 150.9, 990.2 - 1.8, 225.0);
    let found: Vec<&Detection> = d.iter().filter(|x| x.bbox.iou(&van) > 0.8).collect();
    assert!(found.len() == 1 && found[0].class.group() == 2 && found[0].score > 0.6, "{d:?}");
    assert!(d.iter().all(|x| x.bbox.validated().is_ok() && x.bbox.xmax <= 1242.0 && x.score >= 0.4));
    assert_eq!(d, det.detect(50, Some(&img)).expect("runs"), "deterministic");
}

#[test]
fn missing_models_are_errors() {
    let e = DnnDetector::from_darknet("/no/model.cfg", "/no/model.weights", DetectorConfig::default())
        .err()
        .expect("missing");
    assert!(e.to_string().contains("/no/model.cfg"));
    let missing = DnnDetector::from_onnx("/no/model.onnx", DetectorConfig::default(), &runtime()).err();
    assert!(missing.expect("missing").to_string().contains("/no/model.onnx"));
    let junk = std::env::temp_dir().join(format!("junk-{}.onnx", std::process::id()));
    std::fs::write(&junk, b"not a model").expect("write");
    let e = DnnDetector::from_onnx(&junk, DetectorConfig::default(), &runtime()).err().expect("junk");
    assert!(matches!(&e, DetectorError::Model { path, .. } if *path == junk), "{e}");
}

#[test]
fn nms_is_classwise_and_deterministic() {
    let a = Detection::new(ClassId(2), 0.9, BBox::new(0.0, 0.0, 10.0, 10.0));
    let b = Detection::new(ClassId(2), 0.8, BBox::new(1.0, 0.0, 11.0, 10.0));
    let c = Detection::new(ClassId(7), 0.7, BBox::new(1.0, 0.0, 11.0, 10.0));
    let kept = nms(vec![b.clone(), c.clone(), a.clone()], 0.45);
    assert_eq!(kept, vec![a.clone(), c.clone()]);
    // by class group the truck box is the same vehicle; a person over it is not
    let p = Detection::new(ClassId(0), 0.6, BBox::new(1.0, 0.0, 11.0, 10.0));
    assert_eq!(nms_by_group(vec![p.clone(), b, c, a.clone()], 0.45), vec![a, p]);
}
