//! The bad-input suite: every command and reader fed missing, empty, truncated, malformed, non-finite,
//! out-of-range, wrongly sized and wrongly typed input, unwritable paths and conflicting options. Each case
//! asserts the exit status and the message (or, for the few that run the system on 3–4 frames, the counted
//! warning and the unchanged result). Nearly all fail before any tracking starts.

use std::{
    ffi::OsString,
    path::{Path, PathBuf},
    process::Command,
};

fn app() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_slam-app"));
    c.current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    c
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures")
}

/// One bad input: the arguments, the exit status and pieces of text stderr must hold.
struct Case {
    name: String,
    args: Vec<OsString>,
    code: i32,
    want: Vec<String>,
}

fn case(name: &str, args: &[&dyn AsRef<std::ffi::OsStr>], code: i32, want: &[&str]) -> Case {
    Case {
        name: name.to_string(),
        args: args.iter().map(|a| a.as_ref().to_os_string()).collect(),
        code,
        want: want.iter().map(|s| s.to_string()).collect(),
    }
}

/// Run every case; report all failures at once.
fn check(cases: Vec<Case>) -> usize {
    let mut failures = Vec::new();
    let n = cases.len();
    for c in cases {
        let o = app().args(&c.args).output().expect("runs");
        let err = String::from_utf8_lossy(&o.stderr);
        let code = o.status.code().unwrap_or(-1);
        let missing: Vec<&String> = c.want.iter().filter(|w| !err.contains(w.as_str())).collect();
        if code != c.code || !missing.is_empty() || err.contains("panicked") {
            failures.push(format!(
                "{}: exit {code} (want {}), missing {missing:?}\n  args {:?}\n  stderr: {}",
                c.name,
                c.code,
                c.args,
                err.trim()
            ));
        }
    }
    assert!(failures.is_empty(), "{} of {n} cases failed:\n{}", failures.len(), failures.join("\n"));
    n
}

/// A scratch folder for one test.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("slam-bad-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch");
    d
}

/// A copy of the first `n` frames of the shipped odometry sequence, with `calib` as its calib.txt.
fn sequence(root: &Path, name: &str, n: usize, calib: Option<&str>) -> PathBuf {
    let src = fixtures().join("kitti_odom_06/sequences/06");
    let dst = root.join(name).join("sequences/06");
    for d in ["image_0", "image_1"] {
        std::fs::create_dir_all(dst.join(d)).expect("dir");
        for i in 0..n {
            let f = format!("{i:06}.png");
            std::fs::copy(src.join(d).join(&f), dst.join(d).join(&f)).expect("copy");
        }
    }
    match calib {
        Some(text) => std::fs::write(dst.join("calib.txt"), text).expect("calib"),
        None => {
            std::fs::copy(src.join("calib.txt"), dst.join("calib.txt")).expect("calib");
        }
    }
    dst
}

