//! A user's own recording through the runner: the shipped kitti2mcap bag against the KITTI folder it
//! was made from, the same bag with PNG-compressed images, the distorted odometry 06 rectified back
//! (ORB-SLAM's exact rectification gives the original images; Kalibr's is row-aligned), and a run's
//! MCAP file read back.

mod common;

use std::path::{Path, PathBuf};

use slam_dataset::{
    kitti::stereo::FrameSelection,
    recording::{open_sequence, SourceOptions},
    ros::{bag::Bag, cdr::CdrReader, msgs},
};
use slam_runner::{prepare, Outcome, RunSettings};

fn temp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("recording-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("dir");
    d
}

const BAG: &str = "ros2_bag_0005/drive_0005_frames_0-4.mcap";
const DRIVE: &str = "kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync";

fn play(s: &RunSettings) -> Outcome {
    prepare(s).expect("prepares").run(s, &mut |_| {}, || false).expect("runs")
}

fn settings_at(path: &Path, frames: Option<usize>) -> RunSettings {
    RunSettings { path: path.to_path_buf(), ..common::settings(DRIVE, FrameSelection::default(), frames) }
}

#[test]
fn the_bag_tracks_as_its_kitti_folder_raw_and_png_compressed() {
    let kitti = play(&common::settings(DRIVE, FrameSelection::default(), Some(5)));
    let raw = play(&settings_at(&common::fixture(BAG), None));
    assert_eq!(raw.out.poses.len(), 5);
    assert_eq!(raw.out.counts.tracked, kitti.out.counts.tracked);
    assert_eq!(raw.out.counts.tracked, 4, "every frame after the first is tracked");
    // the same pixels, calibration and frame times: the same trajectory to the last bit
    assert_eq!(raw.out.poses, kitti.out.poses);
    assert_eq!(raw.out.map.points.len(), kitti.out.map.points.len());
    // the same bag with its images as PNG in CompressedImage messages
    let dir = temp("png");
    let png = dir.join("png.mcap");
    slam_runner::bag_edit::edit_bag(
        &common::fixture(BAG),
        &png,
        slam_runner::bag_edit::BagEdit { png: true, repeat: 1 },
    )
    .expect("re-encodes");
    let b = Bag::open(&png).expect("opens");
    let left = b.topic("/kitti/camera_gray_left/image_raw/compressed").expect("compressed topic");
    assert_eq!((left.schema.as_str(), left.count), (msgs::COMPRESSED_IMAGE, 5));
    assert!(b.topic("/kitti/camera_gray_left/image_raw").is_none());
    let compressed = play(&settings_at(&png, None));
    assert_eq!(compressed.out.poses, kitti.out.poses);
}

#[test]
fn a_run_written_as_mcap_reads_back_with_its_types_and_counts() {
    let o = play(&settings_at(&common::fixture(BAG), None));
    let dir = temp("results");
    let path = dir.join("run.mcap");
    let line = slam_runner::ros_output::write_results_mcap(&o, &path).expect("writes");
    assert!(line.contains("/tf (5 poses)"), "{line}");
    let b = Bag::open(&path).expect("reads back");
    let types: Vec<(&str, &str, usize)> =
        b.topics.iter().map(|t| (t.name.as_str(), t.schema.as_str(), t.count)).collect();
    assert_eq!(
        types,
        vec![
            ("/slam/map_points", msgs::POINT_CLOUD, 1),
            ("/slam/objects", msgs::MARKERS, 1),
            ("/slam/trajectory", msgs::PATH, 1),
            ("/tf", msgs::TF, 5),
        ]
    );
    // on the bag's time line: the /tf stamps are the left images' header stamps
    let first = o.seq.recording.as_ref().and_then(|r| r.bag.as_ref()).expect("bag").frames[0].left.stamp_ns;
    assert_eq!(b.topic("/tf").and_then(|t| t.span_ns).map(|s| s.0), Some(first));
    // the path holds every pose; its last is the trajectory's last
    let data = read_only_message(&path, "/slam/trajectory");
    let mut r = CdrReader::new(&data).expect("cdr");
    let _ = (r.i32("sec"), r.u32("nanosec"), r.string("frame"));
    assert_eq!(r.u32("poses").expect("count"), 5);
    // the point cloud holds every map point
    let data = read_only_message(&path, "/slam/map_points");
    let mut r = CdrReader::new(&data).expect("cdr");
    let _ = (r.i32("sec"), r.u32("nanosec"), r.string("frame"), r.u32("height"));
    assert_eq!(r.u32("width").expect("width") as usize, o.out.map.points.len());
    // readers that go by the index find every channel and schema in the summary
    let bytes = std::fs::read(&path).expect("read");
    let summary = mcap::Summary::read(&bytes).expect("summary").expect("a summary");
    let mut indexed = std::collections::BTreeMap::new();
    for chunk in &summary.chunk_indexes {
        for m in summary.stream_chunk(&bytes, chunk).expect("chunk") {
            let m = m.expect("a message whose channel the summary holds");
            let schema = m.channel.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default();
            *indexed.entry((m.channel.topic.clone(), schema)).or_insert(0usize) += 1;
        }
    }
    let counted: std::collections::BTreeMap<(String, String), usize> =
        types.iter().map(|(t, s, n)| ((t.to_string(), s.to_string()), *n)).collect();
    assert_eq!(indexed, counted);
    // the same run writes the same messages
    let again = dir.join("again.mcap");
    slam_runner::ros_output::write_results_mcap(&o, &again).expect("writes");
    assert_eq!(all_messages(&path), all_messages(&again), "two writes differ");
}

