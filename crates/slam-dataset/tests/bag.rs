//! ROS 2 bags as stereo sequences: the shipped kitti2mcap bag against the KITTI folder it was made
//! from, and bags made here with the `mcap` crate's writer for every kind of bad bag (docs/datasets.md,
//! "ROS 2 bags").

use std::{
    collections::BTreeMap,
    path::{Path, PathBuf},
};

use slam_dataset::{
    kitti::stereo::{open_stereo, Layout},
    recording::{open_sequence, SourceOptions},
    ros::{
        bag::Bag,
        msgs::{write_image, CameraInfo, Header, CAMERA_INFO, IMAGE},
    },
};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures")
}

fn shipped_bag() -> PathBuf {
    fixtures().join("ros2_bag_0005/drive_0005_frames_0-4.mcap")
}

fn temp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bag-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("dir");
    d
}

#[test]
fn the_kitti2mcap_bag_is_its_kitti_folder() {
    let bag = open_sequence(&shipped_bag(), &SourceOptions::default()).expect("opens");
    let kitti = open_stereo(fixtures().join("kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync")).expect("kitti");
    assert_eq!(bag.layout, Layout::Bag);
    assert_eq!(bag.ids, vec![0, 1, 2, 3, 4]);
    // the calibration is P_rect_00 and P_rect_01, read through CameraInfo to the last bit
    assert_eq!((bag.intrinsics, bag.baseline), (kitti.intrinsics, kitti.baseline));
    // the stamps are the left camera's timestamps.txt, to the nanosecond the file gives
    for (a, b) in bag.times.iter().zip(&kitti.times) {
        assert!((a - b).abs() < 1e-9, "{a} {b}");
    }
    let r = bag.recording.as_ref().expect("recording");
    assert!(r.rectify.is_none(), "KITTI's sync images are rectified");
    assert_eq!(r.calibrated_size, Some((1242, 375)));
    let frames = &r.bag.as_ref().expect("bag").frames;
    assert_eq!(frames[1].left.size, Some((1242, 375)));
    // KITTI's grey pair: the right camera stamped 2.9 ms after the left at frame 1
    assert_eq!(frames[1].right.stamp_ns - frames[1].left.stamp_ns, 2_893_824);
    assert!(
        r.source.contains("/kitti/camera_gray_left/image_raw") && r.source.contains("by their names"),
        "{}",
        r.source
    );
    let b = Bag::open(&shipped_bag()).expect("bag");
    let counts: BTreeMap<&str, usize> = b.topics.iter().map(|t| (t.name.as_str(), t.count)).collect();
    assert_eq!(counts["/kitti/camera_gray_left/image_raw"], 5);
    assert_eq!(counts["/tf_static"], 1);
    assert!(b.warnings.is_empty(), "{:?}", b.warnings);
    // a selection keeps the bag's frames with the ids
    let sub = bag
        .select(&slam_dataset::kitti::stereo::FrameSelection { first: Some(1), end: Some(4), stride: 2 })
        .expect("select");
    assert_eq!(sub.ids, vec![1, 3]);
    assert_eq!(sub.recording.as_ref().and_then(|r| r.bag.as_ref()).map(|b| b.frames[1]), Some(frames[3]));
}

/// One camera of a made bag: topic namespace, `P[0][3]`, whether it has a CameraInfo, its encoding.
struct Camera<'a> {
    ns: &'a str,
    tx: f64,
    info: bool,
    encoding: &'a str,
}

const MS: i64 = 1_000_000;