/// The shipped calibration with one number replaced (row `key`, field `index` 0–11).
fn calib_with(key: &str, index: usize, value: &str) -> String {
    let text = std::fs::read_to_string(fixtures().join("kitti_odom_06/sequences/06/calib.txt")).expect("calib");
    text.lines()
        .map(|l| {
            if l.starts_with(&format!("{key}:")) {
                let mut f: Vec<String> = l.split_whitespace().map(str::to_string).collect();
                f[1 + index] = value.to_string();
                f.join(" ")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn write(path: &Path, text: &str) -> PathBuf {
    if let Some(p) = path.parent() {
        std::fs::create_dir_all(p).expect("dir");
    }
    std::fs::write(path, text).expect("write");
    path.to_path_buf()
}

/// Numbers and settings: every option and settings key outside its range, non-finite or of the wrong type.
#[test]
fn numbers_and_settings_are_checked_at_the_edge() {
    let d = scratch("numbers");
    let cfg = |name: &str, text: &str| write(&d.join(format!("{name}.toml")), text);
    let run_cfg = |name: &str, text: &str, want: &[&str]| {
        let p = cfg(name, text);
        let mut w: Vec<&str> = vec![name];
        w.extend_from_slice(want);
        case(&format!("config {name}"), &[&"run", &"--config", &p, &"--out", &d.join("o")], 1, &w)
    };
    let mut cases = vec![
        case(
            "--label-noise nan",
            &[&"run", &"--label-noise", &"nan"],
            1,
            &["--label-noise NaN: must be a finite number in [0, 1]"],
        ),
        case(
            "--label-noise 2",
            &[&"run", &"--label-noise", &"2"],
            1,
            &["--label-noise 2: must be a finite number in [0, 1]"],
        ),
        case("--label-noise inf", &[&"run", &"--label-noise", &"inf"], 1, &["--label-noise inf"]),
        case(
            "--input-size 32000",
            &[&"run", &"--input-size", &"32000"],
            1,
            &["--input-size 32000: must be a multiple of 32 in [32, 2048]"],
        ),
        case(
            "--input-size 100",
            &[&"run", &"--input-size", &"100"],
            1,
            &["--input-size 100: must be a multiple of 32"],
        ),
        case("--input-size -32", &[&"run", &"--input-size=-32"], 1, &["--input-size -32"]),
        case("--score 1.5", &[&"run", &"--score", &"1.5"], 1, &["--score 1.5: must be a finite number in [0, 1]"]),
        case("--score nan", &[&"run", &"--score", &"NaN"], 1, &["--score NaN"]),
        case("--tiles 0", &[&"run", &"--tiles", &"0"], 1, &["--tiles 0: must be an integer in [1, 16]"]),
        case("--max-frames 0", &[&"run", &"--max-frames", &"0"], 1, &["--max-frames 0: must be at least 1"]),
        case("--max-frames abc", &[&"run", &"--max-frames", &"abc"], 2, &["invalid value 'abc'"]),
        case("--max-frames -1", &[&"run", &"--max-frames=-1"], 2, &["invalid value '-1'"]),
        case("--keyframe-gap 0", &[&"run", &"--keyframe-gap", &"0"], 2, &["--keyframe-gap"]),
        case("--detect-every 0", &[&"run", &"--detect-every", &"0"], 2, &["--detect-every"]),
        case("--overlay-format bmp", &[&"run", &"--overlay-format", &"bmp"], 2, &["invalid value 'bmp'"]),
        case("--detector banana", &[&"run", &"--detector", &"banana"], 2, &["invalid value 'banana'"]),
        case("--onnx with --cfg", &[&"run", &"--onnx", &"a.onnx", &"--cfg", &"b.cfg"], 2, &["cannot be used with"]),
        run_cfg(
            "ransac-nan",
            "[tracking]\nransac_px = nan\n",
            &["[tracking] ransac_px = NaN: must be a finite number in (0, 1000] px"],
        ),
        run_cfg("features-zero", "[tracking]\nfeatures = 0\n", &["[tracking] features = 0"]),
        run_cfg("depth-reversed", "[tracking]\ndepth_range = [5.0, 1.0]\n", &["depth_range (far) = 1"]),
        run_cfg("depth-negative", "[tracking]\ndepth_range = [-1.0, 80.0]\n", &["depth_range (near) = -1"]),
        run_cfg("ratio", "[tracking]\nkeyframe_inlier_ratio = 1.5\n", &["keyframe_inlier_ratio = 1.5", "[0, 1]"]),
        run_cfg("offset-inf", "[tracking]\ndisparity_offset = inf\n", &["disparity_offset = inf"]),
        run_cfg("inliers", "[tracking]\nmin_inliers = 3\n", &["min_inliers = 3: must be at least 4"]),
        run_cfg("hamming", "[tracking]\nstereo_hamming = 300\n", &["stereo_hamming = 300", "[0, 256]"]),
        run_cfg(
            "parallax",
            "[tracking]\ntriangulate_parallax_deg = 90.0\n",
            &["triangulate_parallax_deg = 90", "(0, 90)"],
        ),
        run_cfg("window", "[mapping]\nwindow = 0\n", &["[mapping] window = 0"]),
        run_cfg("huber", "[mapping]\nhuber_px = 0.0\n", &["huber_px = 0", "(0, ∞)"]),
        run_cfg("iterations", "[mapping]\niterations = 0\n", &["iterations = 0"]),
        run_cfg("views", "[objects]\nmin_views = 3\nmax_views = 1\n", &["max_views = 1", "at least min_views"]),
        run_cfg("shape", "[objects]\nbox_shape = \"sphere\"\n", &["invalid configuration", "sphere"]),
        run_cfg("depth-m", "[objects]\nmax_depth_m = -inf\n", &["max_depth_m = -inf"]),
        run_cfg("every", "[system]\ndetect_every = 0\n", &["detect_every = 0"]),
        run_cfg("gate", "[system]\nprojected_gate = -0.1\n", &["projected_gate = -0.1"]),
        run_cfg("max-detections", "[system]\nmax_detections = 0\n", &["max_detections = 0"]),
        run_cfg("min-points", "[texture]\nmin_points = 2\n", &["min_points = 2"]),
        run_cfg("type", "[tracking]\nfeatures = \"many\"\n", &["invalid configuration", "features"]),
        run_cfg("negative-count", "[mapping]\nwindow = -1\n", &["invalid configuration", "window"]),
        run_cfg("truncated", "[tracking\nfeatures = 3", &["invalid configuration"]),
        run_cfg("unknown-table", "[trackin]\nfeatures = 3\n", &["invalid configuration", "trackin"]),
        case("config missing", &[&"run", &"--config", &d.join("none.toml")], 1, &["cannot read", "none.toml"]),
        case("config is a folder", &[&"run", &"--config", &d], 1, &["cannot read"]),
    ];
    let latin1 = d.join("latin1.toml");
    std::fs::write(&latin1, b"[tracking]\n# caf\xe9\n").expect("write");
    cases.push(case("config not UTF-8", &[&"run", &"--config", &latin1], 1, &["cannot read", "latin1.toml"]));
    // other commands' numbers
    let tracking = fixtures().join("kitti_tracking/0003");
    cases.extend([
        case(
            "objects --noise nan",
            &[&"objects", &tracking, &"--noise", &"nan"],
            1,
            &["--noise NaN: must be a finite number in [0, 1]"],
        ),
        case(
            "objects --dropout 2",
            &[&"objects", &tracking, &"--dropout", &"2"],
            1,
            &["--dropout 2: must be a finite number in [0, 1]"],
        ),
        case(
            "objects --min-parallax-deg -1",
            &[&"objects", &tracking, &"--min-parallax-deg=-1"],
            1,
            &["--min-parallax-deg -1"],
        ),
        case(
            "objects --dynamic-prior-sigmas inf",
            &[&"objects", &tracking, &"--dynamic-prior-sigmas", &"inf"],
            1,
            &["--dynamic-prior-sigmas inf"],
        ),
        case(
            "objects --without-parallax-after 0",
            &[&"objects", &tracking, &"--without-parallax-after", &"0"],
            1,
            &["--without-parallax-after 0"],
        ),
        case("objects --seed -1", &[&"objects", &tracking, &"--seed=-1"], 2, &["invalid value '-1'"]),
        case(
            "eval --static-m > --moving-m",
            &[&"eval", &"--static-m", &"5", &"--moving-m", &"3"],
            1,
            &["--static-m 5 exceeds --moving-m 3"],
        ),
        case(
            "eval --moving-m 0",
            &[&"eval", &"--moving-m", &"0"],
            1,
            &["--moving-m 0: must be a finite number in (0, 1000] m"],
        ),
        case("eval --min-frames 0", &[&"eval", &"--min-frames", &"0"], 1, &["--min-frames 0"]),
        case("eval --dropout nan", &[&"eval", &"--dropout", &"nan"], 1, &["--dropout NaN"]),
        case(
            "detect --input-size 32000",
            &[
                &"detect",
                &fixtures().join("kitti_raw_0052/2011_09_26/2011_09_26_drive_0052_sync"),
                &"--input-size",
                &"32000",
                &"--out",
                &d.join("d.json"),
            ],
            1,
            &["--input-size 32000"],
        ),
        case("sim --objects 0", &[&"sim", &"--objects", &"0", &"--out", &d.join("sim")], 1, &["--objects 0"]),
        case(
            "sim --noise-seeds 0",
            &[&"sim", &"--noise-seeds", &"0", &"--out", &d.join("sim")],
            1,
            &["--noise-seeds 0"],
        ),
        case(
            "stereo-check --range nan",
            &[&"stereo-check", &"--range", &"nan"],
            1,
            &["--range NaN: must be a finite number in (0, 10] px"],
        ),
        case("stereo-check --range inf", &[&"stereo-check", &"--range", &"inf"], 1, &["--range inf"]),
        case("stereo-check --step 0", &[&"stereo-check", &"--step", &"0"], 1, &["--step 0"]),
        case(
            "stereo-check --step > --range",
            &[&"stereo-check", &"--step", &"1", &"--range", &"0.5"],
            1,
            &["--step 1"],
        ),
        case("stereo-check --rounds 0", &[&"stereo-check", &"--rounds", &"0"], 1, &["--rounds 0"]),
        case(
            "stereo-check --max-frames 1",
            &[&"stereo-check", &"--max-frames", &"1"],
            1,
            &["--max-frames 1: must be at least 2"],
        ),
        case("assoc sim --frames 0", &[&"assoc", &"sim", &"--frames", &"0"], 1, &["--frames 0"]),
        case("assoc sim --scenes 0", &[&"assoc", &"sim", &"--scenes", &"0"], 1, &["--scenes 0"]),
        case("optim-bench --reps 0", &[&"optim-bench", &"--reps", &"0"], 1, &["--reps 0"]),
        case(
            "optim-bench --only nothing",
            &[&"optim-bench", &"--only", &"nothing"],
            1,
            &["matches no problem", "parking"],
        ),
        case(
            "optim-bench --data missing",
            &[&"optim-bench", &"--only", &"parking", &"--data", &"/no/such/optim"],
            1,
            &["/no/such/optim"],
        ),
    ]);
    let n = check(cases);
    assert!(n >= 60, "{n}");
    std::fs::remove_dir_all(&d).ok();
}

/// Sequences: missing, empty, not KITTI, calibration that cannot be right, images of the wrong size.
#[test]
fn sequences_calibration_and_image_sizes() {
    let d = scratch("sequences");
    let out = d.join("out");
    let run = |seq: &Path| -> Vec<OsString> {
        vec![
            "run".into(),
            "--detector".into(),
            "none".into(),
            seq.as_os_str().to_owned(),
            "--out".into(),
            out.clone().into(),
        ]
    };
    let as_refs = |v: &Vec<OsString>| -> Vec<OsString> { v.clone() };
    let mk = |name: &str, args: Vec<OsString>, want: &[&str]| Case {
        name: name.into(),
        args: as_refs(&args),
        code: 1,
        want: want.iter().map(|s| s.to_string()).collect(),
    };
    let empty = d.join("empty");
    std::fs::create_dir_all(&empty).expect("dir");
    let fx = sequence(&d, "fx", 2, Some(&calib_with("P0", 0, "0.001").replace("7.070912000000e+02 0.0", "0.001 0.0")));
    // the same intrinsics in both cameras (a rectified pair shares them), outside what the images allow
    let both = |index: usize, value: &str| {
        let one = calib_with("P0", index, value);
        let text: Vec<String> = one
            .lines()
            .map(|l| {
                if l.starts_with("P1:") {
                    let mut f: Vec<&str> = l.split_whitespace().collect();
                    f[1 + index] = value;
                    f.join(" ")
                } else {
                    l.to_string()
                }
            })
            .collect();
        text.join("\n")
    };
    let cx = sequence(&d, "cx", 2, Some(&both(2, "5000")));
    let cy = sequence(&d, "cy", 2, Some(&both(6, "-20")));
    let fy = sequence(&d, "fy", 2, Some(&both(5, "70")));
    let base = sequence(&d, "baseline", 2, Some(&calib_with("P1", 3, "0")));
    let nan = sequence(&d, "nan", 2, Some(&calib_with("P0", 0, "nan")));
    let short = sequence(
        &d,
        "short",
        2,
        Some(
            &calib_with("P0", 0, "707.0")
                .lines()
                .map(|l| if l.starts_with("P0") { "P0: 707 0 601 0 0" } else { l })
                .collect::<Vec<_>>()
                .join("\n"),
        ),
    );
    let no_p1 = sequence(
        &d,
        "nop1",
        2,
        Some(&calib_with("P0", 0, "707.0").lines().filter(|l| !l.starts_with("P1")).collect::<Vec<_>>().join("\n")),
    );
    let words = sequence(&d, "words", 2, Some(&calib_with("P0", 3, "zero")));
    // right images of another size (cropped by one column); the message names both files
    let sizes = sequence(&d, "sizes", 2, None);
    for i in 0..2 {
        let f = sizes.join(format!("image_1/{i:06}.png"));
        let mut img = slam_frontend::read_image(&f, false).expect("read");
        let w = img.width as usize;
        let data: Vec<u8> = img.data.chunks(w).flat_map(|r| r[..w - 1].to_vec()).collect();
        img = slam_core::Image::new(img.width - 1, img.height, 1, data).expect("image");
        slam_frontend::write_image(&f, &img).expect("write");
    }
    let blank = sequence(&d, "blank", 2, None);
    std::fs::write(blank.join("image_0/000000.png"), b"").expect("empty image");
    let noimg = sequence(&d, "noimg", 0, None);
    // a raw drive whose calibration declares another rectified image size
    let raw_src = fixtures().join("kitti_raw_0005/2011_09_26");
    let date = d.join("raw/2011_09_26");
    let drive = date.join("2011_09_26_drive_0005_sync");
    for cam in ["image_00", "image_01"] {
        std::fs::create_dir_all(drive.join(cam).join("data")).expect("dir");
        for i in 0..2 {
            let f = format!("{cam}/data/{i:010}.png");
            std::fs::copy(raw_src.join("2011_09_26_drive_0005_sync").join(&f), drive.join(&f)).expect("copy");
        }
    }
    let c2c = std::fs::read_to_string(raw_src.join("calib_cam_to_cam.txt")).expect("calib");
    write(
        &date.join("calib_cam_to_cam.txt"),
        &c2c.replace("S_rect_00: 1.242000e+03 3.750000e+02", "S_rect_00: 1.000000e+03 3.000000e+02"),
    );
    let cases = vec![
        mk("missing sequence", run(&d.join("nowhere")), &["nowhere", "not a folder"]),
        mk("empty folder", run(&empty), &["not a KITTI stereo sequence"]),
        mk("fx 0.001", run(&fx), &["calib.txt: focal length fx", "0.001", "field of view"]),
        mk("cx outside", run(&cx), &["principal point cx 5000", "inside the image", "000000.png is 1226×370"]),
        mk("cy negative", run(&cy), &["principal point cy -20"]),
        mk("fy far from fx", run(&fy), &["focal length fy 70", "within a factor 2 of fx"]),
        mk("baseline 0", run(&base), &["calib.txt", "baseline"]),
        mk("calibration NaN", run(&nan), &["calib.txt", "non-finite", "nan"]),
        mk("calibration truncated", run(&short), &["calib.txt", "P0"]),
        mk("calibration without P1", run(&no_p1), &["calib.txt", "P1"]),
        mk("calibration with a word", run(&words), &["calib.txt", "zero"]),
        mk(
            "right images of another size",
            run(&sizes),
            &["image sizes differ", "image_0/000000.png is 1226×370", "image_1/000000.png is 1225×370"],
        ),
        mk("empty first image", run(&blank), &["000000.png"]),
        mk("no images", run(&noimg), &["no PNG images"]),
        mk(
            "raw calibration declares another size",
            run(&drive),
            &["calib_cam_to_cam.txt: S_rect_00 declares 1000×300 images", "0000000000.png is 1242×375"],
        ),
        mk("stereo-check on wrong sizes", vec!["stereo-check".into(), sizes.clone().into()], &["image sizes differ"]),
        mk(
            "stereo-check on a bad calibration",
            vec!["stereo-check".into(), cx.clone().into()],
            &["principal point cx 5000"],
        ),
    ];
    check(cases);
    assert!(!out.exists(), "no output folder from failed runs");
    std::fs::remove_dir_all(&d).ok();
}

/// Output paths: unwritable, a file where a folder belongs and back, a folder holding foreign files,
/// nameless paths. All refused before any work.
#[test]
fn output_paths_are_checked_before_any_work() {
    let d = scratch("outputs");
    let file = write(&d.join("a-file"), "x");
    let foreign = d.join("foreign");
    write(&foreign.join("thesis.tex"), "x");
    write(&foreign.join("map.json"), "{}");
    let tracking = fixtures().join("kitti_tracking/0003");
    let raw = fixtures().join("kitti_raw_0052/2011_09_26/2011_09_26_drive_0052_sync");
    // /proc accepts no new entries, even from root
    let cases = vec![
        case(
            "run --out unwritable",
            &[&"run", &"--out", &"/proc/slam-out"],
            1,
            &["--out /proc/slam-out: cannot write in /proc"],
        ),
        case("run --out is a file", &[&"run", &"--out", &file], 1, &["is a file, not a folder"]),
        case(
            "run --out with foreign files",
            &[&"run", &"--out", &foreign],
            1,
            &["thesis.tex", "did not write", "replaced as a whole"],
        ),
        case("run --out .", &[&"run", &"--out", &"."], 1, &["name a folder of its own"]),
        case("run --out /", &[&"run", &"--out", &"/"], 1, &["name a folder of its own"]),
        case("objects --out unwritable", &[&"objects", &tracking, &"--out", &"/proc/o.json"], 1, &["/proc/o.json"]),
        case(
            "objects --out a folder",
            &[&"objects", &tracking, &"--out", &d],
            1,
            &["is a folder, expected a file name"],
        ),
        case("eval --csv unwritable", &[&"eval", &"--csv", &"/proc/e.csv"], 1, &["/proc/e.csv"]),
        case("detect --out unwritable", &[&"detect", &raw, &"--out", &"/proc/d.json"], 1, &["/proc/d.json"]),
        case(
            "detect --overlays is a file",
            &[&"detect", &raw, &"--out", &d.join("d.json"), &"--overlays", &file],
            1,
            &["--overlays", "is a file"],
        ),
        case("sim --out is a file", &[&"sim", &"--objects", &"1", &"--out", &file], 1, &["is a file, not a folder"]),
        case("sim --out with foreign files", &[&"sim", &"--objects", &"1", &"--out", &foreign], 1, &["thesis.tex"]),
        case("assoc kitti --csv unwritable", &[&"assoc", &"kitti", &"--csv", &"/proc/a.csv"], 1, &["/proc/a.csv"]),
    ];
    check(cases);
    assert!(!Path::new("/proc/slam-out").exists());
    assert_eq!(std::fs::read_to_string(foreign.join("thesis.tex")).expect("kept"), "x", "foreign files untouched");
    std::fs::remove_dir_all(&d).ok();
}

/// Files of the other commands: maps, trajectories, labels, poses, calibration, detections.
#[test]
fn files_of_every_command() {
    let d = scratch("files");
    let pose = "1 0 0 0 0 1 0 0 0 0 1 0";
    let map_ok = r#"{"format":"quadric-slam-map","version":2,"keyframes":{"0":{"frame":0,"pose":[0,0,0,1,0,0,0],"parent":null,"observations":[]}},"points":{},"objects":[],"trajectory":[{"frame":0,"keyframe":0,"relative":[0,0,0,1,0,0,0],"state":"initialised"}]}"#;
    let zero_q = write(&d.join("zero.json"), &map_ok.replacen("[0,0,0,1,0,0,0]", "[0,0,0,0,0,0,0]", 1));
    let bad_kf = write(&d.join("badkf.json"), &map_ok.replace(r#""keyframe":0"#, r#""keyframe":5"#));
    let other = write(&d.join("other.json"), r#"{"format":"something","version":2}"#);
    let trunc = write(&d.join("trunc.json"), &map_ok[..60]);
    let ok = write(&d.join("ok.json"), map_ok);
    let three = write(&d.join("three.txt"), "1 2 3\n");
    let nan_pose = write(&d.join("nan.txt"), &format!("{pose}\n1 0 0 nan 0 1 0 0 0 0 1 0\n"));
    let tum = write(&d.join("q.tum"), "0 0 0 0 0 0 0 2\n0.1 0 0 1 0 0 0 1\n");
    let empty = write(&d.join("empty.txt"), "");
    let one = write(&d.join("one.txt"), &format!("{pose}\n"));
    let gt = fixtures().join("kitti_odom_06/poses/06.txt");
    // a tracking folder with one thing wrong at a time
    let src = fixtures().join("kitti_tracking/0003");
    let seq_with = |name: &str, file: &str, text: &str| -> PathBuf {
        let dir = d.join(name);
        std::fs::create_dir_all(&dir).expect("dir");
        for f in ["label_02.txt", "poses_orbslam3.txt", "calib.txt"] {
            std::fs::copy(src.join(f), dir.join(f)).expect("copy");
        }
        std::fs::write(dir.join(file), text).expect("write");
        dir
    };
    let labels = std::fs::read_to_string(src.join("label_02.txt")).expect("labels");
    let poses = std::fs::read_to_string(src.join("poses_orbslam3.txt")).expect("poses");
    let calib = std::fs::read_to_string(src.join("calib.txt")).expect("calib");
    let nan_label = seq_with("nanlabel", "label_02.txt", &labels.replacen("320.980000", "nan", 1));
    let short_label = seq_with("shortlabel", "label_02.txt", "0 -1 DontCare -1\n");
    let few_poses = seq_with("fewposes", "poses_orbslam3.txt", &poses.lines().take(3).collect::<Vec<_>>().join("\n"));
    let bad_pose = seq_with("badpose", "poses_orbslam3.txt", &poses.replacen("0.000987017", "x", 1));
    let no_p2 =
        seq_with("nop2", "calib.txt", &calib.lines().filter(|l| !l.starts_with("P2")).collect::<Vec<_>>().join("\n"));
    let neg_p2 = seq_with("negp2", "calib.txt", &calib.replacen("P2: 7", "P2: -7", 1));
    let space_label = seq_with("spacelabel", "label_02.txt", &labels.replacen(" Car ", " Spaceship ", 1));
    let no_labels = d.join("nolabels");
    std::fs::create_dir_all(&no_labels).expect("dir");
    // a run folder that lost its objects.json
    let half_run = d.join("halfrun");
    std::fs::create_dir_all(&half_run).expect("dir");
    std::fs::write(half_run.join("trajectory.kitti.txt"), format!("{pose}\n")).expect("write");
    std::fs::write(half_run.join("camera.json"), "{}").expect("write");
    // detection files for `run --detector file` on 3 frames of the shipped sequence
    let det = |name: &str, text: &str| write(&d.join(format!("{name}.json")), text);
    let frame = |b: &str| {
        format!(r#"{{"version":1,"frames":[{{"frame":0,"detections":[{{"class":2,"score":0.9,"box":{b}}}]}}]}}"#)
    };
    let run_det = |p: &Path| -> Vec<OsString> {
        ["run", "--detector", "file", "--max-frames", "3", "--detections"]
            .iter()
            .map(|s| OsString::from(*s))
            .chain([p.as_os_str().to_owned(), "--out".into(), d.join("o").into()])
            .collect()
    };
    let det_cases: Vec<(&str, PathBuf, &str)> = vec![
        ("detections: reversed box", det("rev", &frame("[50, 10, 20, 40]")), "frame 0 detection 0"),
        (
            "detections: score 1.5",
            det("score", &frame("[10, 10, 20, 40]").replace("0.9", "1.5")),
            "score 1.5 outside [0, 1]",
        ),
        (
            "detections: version 7",
            det("ver", &frame("[10, 10, 20, 40]").replace(r#""version":1"#, r#""version":7"#)),
            "schema version 7",
        ),
        ("detections: truncated", det("trunc", &frame("[10, 10, 20, 40]")[..40]), "trunc.json:1"),
        (
            "detections: frame twice",
            det("twice", r#"{"version":1,"frames":[{"frame":0,"detections":[]},{"frame":0,"detections":[]}]}"#),
            "frame 0 appears twice",
        ),
        (
            "detections: class as text",
            det("class", &frame("[10, 10, 20, 40]").replace(r#""class":2"#, r#""class":"car""#)),
            "class.json",
        ),
        ("detections: box of 3", det("box3", &frame("[10, 10, 20]")), "box3.json"),
        (
            "detections: class 999",
            det("c999", &frame("[10, 10, 20, 40]").replace(r#""class":2"#, r#""class":999"#)),
            "frame 0 detection 0: class 999 is not a COCO class index (0-79)",
        ),
        (
            "detections: a mask not of the image's size",
            det(
                "mask10",
                &frame("[10, 10, 20, 40]").replace(
                    r#""box":[10, 10, 20, 40]"#,
                    r#""box":[10, 10, 20, 40],"mask":{"rle":{"size":[10,10],"counts":[100]}}"#,
                ),
            ),
            "detections for 10×10 images, but",
        ),
        (
            "detections: other image size",
            det(
                "size",
                &frame("[10, 10, 20, 40]").replace(r#""version":1,"#, r#""version":1,"image_size":[1242,375],"#),
            ),
            "detections for 1242×375 images, but",
        ),
        ("detections: missing file", d.join("absent.json"), "absent.json"),
    ];
    let mut cases: Vec<Case> = det_cases
        .into_iter()
        .map(|(name, p, want)| Case { name: name.into(), args: run_det(&p), code: 1, want: vec![want.into()] })
        .collect();
    cases.extend([
        case(
            "run --detector file without --detections",
            &[&"run", &"--detector", &"file"],
            1,
            &["--detector file needs --detections"],
        ),
        case(
            "run --detector labels without labels",
            &[&"run", &"--detector", &"labels", &"--out", &d.join("o")],
            1,
            &["has no labels"],
        ),
        case(
            "run --cfg missing",
            &[&"run", &"--cfg", &d.join("x.cfg"), &"--out", &d.join("o")],
            1,
            &["cannot load detector model", "x.cfg", "no such file"],
        ),
        case("map: missing", &[&"map", &d.join("none.json")], 1, &["none.json"]),
        case("map: zero quaternion", &[&"map", &zero_q], 1, &["zero.json: keyframes.0.pose: zero quaternion"]),
        case(
            "map: keyframe that does not exist",
            &[&"map", &bad_kf],
            1,
            &["badkf.json: trajectory[0].keyframe: keyframe 5 does not exist"],
        ),
        case("map: another format", &[&"map", &other], 1, &["other.json", "something"]),
        case("map: truncated", &[&"map", &trunc], 1, &["trunc.json", "line 1"]),
        case("map: not JSON", &[&"map", &three], 1, &["three.txt", "not a readable map file"]),
        case("map --trajectory onto a folder", &[&"map", &ok, &"--trajectory", &d], 1, &["slam-bad-files"]),
        case(
            "map --picture onto a file",
            &[&"map", &ok, &"--picture", &three],
            1,
            &["three.txt: is a file, expected a folder"],
        ),
        case("map --ply unwritable", &[&"map", &ok, &"--ply", &"/proc/p.ply"], 1, &["/proc/p.ply"]),
        case("trajectory-eval: missing", &[&"trajectory-eval", &d.join("none.txt"), &gt], 1, &["none.txt"]),
        case(
            "trajectory-eval: 3 numbers",
            &[&"trajectory-eval", &three, &gt],
            1,
            &["three.txt", "12 (KITTI) or 8 (TUM)"],
        ),
        case("trajectory-eval: NaN", &[&"trajectory-eval", &nan_pose, &gt], 1, &["nan.txt:2", "non-finite"]),
        case(
            "trajectory-eval: non-unit quaternion",
            &[&"trajectory-eval", &tum, &gt],
            1,
            &["q.tum:1", "quaternion is not unit"],
        ),
        case("trajectory-eval: empty", &[&"trajectory-eval", &empty, &gt], 1, &["empty.txt"]),
        case("trajectory-eval: one pose", &[&"trajectory-eval", &one, &gt], 1, &["fewer than two matched poses"]),
        case(
            "objects: NaN in a label",
            &[&"objects", &nan_label, &"--out", &d.join("x.json")],
            1,
            &["label_02.txt:1", "non-finite"],
        ),
        case(
            "objects: truncated label",
            &[&"objects", &short_label, &"--out", &d.join("x.json")],
            1,
            &["label_02.txt:1"],
        ),
        case(
            "objects: fewer poses than frames",
            &[&"objects", &few_poses, &"--out", &d.join("x.json")],
            1,
            &["poses_orbslam3.txt", "3 poses, but the labels of", "label_02.txt go up to frame"],
        ),
        case(
            "objects: word in a pose",
            &[&"objects", &bad_pose, &"--out", &d.join("x.json")],
            1,
            &["poses_orbslam3.txt:2", "not a number"],
        ),
        case(
            "objects: calibration without P2",
            &[&"objects", &no_p2, &"--out", &d.join("x.json")],
            1,
            &["calib.txt", "P2"],
        ),
        case("objects: missing folder", &[&"objects", &d.join("nope"), &"--out", &d.join("x.json")], 1, &["nope"]),
        case("eval: no sequences", &[&"eval", &no_labels], 1, &["is neither a sequence folder"]),
        case(
            "eval: a run folder without objects.json",
            &[&"eval", &half_run, &"--labels", &src.join("label_02.txt")],
            1,
            &["halfrun", "objects.json is missing"],
        ),
        case(
            "objects: negative focal length",
            &[&"objects", &neg_p2, &"--out", &d.join("x.json")],
            1,
            &["calib.txt", "focal lengths", "must be positive"],
        ),
        case(
            "objects: unknown label type",
            &[&"objects", &space_label, &"--out", &d.join("x.json")],
            1,
            &["label_02.txt:", "unknown type 'Spaceship'"],
        ),
        case(
            "trajectory-eval --max-diff nan",
            &[&"trajectory-eval", &gt, &gt, &"--max-diff", &"nan"],
            2,
            &["--max-diff", "not a finite number at least 0"],
        ),
        case("assoc kitti: no sequences", &[&"assoc", &"kitti", &no_labels], 1, &["is neither a sequence folder"]),
        case(
            "detect: empty folder",
            &[&"detect", &no_labels, &"--out", &d.join("d.json")],
            1,
            &["nor a folder of PNG/JPG images"],
        ),
    ]);
    check(cases);
    assert!(!d.join("x.json").exists() && !d.join("o").exists(), "failed commands write nothing");
    std::fs::remove_dir_all(&d).ok();
}

/// A number printed after `key` in `text`.
fn number_after(text: &str, key: &str) -> f64 {
    text.split(key)
        .nth(1)
        .and_then(|s| s.split(|c: char| c.is_whitespace() || c == ',' || c == ';').find(|w| !w.is_empty()))
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("`{key}` not followed by a number in:\n{text}"))
}

/// Detections the system cannot use are counted and reported, and the result does not change: boxes far
/// outside the image (refused), boxes across the border (clipped), more boxes than the per-frame limit
/// (the lowest scores dropped), frames beyond the sequence; and a frame of another size is unreadable
/// (counted, named) while the others run.
#[test]
fn counted_warnings_leave_the_result_unchanged() {
    let d = scratch("counted");
    let seq = sequence(&d, "seq", 4, None);
    let dets = |extra: &str, extra_frames: &str| {
        format!(
            r#"{{"version":1,"frames":[{{"frame":1,"detections":[{{"class":2,"score":0.9,"box":[500,150,600,250]}}{extra}]}}{extra_frames}]}}"#
        )
    };
    let plain = write(&d.join("plain.json"), &dets("", ""));
    // 120 low-scored boxes in frame 1, one box far outside (refused), one across the left border
    // (clipped): 122 boxes left, 22 over the limit of 100 (the lowest scores); and a frame far beyond the
    // 4-frame sequence
    let mut extra = String::new();
    for i in 0..120 {
        extra += &format!(r#",{{"class":2,"score":0.05,"box":[{x},10,{x2},20]}}"#, x = 5 * i, x2 = 5 * i + 4);
    }
    extra += r#",{"class":2,"score":0.5,"box":[5000,10,5100,40]},{"class":2,"score":0.4,"box":[-30,200,40,260]}"#;
    let noisy = write(
        &d.join("noisy.json"),
        &dets(&extra, r#",{"frame":500,"detections":[{"class":2,"score":0.9,"box":[1,1,50,50]}]}"#),
    );
    let run = |file: &Path, out: &str| {
        let o = app()
            .args(["run", "--detector", "file", "--detections"])
            .arg(file)
            .arg(&seq)
            .arg("--out")
            .arg(d.join(out))
            .output()
            .expect("runs");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (String::from_utf8_lossy(&o.stdout).to_string(), String::from_utf8_lossy(&o.stderr).to_string())
    };
    let (clean, _) = run(&plain, "plain");
    assert!(clean.contains("0 boxes clipped to the image, 0 refused (outside the image), 0 dropped"), "{clean}");
    let (text, err) = run(&noisy, "noisy");
    assert_eq!(number_after(&text, "detection bounds: ") as usize, 1, "one clipped: {text}");
    assert_eq!(number_after(&text, "clipped to the image, ") as usize, 1, "one refused: {text}");
    assert_eq!(number_after(&text, "(outside the image), ") as usize, 22, "{text}");
    assert!(text.contains("1 frames (1 boxes) lie after the last frame played, 3 (first: frame 500)"), "{text}");
    assert!(err.contains("lie after the last frame played"), "logged too: {err}");
    // the tracking result does not depend on the detections (their boxes only mask moving objects, and
    // none is moving here): both runs give the same trajectory
    let traj = |o: &str| std::fs::read_to_string(d.join(o).join("trajectory.kitti.txt")).expect("trajectory");
    assert_eq!(traj("plain"), traj("noisy"));
    // a frame of another size in the middle: unreadable, named, counted; the run goes on
    let f = seq.join("image_0/000002.png");
    let img = slam_frontend::read_image(&f, false).expect("read");
    let small = slam_core::Image::new(600, 200, 1, img.data[..600 * 200].to_vec()).expect("image");
    slam_frontend::write_image(&f, &small).expect("write");
    let f1 = seq.join("image_1/000002.png");
    slam_frontend::write_image(&f1, &small).expect("write");
    let o =
        app().args(["run", "--detector", "none"]).arg(&seq).arg("--out").arg(d.join("sized")).output().expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert_eq!(number_after(&text, "unreadable ") as usize, 1, "{text}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("000002.png is 600×200, the sequence's first frame 1226×370"), "{err}");
    assert_eq!(traj("sized").lines().count(), 4, "every frame has a pose");
    std::fs::remove_dir_all(&d).ok();
}