/// Every message of a file in order: topic, log time and bytes.
fn all_messages(path: &Path) -> Vec<(String, u64, Vec<u8>)> {
    let bytes = std::fs::read(path).expect("read");
    mcap::MessageStream::new(&bytes)
        .expect("stream")
        .map(|m| m.expect("message"))
        .map(|m| (m.channel.topic.clone(), m.log_time, m.data.into_owned()))
        .collect()
}

/// The bytes of the one message of `topic` in a file (a bag index holds images only: the file is read
/// with the crate's own reader here).
fn read_only_message(path: &Path, topic: &str) -> Vec<u8> {
    let bytes = std::fs::read(path).expect("read");
    let mut found = Vec::new();
    for m in mcap::MessageStream::new(&bytes).expect("stream") {
        let m = m.expect("message");
        if m.channel.topic == topic {
            found.push(m.data.into_owned());
        }
    }
    assert_eq!(found.len(), 1, "{topic}");
    found.remove(0)
}

/// How well a rectified image lines up with the original: over 32 × 32 patches on a grid at least
/// `margin` from the border (and with texture: a flat patch lines up at any shift), the integer shift
/// within ±2 px that matches best (least sum of squared differences), and the patches' mean absolute
/// difference at no shift. Returns (patches looked at, patches that match best unshifted, mean
/// absolute difference in grey levels).
fn alignment(rect: &slam_core::Image, orig: &slam_core::Image, margin: usize) -> (usize, usize, f64) {
    assert_eq!((rect.width, rect.height, rect.channels), (orig.width, orig.height, orig.channels));
    let (w, h, c) = (orig.width as usize, orig.height as usize, orig.channels as usize);
    let at = |img: &slam_core::Image, x: usize, y: usize| f64::from(img.data[(y * w + x) * c]);
    const P: usize = 32;
    let (mut looked, mut unshifted, mut diff, mut n) = (0, 0, 0.0, 0usize);
    let mut y = margin;
    while y + P + margin <= h {
        let mut x = margin;
        while x + P + margin <= w {
            let mean = (0..P * P).map(|i| at(orig, x + i % P, y + i / P)).sum::<f64>() / (P * P) as f64;
            let var = (0..P * P).map(|i| (at(orig, x + i % P, y + i / P) - mean).powi(2)).sum::<f64>() / (P * P) as f64;
            // texture: a standard deviation of at least 8 grey levels
            if var >= 64.0 {
                looked += 1;
                let ssd = |dx: i64, dy: i64| -> f64 {
                    (0..P * P)
                        .map(|i| {
                            let (u, v) = (x + i % P, y + i / P);
                            let (ou, ov) = ((u as i64 + dx) as usize, (v as i64 + dy) as usize);
                            (at(rect, u, v) - at(orig, ou, ov)).powi(2)
                        })
                        .sum()
                };
                let best = (-2..=2i64)
                    .flat_map(|dy| (-2..=2i64).map(move |dx| (dx, dy)))
                    .min_by(|a, b| ssd(a.0, a.1).total_cmp(&ssd(b.0, b.1)));
                unshifted += usize::from(best == Some((0, 0)));
                for i in 0..P * P {
                    diff += (at(rect, x + i % P, y + i / P) - at(orig, x + i % P, y + i / P)).abs();
                    n += 1;
                }
            }
            x += P;
        }
        y += P;
    }
    (looked, unshifted, diff / n.max(1) as f64)
}