/// A bag of 64 × 48 images at 10 Hz from `t0`: each camera's images at `stamps(camera, k)`.
fn make_bag(path: &Path, cameras: &[Camera<'_>], frames: usize, stamp: impl Fn(usize, usize) -> Option<i64>) {
    let file = std::fs::File::create(path).expect("create");
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .chunk_size(Some(16 * 1024))
        .create(std::io::BufWriter::new(file))
        .expect("writer");
    let image_schema = w.add_schema(IMAGE, "ros2msg", b"std_msgs/Header header\n").expect("schema");
    let info_schema = w.add_schema(CAMERA_INFO, "ros2msg", b"std_msgs/Header header\n").expect("schema");
    let mut channels = Vec::new();
    for c in cameras {
        let img =
            w.add_channel(image_schema, &format!("{}/image_raw", c.ns), "cdr", &BTreeMap::new()).expect("channel");
        let info =
            w.add_channel(info_schema, &format!("{}/camera_info", c.ns), "cdr", &BTreeMap::new()).expect("channel");
        channels.push((img, info));
    }
    for k in 0..frames {
        for (i, c) in cameras.iter().enumerate() {
            let Some(t) = stamp(i, k) else { continue };
            let header = Header { stamp_ns: t, frame_id: c.ns.into() };
            let pixels: Vec<u8> = (0..64 * 48).map(|p| ((p * 7 + k * 3 + i) % 251) as u8).collect();
            let data = write_image(&header, 64, 48, c.encoding, 64, &pixels);
            let h = mcap::records::MessageHeader {
                channel_id: channels[i].0,
                sequence: k as u32,
                log_time: t as u64,
                publish_time: t as u64,
            };
            w.write_to_known_channel(&h, &data).expect("write");
            if c.info {
                let info = CameraInfo {
                    header,
                    width: 64,
                    height: 48,
                    distortion_model: "plumb_bob".into(),
                    d: vec![0.0; 5],
                    k: [50.0, 0.0, 32.0, 0.0, 50.0, 24.0, 0.0, 0.0, 1.0],
                    r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                    p: [50.0, 0.0, 32.0, c.tx, 0.0, 50.0, 24.0, 0.0, 0.0, 0.0, 1.0, 0.0],
                };
                let h = mcap::records::MessageHeader { channel_id: channels[i].1, ..h };
                w.write_to_known_channel(&h, &info.write()).expect("write");
            }
        }
    }
    w.finish().expect("finish");
}

const T0: i64 = 1_700_000_000_000_000_000;

fn pair(a: &str, b: &str) -> [Camera<'static>; 2] {
    let (a, b) = (a.to_string().leak(), b.to_string().leak());
    [
        Camera { ns: a, tx: 0.0, info: true, encoding: "mono8" },
        Camera { ns: b, tx: -25.0, info: true, encoding: "mono8" },
    ]
}

fn open(path: &Path) -> Result<slam_dataset::kitti::stereo::StereoSequence, String> {
    open_sequence(path, &SourceOptions::default()).map_err(|e| e.to_string())
}

#[test]
fn cameras_are_found_by_name_or_by_p_and_named_when_they_cannot_be() {
    let dir = temp("topics");
    // unnamed cameras: the right one is told by P's negative translation, whatever their order
    let p = dir.join("by_p.mcap");
    let cams = pair("/rig/b", "/rig/a");
    make_bag(&p, &cams, 4, |_, k| Some(T0 + k as i64 * 100 * MS));
    let s = open(&p).expect("opens");
    let r = s.recording.as_ref().expect("recording");
    assert_eq!(r.bag.as_ref().map(|b| b.topics.0.as_str()), Some("/rig/b/image_raw"));
    assert!(r.source.contains("by their CameraInfo P"), "{}", r.source);
    assert!((s.baseline - 0.5).abs() < 1e-12);
    // a third camera: ambiguous, --left/--right decide
    let p3 = dir.join("three.mcap");
    let [b, a] = cams;
    let three = [Camera { ns: "/c", tx: 0.0, info: true, encoding: "mono8" }, b, a];
    make_bag(&p3, &three, 3, |_, k| Some(T0 + k as i64 * 100 * MS));
    let e = open(&p3).expect_err("three cameras");
    assert!(e.contains("3 cameras") && e.contains("--left TOPIC --right TOPIC"), "{e}");
    let opts = SourceOptions {
        left: Some("/rig/b/image_raw".into()),
        right: Some("/rig/a/image_raw".into()),
        ..Default::default()
    };
    let s = open_sequence(&p3, &opts).expect("named");
    assert!(s.recording.as_ref().is_some_and(|r| r.source.contains("given with --left and --right")));
    let opts =
        SourceOptions { left: Some("/nope".into()), right: Some("/rig/a/image_raw".into()), ..Default::default() };
    let e = open_sequence(&p3, &opts).expect_err("no such topic").to_string();
    assert!(e.contains("--left /nope: no such topic"), "{e}");
    // names that disagree with P: swapped cameras are refused
    let p = dir.join("disagree.mcap");
    let cams = [
        Camera { ns: "/left", tx: -25.0, info: true, encoding: "mono8" },
        Camera { ns: "/right", tx: 0.0, info: true, encoding: "mono8" },
    ];
    make_bag(&p, &cams, 2, |_, k| Some(T0 + k as i64 * 100 * MS));
    let e = open(&p).expect_err("disagree");
    assert!(e.contains("disagree on which is left"), "{e}");
}

#[test]
fn bad_bags_are_errors_naming_what_or_counted_skips() {
    let dir = temp("bad");
    // no camera_info and no --calib: the topics and the flag
    let p = dir.join("no_info.mcap");
    let cams = [
        Camera { ns: "/l", tx: 0.0, info: false, encoding: "mono8" },
        Camera { ns: "/r", tx: 0.0, info: false, encoding: "mono8" },
    ];
    make_bag(&p, &cams, 2, |_, k| Some(T0 + k as i64 * 100 * MS));
    let e = open(&p).expect_err("no info");
    assert!(
        e.contains("no_info.mcap")
            && e.contains("/l/image_raw (looked for /l/camera_info)")
            && e.contains("--calib FILE"),
        "{e}"
    );
    // one camera only
    let p = dir.join("one.mcap");
    make_bag(&p, &pair("/left", "/right")[..1], 3, |_, k| Some(T0 + k as i64 * 100 * MS));
    let e = open(&p).expect_err("one camera");
    assert!(e.contains("one camera only: /left/image_raw"), "{e}");
    // an encoding the front end does not decode, named
    let p = dir.join("yuv.mcap");
    let cams = [
        Camera { ns: "/left", tx: 0.0, info: true, encoding: "yuv422" },
        Camera { ns: "/right", tx: -25.0, info: true, encoding: "mono8" },
    ];
    make_bag(&p, &cams, 2, |_, k| Some(T0 + k as i64 * 100 * MS));
    let e = open(&p).expect_err("yuv");
    assert!(
        e.contains("/left/image_raw: images of encoding 'yuv422'") && e.contains("mono8, rgb8, bgr8, mono16"),
        "{e}"
    );
    // stamps further apart than a quarter period: counted and skipped, the others keep their ids
    let p = dir.join("late.mcap");
    make_bag(&p, &pair("/left", "/right"), 8, |cam, k| {
        let late = if cam == 1 && (k == 2 || k == 5) { 40 * MS } else { MS };
        Some(T0 + k as i64 * 100 * MS + if cam == 1 { late } else { 0 })
    });
    let s = open(&p).expect("opens");
    assert_eq!(s.ids, vec![0, 1, 3, 4, 6, 7]);
    let w = s.warnings.join("\n");
    assert!(w.contains("2 left image(s) have no right image within 25.0 ms") && w.contains("skipped"), "{w}");
    // a file cut short by a power loss: the frames before the cut, a warning naming the byte
    let p = dir.join("long.mcap");
    make_bag(&p, &pair("/left", "/right"), 40, |_, k| Some(T0 + k as i64 * 100 * MS));
    let bytes = std::fs::read(&p).expect("read");
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).expect("write");
    let s = open(&cut).expect("a cut bag opens");
    assert!(s.len() > 10 && s.len() < 40, "{} frames", s.len());
    let w = s.warnings.join("\n");
    assert!(w.contains("cut.mcap is cut short at byte") && w.contains("power loss") && w.contains("are used"), "{w}");
    // a damaged chunk in the middle of a whole file: an error naming the chunk's offset
    let chunks = chunk_offsets(&bytes);
    assert!(chunks.len() > 3, "{chunks:?}");
    let (at, len) = chunks[2];
    let mut bad = bytes.clone();
    for b in &mut bad[at + 9 + len / 2..at + 9 + len / 2 + 16] {
        *b ^= 0x5a;
    }
    let damaged = dir.join("damaged.mcap");
    std::fs::write(&damaged, &bad).expect("write");
    let e = open(&damaged).expect_err("damaged");
    assert!(e.contains("damaged.mcap") && e.contains(&format!("the chunk at byte {at} is damaged")), "{e}");
    // a chunk whose length is damaged in a whole file is damage, not a cut
    let mut bad = bytes.clone();
    bad[at + 1..at + 9].copy_from_slice(&(10 * bytes.len() as u64).to_le_bytes());
    std::fs::write(&damaged, &bad).expect("write");
    let e = open(&damaged).expect_err("damaged length");
    assert!(e.contains(&format!("the record at byte {at} declares")) && e.contains("damaged"), "{e}");
    // not an MCAP file, and a rosbag2 folder of another storage
    std::fs::write(dir.join("text.mcap"), "hello").expect("write");
    assert!(open(&dir.join("text.mcap")).expect_err("text").contains("not an MCAP file"));
    let sq = dir.join("sqlite");
    std::fs::create_dir_all(&sq).expect("dir");
    std::fs::write(
        sq.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  storage_identifier: sqlite3\n  relative_file_paths: [a.db3]\n",
    )
    .expect("write");
    let e = open(&sq).expect_err("sqlite");
    assert!(e.contains("storage_identifier is 'sqlite3'"), "{e}");
}

