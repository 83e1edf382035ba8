//! KITTI raw readers on the shipped drive-0001 fixture and on malformed input.

use std::path::PathBuf;

use slam_dataset::{
    kitti::{
        poses::read_kitti_poses,
        raw::{
            camera_poses_from_oxts, check_oxts_steps, oxts_poses, parse_oxts_packet, read_oxts_packet, read_timestamps,
            OxtsPacket, RawCalib,
        },
        stereo::{open_stereo, FrameSelection, Layout, TruthSource},
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

fn drive_0005() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync")
}

#[test]
fn oxts_to_camera_by_construction() {
    // KITTI's axes: IMU and Velodyne x forward, y left, z up; camera x right, y down, z forward. The
    // Velodyne sits 0.8 m ahead of and 0.7 m above the IMU, the camera 0.3 m ahead of the Velodyne.
    let cam_from_velo = nalgebra::Matrix3::new(0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0);
    let rot =
        nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(cam_from_velo));
    let calib = RawCalib {
        p_rect: [nalgebra::Matrix3x4::identity(); 4],
        r_rect_00: nalgebra::Matrix3::identity(),
        cam0_from_velo: nalgebra::Isometry3::from_parts(nalgebra::Translation3::new(0.0, 0.0, -0.3), rot),
        velo_from_imu: nalgebra::Isometry3::translation(-0.8, 0.0, -0.7),
        image_size: [1242.0, 375.0],
    };
    let lat: f64 = 49.0;
    let metre_in_lon = (1.0 / (lat.to_radians().cos() * 6_378_137.0)).to_degrees();
    let packet = |east_m: f64, yaw: f64| OxtsPacket {
        lat,
        lon: 8.4 + east_m * metre_in_lon,
        alt: 110.0,
        roll: 0.0,
        pitch: 0.0,
        yaw,
        values: [0.0; 30],
    };
    // heading east (yaw 0), 1 m per frame: the camera moves 1 m per frame along its own z
    let straight: Vec<OxtsPacket> = (0..5).map(|i| packet(i as f64, 0.0)).collect();
    for (i, p) in camera_poses_from_oxts(&straight, &calib).iter().enumerate() {
        assert!((p.translation.vector - nalgebra::Vector3::new(0.0, 0.0, i as f64)).norm() < 1e-6, "{i}: {p}");
        assert!(p.rotation.angle() < 1e-9);
    }
    // a quarter turn left on the spot: the camera now looks along the first camera's −x (its left),
    // and, 1.1 m ahead of the IMU, it swings 1.1 m left and 1.1 m back
    let turn = camera_poses_from_oxts(&[packet(0.0, 0.0), packet(0.0, std::f64::consts::FRAC_PI_2)], &calib);
    let forward = turn[1].rotation * nalgebra::Vector3::z();
    assert!((forward - nalgebra::Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-9, "{forward}");
    assert!((turn[1].translation.vector - nalgebra::Vector3::new(-1.1, 0.0, -1.1)).norm() < 1e-6, "{}", turn[1]);
}

#[test]
fn drive_0005_ground_truth_agrees_with_orbslam3() {
    // the drive opens with one entry per frame, OXTS ground truth and the GPS accuracy of its packets
    let s = open_stereo(drive_0005()).expect("opens");
    assert_eq!((s.layout, s.ids.len(), s.ids[90]), (Layout::Raw, 91, 90));
    // the drive's timestamps.txt has 154 lines: the 91 of the frames present are taken
    let all = read_timestamps(drive_0005().join("image_00/timestamps.txt")).expect("ts");
    assert_eq!(all.len(), 154);
    assert_eq!(s.times, all[..91].to_vec());
    let Some(TruthSource::Oxts { median_pos_accuracy_m, path }) = s.truth_source else {
        panic!("{:?}", s.truth_source)
    };
    assert!((0.3..0.6).contains(&median_pos_accuracy_m), "{median_pos_accuracy_m}");
    // the packets' velocities integrate to a path about 4 % longer than their GPS positions trace
    // (34.9 m against 33.5 m over frames 0–90; ORB-SLAM3's stereo poses make it 36.0 m)
    let path = path.expect("path check");
    assert!((34.0..36.0).contains(&path.velocities_m), "{path:?}");
    assert!((-6.0..-2.5).contains(&path.position_excess_pct()), "{path:?}");
    let gt = s.ground_truth.as_ref().expect("truth");
    // the same drive is KITTI tracking sequence 0000, whose ORB-SLAM3 stereo poses (left colour camera,
    // 6 cm beside camera 0, same rectified axes) are shipped: over the 91 frames (33 m, a 21° turn) the
    // two must agree to about the GPS accuracy; a wrong chain (axes, inverse, lever arm) errs by metres
    let orb = read_kitti_poses(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/kitti_tracking/0000/poses_orbslam3.txt"),
    )
    .expect("orb");
    let path: f64 = gt.windows(2).map(|w| (w[1].translation.vector - w[0].translation.vector).norm()).sum();
    assert!((30.0..37.0).contains(&path), "{path}");
    // the GPS positions of this drive are shorter than ORB-SLAM3's (and than the packets' own forward
    // speed integrated) by about 7 %: differential GPS, not the conversion. So compare what the
    // conversion decides: the orientation of every frame, the direction of every position from the
    // start (beyond 5 m, where 0.5 m of GPS error is under 6°) and the path length to within 10 %
    let orb_path: f64 = orb[..91].windows(2).map(|w| (w[1].translation.vector - w[0].translation.vector).norm()).sum();
    assert!((orb_path / path - 1.0).abs() < 0.1, "{orb_path} vs {path}");
    let mut worst: (f64, f64) = (0.0, 0.0);
    for (g, o) in gt.iter().zip(&orb) {
        worst.0 = worst.0.max(g.rotation.angle_to(&o.rotation).to_degrees());
        if g.translation.vector.norm() > 5.0 {
            worst.1 = worst.1.max(g.translation.vector.angle(&o.translation.vector).to_degrees());
        }
    }
    assert!(worst.0 < 1.0 && worst.1 < 6.0, "largest rotation / direction difference, degrees: {worst:?}");
    // a frame selection is rebased to its first frame
    let sub = s.select(&FrameSelection { first: Some(30), end: None, stride: 3 }).expect("select");
    // whose path check (made from all 91 frames) is not carried over
    assert!(matches!(sub.truth_source, Some(TruthSource::Oxts { path: None, .. })), "{:?}", sub.truth_source);
    let r = sub.truth_from_first().expect("truth");
    assert!(r[0].translation.vector.norm() < 1e-12);
    let step = gt[30].inverse() * gt[33];
    assert!((r[1].translation.vector - step.translation.vector).norm() < 1e-9);
}

/// The OXTS path check: packets driving north at 10 m/s whose positions agree with their velocities
/// trace the same path both ways; positions that cover 5 % less ground show −5 %.
#[test]
fn oxts_path_check_compares_positions_with_velocities() {
    use slam_dataset::kitti::raw::{oxts_path_lengths, OXTS_VELOCITY};
    let metre_of_latitude = (1.0 / 6_378_137.0f64).to_degrees();
    let packets = |shrink: f64| -> Vec<OxtsPacket> {
        (0..11)
            .map(|i| {
                let mut values = [0.0; 30];
                values[0] = 49.0 + shrink * metre_of_latitude * i as f64; // 1 m per frame
                values[1] = 8.4;
                values[OXTS_VELOCITY[0]] = 10.0; // vn
                OxtsPacket { lat: values[0], lon: 8.4, alt: 0.0, roll: 0.0, pitch: 0.0, yaw: 0.0, values }
            })
            .collect()
    };
    let times: Vec<f64> = (0..11).map(|i| 0.1 * i as f64).collect();
    let agree = oxts_path_lengths(&packets(1.0), &times).expect("path");
    assert!((agree.velocities_m - 10.0).abs() < 1e-9, "{agree:?}");
    assert!((agree.positions_m - 10.0).abs() < 0.01 && agree.position_excess_pct().abs() < 0.1, "{agree:?}");
    let short = oxts_path_lengths(&packets(0.95), &times).expect("path");
    assert!((short.position_excess_pct() + 5.0).abs() < 0.1, "{short:?}");
    // too few packets, or times that do not match them
    assert!(oxts_path_lengths(&packets(1.0)[..1], &times[..1]).is_none());
    assert!(oxts_path_lengths(&packets(1.0), &times[..5]).is_none());
}

/// The INS dead reckoning: a car at 10 m/s turning at 0.2 rad/s (its velocity over ground `v_e, v_n`
/// along its heading, the body tilted by a constant roll and pitch) traces the circle of radius 50 m,
/// expressed in its first pose's frame, to the trapezoid rule's error, whatever its GPS positions
/// say; a car that stands still stays at the start.
#[test]
fn oxts_dead_reckoning_follows_the_velocities_and_the_heading() {
    use slam_dataset::kitti::raw::{oxts_dead_reckoning, OXTS_VELOCITY};
    let (speed, rate, dt, heading0) = (10.0, 0.2, 0.1, 0.3);
    let packets = |moving: bool| -> Vec<OxtsPacket> {
        (0..31)
            .map(|i| {
                let mut values = [0.0; 30];
                values[0] = 49.0; // GPS positions that never move: not used
                values[1] = 8.4;
                let yaw = if moving { heading0 + rate * dt * i as f64 } else { heading0 };
                let v = if moving { speed } else { 0.0 };
                values[OXTS_VELOCITY[0]] = v * yaw.sin(); // north
                values[OXTS_VELOCITY[1]] = v * yaw.cos(); // east
                OxtsPacket { lat: 49.0, lon: 8.4, alt: 0.0, roll: 0.03, pitch: -0.02, yaw, values }
            })
            .collect()
    };
    let times: Vec<f64> = (0..31).map(|i| dt * i as f64).collect();
    let moving = packets(true);
    let poses = oxts_dead_reckoning(&moving, &times).expect("poses");
    assert_eq!(poses.len(), 31);
    assert!(poses[0].translation.vector.norm() < 1e-12 && poses[0].rotation.angle() < 1e-12);
    let first = moving[0].orientation();
    let r = speed / rate;
    for (i, p) in poses.iter().enumerate() {
        let yaw = heading0 + rate * dt * i as f64;
        let east_north =
            nalgebra::Vector3::new(r * (yaw.sin() - heading0.sin()), r * (heading0.cos() - yaw.cos()), 0.0);
        let expected = first.inverse() * east_north;
        assert!((p.translation.vector - expected).norm() < 0.02, "frame {i}: {} vs {expected}", p.translation.vector);
        assert!((p.rotation.angle_to(&(first.inverse() * moving[i].orientation()))).abs() < 1e-9);
    }
    let still = oxts_dead_reckoning(&packets(false), &times).expect("poses");
    assert!(still.iter().all(|p| p.translation.vector.norm() < 1e-12));
    assert!(oxts_dead_reckoning(&moving, &times[..3]).is_none());
}

/// Drive 0005's dead reckoning: one pose per frame, in the frame of the GPS ground truth (the same
/// start), tracing about the path of the packets' velocities (34.9 m for the IMU; camera 0's path
/// differs a little in the turn) where the GPS positions trace 33.5 m; a selection keeps it aligned
/// with its frames.
#[test]
fn drive_0005_dead_reckoning_traces_the_velocities_path() {
    let s = open_stereo(drive_0005()).expect("opens");
    let dr = s.dead_reckoned_from_first().expect("dead reckoning");
    assert_eq!(dr.len(), 91);
    let path: f64 = dr.windows(2).map(|w| (w[1].translation.vector - w[0].translation.vector).norm()).sum();
    assert!((34.5..35.5).contains(&path), "{path}");
    // it ends near the GPS truth's end point (2.5 m apart: the positions' path is 4 % shorter, and
    // the velocities point about 3° off the packets' yaw on this drive), far from the tens of metres a
    // wrong axis or sign would put it
    let gt = s.truth_from_first().expect("truth");
    let gap = (dr[90].translation.vector - gt[90].translation.vector).norm();
    assert!(gap < 0.1 * path, "{gap}");
    let sub = s.select(&FrameSelection { first: Some(30), end: None, stride: 3 }).expect("select");
    let r = sub.dead_reckoned_from_first().expect("dead reckoning");
    let full = s.dead_reckoned.as_ref().expect("dead reckoning");
    let step = full[30].inverse() * full[33];
    assert!((r[1].translation.vector - step.translation.vector).norm() < 1e-9);
}

/// Packets a vehicle cannot have produced: a 1.1 km jump between two frames, a turn of 90° in 0.1 s,
/// each named by its packet; the shipped drive's packets pass.
#[test]
fn impossible_oxts_steps_name_the_packet() {
    // lat, lon, alt, roll, pitch, yaw, … pos_accuracy (value 23) 0.5 m
    let packet_with = |lat: f64, yaw: f64, accuracy: f64| {
        let mut v = vec![0.0; 30];
        (v[0], v[1], v[2], v[5], v[23]) = (49.0 + lat, 8.4, 110.0, yaw, accuracy);
        let line: Vec<String> = v.iter().map(|x| x.to_string()).collect();
        parse_oxts_packet(std::path::Path::new("p.txt"), &line.join(" ")).expect("packet")
    };
    let packet = |lat: f64, yaw: f64| packet_with(lat, yaw, 0.5);
    let names: Vec<PathBuf> = (0..4).map(|i| PathBuf::from(format!("oxts/{i:010}.txt"))).collect();
    let named: Vec<&std::path::Path> = names.iter().map(PathBuf::as_path).collect();
    let times = [0.0, 0.1, 0.2, 0.3];
    // 1e-5° of latitude is 1.1 m a step: a car at 40 km/h
    let driving: Vec<OxtsPacket> = (0..4).map(|i| packet(1e-5 * i as f64, 0.01 * i as f64)).collect();
    check_oxts_steps(&driving, &times, &named).expect("a drive");
    let mut jump = driving.clone();
    jump[2] = packet(0.01 + 2e-5, 0.02);
    let e = check_oxts_steps(&jump, &times, &named).expect_err("jump").to_string();
    assert!(e.starts_with("oxts/0000000002.txt: the IMU moved 111") && e.contains("0000000001.txt"), "{e}");
    // a fix claiming an accuracy of 1000 km opens the check no wider than a 20 m fix would
    jump[2] = packet_with(0.01 + 2e-5, 0.02, 1e6);
    let e = check_oxts_steps(&jump, &times, &named).expect_err("jump with a huge accuracy").to_string();
    assert!(e.contains("the IMU moved 111") && e.contains("(20.50 m)"), "{e}");
    let mut spin = driving.clone();
    spin[3] = packet(3e-5, std::f64::consts::FRAC_PI_2);
    let e = check_oxts_steps(&spin, &times, &named).expect_err("spin").to_string();
    assert!(e.starts_with("oxts/0000000003.txt: the IMU turned 88.9°"), "{e}");
    // the shipped drive 0005, its packets checked as it opens
    let d5 = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync");
    let seq = open_stereo(d5).expect("drive 0005");
    assert!(seq.ground_truth.is_some());
}

/// Frame times are read with their dates: a clock 13 h earlier on the same date is an error (it was read
/// as a midnight crossing), a real crossing is 0.1 s, a year's jump or a `times.txt` line of 1e300 s is
/// no recording's.
#[test]
fn frame_times_follow_the_date_and_stay_within_a_recording() {
    use slam_dataset::kitti::{frames::read_frame_times, raw::parse_timestamps};
    let p = std::path::Path::new("timestamps.txt");
    let crossing = "2011-09-26 23:59:59.950000000\n2011-09-27 00:00:00.050000000\n";
    let t = parse_timestamps(p, crossing).expect("a midnight crossing");
    assert!((t[1] - 0.1).abs() < 1e-9, "{t:?}");
    let leap_year = "2012-02-28 23:59:59.950000000\n2012-02-29 00:00:00.050000000\n2012-03-01 00:00:00.150000000\n";
    let e = parse_timestamps(p, leap_year).expect_err("a day's jump").to_string();
    assert!(e.contains("timestamps.txt:3:") && e.contains("at most 3600"), "{e}");
    let back = "2011-09-26 13:02:25.9\n2011-09-26 00:02:26.0\n";
    let e = parse_timestamps(p, back).expect_err("13 h back").to_string();
    assert!(e.contains("timestamps.txt:2:") && e.contains("not after the line before"), "{e}");
    let year = "2011-09-26 13:02:25.9\n2012-09-26 13:02:26.0\n";
    assert!(parse_timestamps(p, year).expect_err("a year").to_string().contains("at most 3600"));
    let e = parse_timestamps(p, "2011-02-30 13:02:25.9\n").expect_err("no such day").to_string();
    assert!(e.contains("2011-02-30 is not a date"), "{e}");
    let dir = std::env::temp_dir().join(format!("slam-times-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let f = dir.join("times.txt");
    std::fs::write(&f, "0.0\n0.1\n1e300\n").expect("write");
    let e = read_frame_times(&f).expect_err("1e300").to_string();
    assert!(e.contains("times.txt:3:") && e.contains("at most 1e10 s"), "{e}");
    std::fs::write(&f, "0.0\n0.1\n0.2\n").expect("write");
    assert_eq!(read_frame_times(&f).expect("times").len(), 3);
    std::fs::remove_dir_all(&dir).ok();
}
