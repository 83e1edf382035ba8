//! Both KITTI tracking layouts.

use std::path::PathBuf;

use slam_dataset::{kitti::tracking::TrackingSequence, DatasetError};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures")
}

#[test]
fn image_free_layout() {
    let s = TrackingSequence::open_image_free(fixtures().join("kitti_tracking/0000")).expect("opens");
    assert_eq!(s.labels.len(), 1089);
    assert_eq!(s.poses.as_ref().map(|p| p.len()), Some(154));
    let t2 = s.cam2_offset().expect("P2");
    assert!((t2.x - 0.0598).abs() < 1e-3, "{t2}");
}

#[test]
fn official_layout() {
    let t = std::env::temp_dir().join(format!("tracking-official-{}", std::process::id())).join("training");
    for d in ["image_02/0000", "label_02", "calib", "oxts"] {
        std::fs::create_dir_all(t.join(d)).expect("dir");
    }
    let src = fixtures().join("kitti_tracking/0000");
    std::fs::copy(src.join("label_02.txt"), t.join("label_02/0000.txt")).expect("labels");
    std::fs::copy(src.join("calib.txt"), t.join("calib/0000.txt")).expect("calib");
    for i in 0..3 {
        std::fs::write(t.join(format!("image_02/0000/{i:06}.png")), b"x").expect("img");
    }
    let packet = std::fs::read_to_string(
        fixtures().join("kitti_raw_0001/2011_09_26/2011_09_26_drive_0001_sync/oxts/data/0000000000.txt"),
    )
    .expect("oxts");
    std::fs::write(t.join("oxts/0000.txt"), format!("{}\n{}\n", packet.trim(), packet.trim())).expect("oxts");
    let s = TrackingSequence::open_official(&t, "0000").expect("opens");
    assert_eq!(s.images.len(), 3);
    assert_eq!(s.imu_poses.as_ref().map(|p| p.len()), Some(2));
    // a malformed OXTS line names its line
    std::fs::write(t.join("oxts/0000.txt"), format!("{}\n1 2 3\n", packet.trim())).expect("oxts");
    match TrackingSequence::open_official(&t, "0000") {
        Err(DatasetError::Parse { line, .. }) => assert_eq!(line, 2),
        other => panic!("expected a parse error, got {other:?}"),
    }
    assert!(matches!(TrackingSequence::open_official(&t, "0001"), Err(DatasetError::Io { .. })));
}