/// The offsets and body lengths of a file's top-level chunk records.
fn chunk_offsets(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().expect("8 bytes")) as usize;
        if bytes[at] == 0x06 {
            out.push((at, len));
        }
        if bytes[at] == 0x0f {
            break;
        }
        at += 9 + len;
    }
    out
}

#[test]
fn a_rosbag2_folder_reads_its_files_in_order() {
    let dir = temp("rosbag2");
    let bag = dir.join("run_1");
    std::fs::create_dir_all(&bag).expect("dir");
    make_bag(&bag.join("run_1_0.mcap"), &pair("/left", "/right"), 3, |_, k| Some(T0 + k as i64 * 100 * MS));
    make_bag(&bag.join("run_1_1.mcap"), &pair("/left", "/right"), 3, |_, k| Some(T0 + (k + 3) as i64 * 100 * MS));
    std::fs::write(
        bag.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n  relative_file_paths:\n    - run_1_0.mcap\n    - run_1_1.mcap\n",
    )
    .expect("metadata");
    let s = open(&bag).expect("opens");
    assert_eq!(s.ids, (0..6).collect::<Vec<_>>());
    assert!((s.times[5] - 0.5).abs() < 1e-9);
    let frames = &s.recording.as_ref().and_then(|r| r.bag.as_ref()).expect("bag").frames;
    assert_eq!((frames[2].left.at.file, frames[3].left.at.file), (0, 1));
    assert_eq!(s.left[4], bag.join("run_1_1.mcap"));
}
