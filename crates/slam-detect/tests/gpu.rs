//! The detector on ONNX Runtime's CUDA execution provider. It needs an NVIDIA GPU and the
//! `onnxruntime-gpu` runtime (tools/setup.sh installs it where nvidia-smi lists a GPU), so it is ignored
//! by a plain `cargo test`, which names it as skipped; tools/test.sh runs it (`--ignored`) where
//! nvidia-smi lists a GPU. In a process of its own: a process opens one ONNX Runtime library.

use std::path::PathBuf;

use slam_core::{geometry::BBox, DetectionSource};
use slam_detect::{DetectorConfig, Device, DnnDetector, RuntimeOptions};
use slam_frontend::read_image;

fn repo(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel)
}

#[test]
#[ignore = "needs an NVIDIA GPU and the onnxruntime-gpu runtime: tools/test.sh runs it where nvidia-smi lists a GPU"]
fn cuda_finds_the_van() {
    let frame = repo("fixtures/kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync/image_00/data/0000000050.png");
    let img = read_image(frame, false).expect("reads");
    let model = repo("fixtures/yolox_nano/yolox_nano.onnx");
    let runtime = RuntimeOptions { device: Device::Cuda, ..RuntimeOptions::cpu(repo(".ort")) };
    let mut det = DnnDetector::from_onnx(&model, DetectorConfig::yolox(), &runtime).unwrap_or_else(|e| panic!("{e}"));
    let d = det.detect(50, Some(&img)).expect("runs");
    // as on the CPU (tests/detector.rs): the parked van, once, and only valid boxes
    let van = BBox::new(844.1 - 1.8, 150.9, 990.2 - 1.8, 225.0);
    let found: Vec<_> = d.iter().filter(|x| x.bbox.iou(&van) > 0.8).collect();
    assert!(found.len() == 1 && found[0].class.group() == 2 && found[0].score > 0.6, "{d:?}");
    assert!(d.iter().all(|x| x.bbox.validated().is_ok() && x.bbox.xmax <= 1242.0 && x.score >= 0.4));
    assert!(det.forward_ms().is_some_and(|ms| ms > 0.0));
}
