//! KITTI raw readers on the shipped drive-0001 fixture and on malformed input.

use std::path::PathBuf;

use slam_dataset::{
    kitti::{
        raw::{oxts_poses, read_oxts_packet, read_timestamps, OxtsPacket, RawCalib},
        tracklets::read_tracklets,
    },
    DatasetError,
};

fn drive() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/kitti_raw_0001/2011_09_26")
}

#[test]
fn tracklets_of_drive_0001() {
    let t = read_tracklets(drive().join("2011_09_26_drive_0001_sync/tracklet_labels.xml")).expect("reads");
    assert_eq!(t.len(), 15);
    let count = |k: &str| t.iter().filter(|x| x.object_type == k).count();
    assert_eq!((count("Car"), count("Cyclist"), count("Tram")), (12, 2, 1));
    assert_eq!(t.iter().map(|x| x.frames().end).max(), Some(108));
    let first = &t[0];
    assert_eq!(first.first_frame, 0);
    assert_eq!(first.poses.len(), 14);
    assert!((first.hwl[2] - 4.3293562).abs() < 1e-9);
    let p = first.pose_at(0).expect("frame 0");
    assert!((p.t[0] - 25.212_516_037_456_26).abs() < 1e-12 && (p.r[2] + 3.1842001424562025).abs() < 1e-12);
    assert_eq!(p.state, 2);
    assert!(first.pose_at(14).is_none());
}

#[test]
fn calib_oxts_and_timestamps() {
    let c = RawCalib::read(drive()).expect("calib");
    assert!((c.p_rect[2][(0, 0)] - 721.5377).abs() < 1e-6 && (c.image_size[0] - 1242.0).abs() < 1e-9);
    // Velodyne x (forward) maps to camera z (forward)
    let fwd = c.rect_from_velo().rotation * nalgebra::Vector3::x();
    assert!(fwd.z > 0.99, "{fwd}");
    let p = read_oxts_packet(drive().join("2011_09_26_drive_0001_sync/oxts/data/0000000000.txt")).expect("oxts");
    assert!((p.lat - 49.015003823272).abs() < 1e-12 && (p.yaw + 2.6087069803847).abs() < 1e-12);
    // the first pose is the origin; a packet 1e-5 degrees further north is r·cos(lat)·Δ ahead along +y
    let north = OxtsPacket { lat: p.lat + 1e-5, ..p };
    let poses = oxts_poses(&[p, north]);
    assert!(poses[0].translation.vector.norm() < 1e-9);
    let world_step = poses[0].rotation * poses[1].translation.vector;
    let expected = 6_378_137.0 * (1e-5f64).to_radians();
    let local = poses[1].translation.vector.norm();
    assert!((local - expected).abs() < 0.01 * expected, "{local} vs {expected}");
    assert!(world_step.norm() > 0.0);
    let ts = read_timestamps(drive().join("2011_09_26_drive_0001_sync/image_00/timestamps.txt")).expect("ts");
    assert_eq!(ts.len(), 108);
    assert!((ts[1] - 0.103129856).abs() < 1e-6, "{}", ts[1]);
}

fn tmp(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("slam-dataset-raw-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write");
    p
}

fn line(e: DatasetError) -> usize {
    match e {
        DatasetError::Parse { line, .. } => line,
        other => panic!("expected a parse error, got {other}"),
    }
}

#[test]
fn malformed_raw_inputs() {
    let xml = |body: &str| {
        format!("<?xml version=\"1.0\"?>\n<boost_serialization>\n<tracklets>\n<count>1</count>\n{body}\n</tracklets>\n</boost_serialization>\n")
    };
    let item = |h: &str, n: usize| {
        format!("<item><objectType>Car</objectType><h>{h}</h><w>1</w><l>4</l><first_frame>0</first_frame><poses><count>{n}</count><item><tx>1</tx><ty>2</ty><tz>3</tz><rx>0</rx><ry>0</ry><rz>0</rz><state>2</state><occlusion>0</occlusion><truncation>0</truncation></item></poses></item>")
    };
    assert!(read_tracklets(tmp("ok.xml", xml(&item("1.5", 1)).as_bytes())).is_ok());
    assert_eq!(line(read_tracklets(tmp("nan.xml", xml(&item("nan", 1)).as_bytes())).expect_err("nan")), 5);
    assert_eq!(line(read_tracklets(tmp("count.xml", xml(&item("1.5", 2)).as_bytes())).expect_err("count")), 5);
    let cut = xml(&item("1.5", 1));
    let truncated = &cut[..cut.len() / 2];
    assert!(matches!(read_tracklets(tmp("cut.xml", truncated.as_bytes())), Err(DatasetError::Parse { .. })));
    assert!(matches!(read_tracklets(tmp("empty.xml", b"")), Err(DatasetError::Parse { .. })));
    assert_eq!(line(read_oxts_packet(tmp("oxts.txt", b"1 2 3\n")).expect_err("short")), 1);
    assert!(matches!(read_oxts_packet(tmp("oxts2.txt", b"\n")), Err(DatasetError::Invalid { .. })));
    assert_eq!(line(read_timestamps(tmp("ts.txt", b"2011-09-26 13:02:25.9\n2011-09-26 xx\n")).expect_err("bad")), 2);
    assert!(matches!(read_timestamps("/nonexistent/ts.txt"), Err(DatasetError::Io { .. })));
}
