//! KITTI odometry layout (built in a temporary folder) and trajectory round trips.

use std::path::PathBuf;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use slam_dataset::{
    kitti::odometry::OdometrySequence,
    trajectory::{read_kitti_poses, read_tum, write_kitti_poses, write_tum},
    DatasetError,
};

fn root() -> PathBuf {
    let r = std::env::temp_dir().join(format!("slam-dataset-odom-{}", std::process::id()));
    std::fs::create_dir_all(&r).expect("dir");
    r
}

#[test]
fn odometry_layout_with_partial_calib() {
    let r = root().join("a");
    let seq = r.join("sequences/06");
    for d in ["image_0", "image_1"] {
        std::fs::create_dir_all(seq.join(d)).expect("dir");
        for i in 0..3 {
            std::fs::write(seq.join(d).join(format!("{i:06}.png")), b"x").expect("img");
        }
    }
    std::fs::write(
        seq.join("calib.txt"),
        "P0: 7.07e+02 0 6.01e+02 0 0 7.07e+02 1.83e+02 0 0 0 1 0\nP1: 7.07e+02 0 6.01e+02 -3.79e+02 0 7.07e+02 1.83e+02 0 0 0 1 0\n",
    )
    .expect("calib");
    let s = OdometrySequence::open(&seq).expect("opens");
    assert_eq!(s.left.len(), 3);
    assert!(s.p_colour.is_none() && s.tr.is_none() && s.ground_truth.is_none());
    assert!((s.baseline() - 379.0 / 707.0).abs() < 1e-12);
    assert!((s.times[2] - 0.2).abs() < 1e-12);
    // times and ground truth
    std::fs::write(seq.join("times.txt"), "0.0\n0.1036\n0.2073\n").expect("times");
    std::fs::create_dir_all(r.join("poses")).expect("dir");
    std::fs::write(
        r.join("poses/06.txt"),
        "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0.8\n1 0 0 0 0 1 0 0 0 0 1 1.6\n",
    )
    .expect("gt");
    let s = OdometrySequence::open(&seq).expect("opens");
    assert!((s.times[1] - 0.1036).abs() < 1e-12);
    assert_eq!(s.ground_truth.as_ref().map(|g| g.len()), Some(3));
    // a right image missing keeps the frame (played as unreadable); no right image at all is an error
    std::fs::remove_file(seq.join("image_1/000002.png")).expect("rm");
    let s = OdometrySequence::open(&seq).expect("opens");
    assert_eq!((s.ids.len(), s.one_camera.clone()), (3, vec![2]));
    for i in 0..2 {
        std::fs::remove_file(seq.join(format!("image_1/{i:06}.png"))).expect("rm");
    }
    let e = OdometrySequence::open(&seq).expect_err("no pair");
    assert!(matches!(&e, DatasetError::Invalid { .. }) && e.to_string().contains("no frame has both"), "{e}");
    // a malformed calib is an error
    std::fs::write(seq.join("calib.txt"), "P0: 1 2 3\n").expect("calib");
    assert!(OdometrySequence::open(&seq).is_err());
}

#[test]
fn trajectories_round_trip() {
    let poses: Vec<Isometry3<f64>> = (0..5)
        .map(|i| {
            Isometry3::from_parts(
                Translation3::new(i as f64, 0.5, -2.0 * i as f64),
                UnitQuaternion::from_euler_angles(0.1 * i as f64, 0.2, -0.3),
            )
        })
        .collect();
    let t: Vec<f64> = (0..5).map(|i| 0.1 * i as f64).collect();
    let dir = root();
    write_tum(dir.join("t.tum.txt"), &t, &poses).expect("write");
    let (t2, p2) = read_tum(dir.join("t.tum.txt")).expect("read");
    write_kitti_poses(dir.join("t.kitti.txt"), &poses).expect("write");
    let p3 = read_kitti_poses(dir.join("t.kitti.txt")).expect("read");
    for i in 0..5 {
        assert!((t2[i] - t[i]).abs() < 1e-9);
        assert!((p2[i].to_homogeneous() - poses[i].to_homogeneous()).norm() < 1e-8);
        assert!((p3[i].to_homogeneous() - poses[i].to_homogeneous()).norm() < 1e-8);
    }
    assert!(write_tum(dir.join("bad.txt"), &t[..2], &poses).is_err());
    std::fs::write(dir.join("bad.tum"), "# c\n0 1 2 3 0 0 0 1\n0 1 2 3 0 0 0 2\n").expect("w");
    assert!(matches!(read_tum(dir.join("bad.tum")), Err(DatasetError::Parse { line: 3, .. })));
}
