//! `--rerun FILE.rrd` of `run` and `map`. With the feature `rerun` (`cargo test --release -p slam-app
//! --features rerun --test rerun`): the shipped excerpt's first frames are recorded, the recording is
//! read back with rerun's own decoder and holds the expected entities, one frame per played frame and
//! the ellipsoids of `objects.json`; the saved map is recorded too. Without the feature the option is
//! refused before any work, saying how to build with it.

use std::process::Command;

fn app() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_slam-app"));
    c.current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    c
}

fn temp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("slam-app-rerun-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

#[cfg(not(feature = "rerun"))]
#[test]
fn without_the_feature_rerun_is_refused_before_the_run() {
    let dir = temp("refused");
    let out = dir.join("run");
    let o = app()
        .args(["run", "--detector", "none", "--max-frames", "2", "--rerun"])
        .arg(dir.join("x.rrd"))
        .arg("--out")
        .arg(&out)
        .output()
        .expect("runs");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("x.rrd") && err.contains("--features rerun"), "{err}");
    assert!(!out.exists() && !dir.join("x.rrd").exists(), "nothing written");
    let o = app().args(["map", "no-such-map.json", "--rerun", "y.rrd"]).output().expect("runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--features rerun"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Frames played by the test: enough for the first objects to be fitted (the first ellipsoids of the
/// shipped excerpt come from the keyframes of its first 10-15 frames).
#[cfg(feature = "rerun")]
const FRAMES: usize = 20;

/// Centres of `objects.json`.
#[cfg(feature = "rerun")]
fn object_centres(path: &std::path::Path) -> Vec<(u64, [f64; 3])> {
    let text = std::fs::read_to_string(path).expect("objects.json");
    let v: serde_json::Value = serde_json::from_str(&text).expect("json");
    v["objects"]
        .as_array()
        .expect("objects")
        .iter()
        .map(|o| {
            let c: Vec<f64> =
                o["center"].as_array().expect("center").iter().map(|x| x.as_f64().expect("number")).collect();
            (o["id"].as_u64().expect("id"), [c[0], c[1], c[2]])
        })
        .collect()
}

/// The recording's last ellipsoids are `objects.json`'s objects: same ids (labels `#id class`), same
/// centres to the recording's single precision.
#[cfg(feature = "rerun")]
fn assert_same_objects(recorded: &[([f32; 3], String)], json: &[(u64, [f64; 3])]) {
    assert_eq!(recorded.len(), json.len(), "{recorded:?} vs {json:?}");
    for (id, c) in json {
        let (r, label) = recorded
            .iter()
            .find(|(_, l)| l.split(' ').next() == Some(&format!("#{id}")))
            .unwrap_or_else(|| panic!("object #{id} not in the recording: {recorded:?}"));
        for k in 0..3 {
            // f32 keeps 24 bits: 1e-6 relative, under 1e-4 m at 100 m
            assert!((f64::from(r[k]) - c[k]).abs() <= 1e-6 * c[k].abs().max(1.0), "#{id} ({label}): {r:?} vs {c:?}");
        }
    }
}

#[cfg(feature = "rerun")]
#[test]
fn a_run_and_its_map_are_recorded_and_read_back() {
    let dir = temp("run");
    let (out, rrd) = (dir.join("run"), dir.join("run.rrd"));
    let o = app()
        .args(["run", "--detections", "fixtures/kitti_odom_06/detections/yolo_fastest_tiles3.json", "--max-frames"])
        .arg(FRAMES.to_string())
        .arg("--out")
        .arg(&out)
        .arg("--rerun")
        .arg(&rrd)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let wrote = text.lines().find(|l| l.starts_with(&format!("wrote {}", rrd.display()))).expect("recording line");
    assert!(wrote.contains(&format!("{FRAMES} frames, {FRAMES} images")), "{wrote}");
    // written beside its place and renamed when whole: no temporary file stays behind
    let names: Vec<String> = std::fs::read_dir(&dir)
        .expect("dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.contains(".tmp-")), "{names:?}");

    let s = slam_rerun::read::summarise(&rrd).expect("rerun's decoder reads the recording");
    assert_eq!(s.frames, (0..FRAMES as i64).collect(), "one frame per played frame id");
    assert_eq!(s.images, FRAMES);
    for entity in [
        "world",
        "world/camera",
        "world/camera/image",
        "world/camera/image/detections",
        "world/camera/image/ellipses",
        "world/trajectory/estimate/b000",
        "world/trajectory/final",
        "world/trajectory/truth",
        "world/points/kf00000",
        "world/objects",
        "tracking/state",
        "tracking/level",
        "tracking/inliers",
        "tracking/map_points",
        "tracking/reprojection_rms_px",
        "tracking/frame_ms",
        "legend",
    ] {
        assert!(s.entities.contains(entity), "{entity} missing: {:?}", s.entities);
    }
    assert!(s.points > 1000, "map points of the keyframes: {}", s.points);
    assert!(wrote.contains(&format!("{} map points", s.points)), "{wrote}");
    let json = object_centres(&out.join("objects.json"));
    assert!(!json.is_empty(), "the test needs fitted objects: play more frames");
    assert_same_objects(&s.objects, &json);

    // the saved map: the same frames, no images, the same objects
    let map_rrd = dir.join("map.rrd");
    let o = app().arg("map").arg(out.join("map.json")).arg("--rerun").arg(&map_rrd).output().expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m = slam_rerun::read::summarise(&map_rrd).expect("reads");
    assert_eq!(m.frames, s.frames);
    assert_eq!(m.images, 0);
    assert!(!m.entities.contains("world/camera/image"), "{:?}", m.entities);
    assert!(m.entities.contains("world/camera") && m.entities.contains("world/objects"));
    assert!(m.points > 1000, "{}", m.points);
    assert_same_objects(&m.objects, &json);
    std::fs::remove_dir_all(&dir).ok();
}

/// A recording inside the output folder would be lost when the run swaps the folder in: refused.
#[cfg(feature = "rerun")]
#[test]
fn a_recording_inside_the_output_folder_is_refused() {
    let dir = temp("inside");
    let o = app()
        .args(["run", "--detector", "none", "--max-frames", "2", "--out"])
        .arg(dir.join("run"))
        .arg("--rerun")
        .arg(dir.join("run/x.rrd"))
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("inside --out"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
