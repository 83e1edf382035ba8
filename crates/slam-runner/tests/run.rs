//! A few frames of the shipped odometry excerpt through the runner: preparation and its refusals, the
//! header, the run, the files and summary of `run`, and a `track-bench` row.

mod common;

use std::path::PathBuf;

use slam_dataset::kitti::stereo::FrameSelection;
use slam_runner::{bench, prepare, DetectorChoice, RunSettings};

fn settings(frames: usize, stride: usize) -> RunSettings {
    let all = FrameSelection { first: None, end: None, stride };
    common::settings("kitti_odom_06/sequences/06", all, Some(frames))
}

#[test]
fn a_short_run_is_prepared_played_written_and_summarised() {
    let e = prepare(&settings(0, 1)).err().expect("zero frames refused");
    assert_eq!(e.to_string(), "nothing to run: --max-frames 0");

    let s = settings(4, 2);
    let p = prepare(&s).expect("prepares");
    assert_eq!(p.len(), 4);
    let header = p.header(&s);
    assert!(header.contains("4 frames: frame ids 0..=6 every 2 ids"), "{header}");
    assert!(header.contains("detector: none, association: IoU"), "{header}");
    let mut seen = Vec::new();
    let o = p.run(&s, &mut |v| seen.push(v.record.index), || false).expect("runs");
    assert_eq!(seen, [0, 2, 4, 6], "every played frame reported, in id order");
    assert_eq!(o.out.counts.frames, 4);
    assert!(o.detections.is_none() && o.labels.is_none());

    let dir = std::env::temp_dir().join(format!("slam-runner-run-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    o.write_files(&dir, &dir).expect("writes");
    let kitti = std::fs::read_to_string(dir.join("trajectory.kitti.txt")).expect("trajectory");
    assert_eq!(kitti.lines().count(), 4, "one pose per played frame");
    assert_eq!(std::fs::read_to_string(dir.join("tracking.csv")).expect("csv").lines().count(), 5);
    let summary = o.summary(s.system.max_detections);
    assert!(summary.starts_with("4 frames in "), "{summary}");
    assert!(summary.contains("\nground truth: path "), "odometry 06 has ground truth: {summary}");
    assert!(o.score(&dir).expect("no labels").is_none());
    assert!(o.wrote_line(&dir, false, "map.svg").ends_with("map.svg; frame ids 0..=6 every 2 ids"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_track_bench_row_replaces_path_stride_and_detector() {
    let mut base = settings(3, 1);
    base.detector = DetectorChoice::File(PathBuf::from("/nonexistent.json"));
    let case =
        bench::TrackCase { name: "odometry 06 stride 3".into(), path: base.path.clone(), stride: 3, order: None };
    let row = bench::track_row(&base, &case, false).expect("the detector is none in track-bench");
    assert!(row.line.starts_with("| odometry 06 stride 3 | 3 | "), "{}", row.line);
    assert!(row.notes.is_empty(), "ground truth present, not OXTS: {:?}", row.notes);
    // with objects the run keeps the base's detector: here a detection file that does not exist
    bench::track_row(&base, &case, true).expect_err("--objects keeps the detector");
    let missing =
        bench::TrackCase { name: "nowhere".into(), path: PathBuf::from("/nonexistent/seq"), stride: 1, order: None };
    let e = bench::track_row(&base, &missing, false).expect_err("no such sequence");
    assert_eq!(e.to_string(), "case nowhere");
}

/// The ground-truth check flags the interpolated start of the odometry excerpt and nothing of drive
/// 0005's OXTS poses, which are measured throughout (their step rotations change by 0.037° or more).
#[test]
fn the_ground_truth_check_tells_interpolated_from_measured_poses() {
    use slam_eval::trajectory_errors::interpolated_stretches;
    let fixtures = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures");
    let odometry = slam_dataset::kitti::stereo::open_stereo(fixtures.join("kitti_odom_06/sequences/06")).expect("06");
    assert_eq!(interpolated_stretches(&odometry.truth_from_first().expect("06 poses")), vec![(0, 11)]);
    let raw =
        slam_dataset::kitti::stereo::open_stereo(fixtures.join("kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync"))
            .expect("0005");
    let oxts = raw.truth_from_first().expect("OXTS poses");
    assert_eq!(oxts.len(), 91);
    assert!(interpolated_stretches(&oxts).is_empty());
    assert!(interpolated_stretches(&raw.dead_reckoned_from_first().expect("INS")).is_empty());
}