#[test]
fn the_distorted_06_is_rectified_back() {
    let dir = temp("raw06");
    let out = dir.join("raw06");
    let seq06 = common::fixture("kitti_odom_06/sequences/06");
    let rig = slam_runner::raw_rig::write_raw_rig(&seq06, &out, Some(2), &slam_runner::raw_rig::RawRigSpec::default())
        .expect("writes the raw rig");
    let original = slam_dataset::kitti::stereo::open_stereo(&seq06).expect("06");
    // ORB-SLAM's settings hold the exact rectification: the original images come back
    let opts = SourceOptions { calib: Some(rig.orbslam.clone()), ..Default::default() };
    let mut seq = open_sequence(&out, &opts).expect("opens");
    let rect = slam_runner::source::rectifier_of(&mut seq).expect("rectifies").expect("needs rectifying");
    assert_eq!(seq.intrinsics, original.intrinsics);
    assert!((seq.baseline - original.baseline).abs() < 1e-12);
    let mut reader = slam_runner::source::FrameReader::new(&seq, false, Some(rect));
    for k in 0..2 {
        let (l, r) = reader.pair(k).expect("pair");
        for (img, path) in [(&l, &original.left[k]), (&r, &original.right[k])] {
            let orig = slam_frontend::read_image(path, false).expect("original");
            // 16 px: the right camera's 0.5° turn moves its border by 6 px, and what the raw camera saw
            // beyond the original's border is black
            let (looked, unshifted, diff) = alignment(img, &orig, 16);
            // every textured patch matches best where it was: the images line up within half a pixel
            assert!(
                looked > 200 && unshifted == looked,
                "{}: {unshifted} of {looked} patches unshifted",
                path.display()
            );
            // interpolated twice (made raw, then rectified), edges soften: a few grey levels on average
            // (a shift of one pixel gives about 20 on these images)
            assert!(diff < 6.0, "{}: mean difference {diff:.2}", path.display());
        }
    }
    // Kalibr's camchain gives the cameras and the pose: the run's own rectification is row-aligned
    let opts = SourceOptions { calib: Some(rig.kalibr.clone()), ..Default::default() };
    let mut seq = open_sequence(&out, &opts).expect("opens");
    let rect = slam_runner::source::rectifier_of(&mut seq).expect("rectifies").expect("needs rectifying");
    let spec = slam_runner::raw_rig::RawRigSpec::default();
    let q = nalgebra::Rotation3::from_axis_angle(
        &nalgebra::Unit::new_normalize(nalgebra::Vector3::from(spec.axis)),
        spec.turn_deg.to_radians(),
    );
    // both rectified cameras look the same way: R_right · Q = R_left (the raw right camera is the
    // rectified one turned by Q)
    assert!((rect.right_rotation * q.matrix() - rect.left_rotation).abs().max() < 1e-9);
    assert!((seq.baseline - original.baseline).abs() < 1e-9, "{}", seq.baseline);
    // and along the baseline: the right camera's centre, (b, 0, 0) from the raw left camera, lies on the
    // rectified x axis
    let along = rect.left_rotation * nalgebra::Vector3::x();
    assert!((along - nalgebra::Vector3::x()).norm() < 1e-9, "{along}");
    // trajectory outputs of a rectified run are in the raw left camera's frame
    let s = RunSettings { source: opts, ..settings_at(&out, None) };
    let o = play(&s);
    assert_eq!(o.out.counts.tracked, 1);
    let moved = o.raw_left(&o.out.poses[1]);
    let turned = nalgebra::Rotation3::from_matrix_unchecked(rect.left_rotation.transpose());
    let c = nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::identity(),
        nalgebra::UnitQuaternion::from_rotation_matrix(&turned),
    );
    assert!((moved.to_homogeneous() - (c * o.out.poses[1] * c.inverse()).to_homogeneous()).abs().max() < 1e-12);
}
