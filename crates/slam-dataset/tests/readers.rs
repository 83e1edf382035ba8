//! Readers on the shipped KITTI tracking fixtures and on malformed input.

use std::path::PathBuf;

use slam_dataset::{
    classes,
    kitti::{calib::Calib, poses::read_kitti_poses, tracking::read_tracking_labels},
    DatasetError,
};

fn fixture(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/kitti_tracking").join(rel)
}

#[test]
fn sequence_0000() {
    let labels = read_tracking_labels(fixture("0000/label_02.txt")).expect("labels");
    assert_eq!(labels.len(), 1089); // META.md: 1089 lines
    let cars = labels.iter().filter(|l| l.kind == "Car").count();
    assert_eq!(cars, 243);
    let van = &labels[2];
    assert_eq!((van.frame, van.track_id, van.kind.as_str()), (0, 0, "Van"));
    assert_eq!(van.class, Some(classes::CAR));
    assert!((van.bbox.xmin - 296.744956).abs() < 1e-9 && (van.location[2] - 13.410495).abs() < 1e-9);
    assert!(labels[0].is_dont_care() && labels[0].class.is_none());
    let poses = read_kitti_poses(fixture("0000/poses_orbslam3.txt")).expect("poses");
    assert_eq!(poses.len(), 154);
    assert!(poses[0].translation.vector.norm() < 1e-12);
    let calib = Calib::read(fixture("0000/calib.txt")).expect("calib");
    let p2 = calib.matrix3x4("P2").expect("P2");
    assert!((p2[(0, 0)] - 721.5377).abs() < 1e-9 && (p2[(0, 3)] - 44.85728).abs() < 1e-9);
    assert!(calib.matrix3x4("P9").is_err());
    assert!(calib.has("R0_rect") && calib.matrix3("R0_rect").is_ok());
}

fn write_tmp(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("slam-dataset-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write");
    p
}

fn parse_line(e: DatasetError) -> usize {
    match e {
        DatasetError::Parse { line, .. } => line,
        other => panic!("expected a parse error, got {other}"),
    }
}

#[test]
fn malformed_labels_name_the_line() {
    let good = "0 0 Car 0 0 -1.5 10 20 50 60 1.5 1.6 3.9 1.0 1.7 20.0 0.1\n";
    let cases: [(&str, String); 5] = [
        ("truncated", format!("{good}0 1 Car 0 0 -1.5 10 20\n")),
        (
            "nan",
            format!(
                "{good}{}0 1 Car 0 0 -1.5 10 20 nan 60 1.5 1.6 3.9 1.0 1.7 20.0 0.1\n",
                good.replacen("0 0 Car", "0 2 Car", 1)
            ),
        ),
        ("word", "x 1 Car 0 0 -1.5 10 20 50 60 1.5 1.6 3.9 1.0 1.7 20.0 0.1\n".to_string()),
        ("emptybox", format!("{good}0 1 Car 0 0 -1.5 50 20 50 60 1.5 1.6 3.9 1.0 1.7 20.0 0.1\n")),
        ("inf", format!("{good}0 1 Car 0 0 -1.5 10 20 inf 60 1.5 1.6 3.9 1.0 1.7 20.0 0.1\n")),
    ];
    let expected = [2, 3, 1, 2, 2];
    for ((name, text), line) in cases.iter().zip(expected) {
        let p = write_tmp(&format!("{name}.txt"), text.as_bytes());
        let e = read_tracking_labels(&p).expect_err(name);
        assert!(e.to_string().contains(&p.display().to_string()), "{e}");
        assert_eq!(parse_line(e), line, "{name}");
    }
    // a track id below -1, a DontCare with a track, one track twice in a frame, a box 10^12 m away
    let bad: [(&str, String, &str); 4] = [
        ("below", good.replacen("0 0 Car", "0 -2 Car", 1), "track id -2 for a Car"),
        ("dontcare", good.replacen("0 0 Car", "0 3 DontCare", 1), "-1 marks a DontCare region"),
        ("twice", format!("{good}{good}"), "track 0 again in frame 0 (first on line 1)"),
        ("far", good.replacen(" 20.0 0.1", " 1e12 0.1", 1), "location coordinate 1.000e12 m"),
    ];
    for (name, text, want) in bad {
        let p = write_tmp(&format!("{name}.txt"), text.as_bytes());
        let e = read_tracking_labels(&p).expect_err(name).to_string();
        assert!(e.contains(want), "{name}: {e}");
    }
    // the same track in two frames, and DontCare regions (-1) any number of times, are fine
    let two = format!(
        "{good}{}{}{}",
        good.replacen("0 0 Car", "1 0 Car", 1),
        "0 -1 DontCare -1 -1 -10 1 2 3 4 -1 -1 -1 -1000 -1000 -1000 -10\n",
        "0 -1 DontCare -1 -1 -10 5 6 7 8 -1 -1 -1 -1000 -1000 -1000 -10\n"
    );
    assert_eq!(read_tracking_labels(write_tmp("two.txt", two.as_bytes())).expect("fine").len(), 4);
    // non-UTF-8
    let p = write_tmp("bin.txt", b"0 0 Car\n\xff\xfe\n");
    assert_eq!(parse_line(read_tracking_labels(&p).expect_err("binary")), 2);
    // empty file: nothing to score against or play as detections, so an error naming it
    let p = write_tmp("empty.txt", b"");
    let e = read_tracking_labels(&p).expect_err("empty");
    assert!(e.to_string().contains("empty.txt") && e.to_string().contains("no labels"), "{e}");
    // missing file
    let e = read_tracking_labels("/nonexistent/label.txt").expect_err("missing");
    assert!(matches!(e, DatasetError::Io { .. }) && e.to_string().contains("/nonexistent/label.txt"));
}

#[test]
fn malformed_poses_and_calib() {
    let p = write_tmp("poses.txt", b"1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0\n");
    assert_eq!(parse_line(read_kitti_poses(&p).expect_err("short")), 2);
    let p = write_tmp("poses2.txt", b"2 0 0 0 0 1 0 0 0 0 1 0\n");
    assert_eq!(parse_line(read_kitti_poses(&p).expect_err("not a rotation")), 1);
    let p = write_tmp("poses3.txt", b"");
    assert!(matches!(read_kitti_poses(&p), Err(DatasetError::Invalid { .. })));
    let p = write_tmp("calib.txt", b"P0: 1 2 3\nP1:\n");
    assert_eq!(parse_line(Calib::read(&p).expect_err("no values")), 2);
    let p = write_tmp("calib2.txt", b"P0: 1 2 3\ncalib_time: 09-Jan-2012 13:57:47\nP2: 1 2 x 4 5 6 7 8 9 10 11 12\n");
    let c = Calib::read(&p).expect("parses");
    assert_eq!(parse_line(c.matrix3x4("P0").expect_err("short")), 1);
    assert_eq!(parse_line(c.matrix3x4("P2").expect_err("not a number")), 3);
    assert!(matches!(c.matrix3x4("P3"), Err(DatasetError::Invalid { .. })));
}
