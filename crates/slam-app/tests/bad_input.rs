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

/// The smallest valid map: one keyframe, one frame.
const MAP_OK: &str = r#"{"format":"quadric-slam-map","version":2,"keyframes":{"0":{"frame":0,"pose":[0,0,0,1,0,0,0],"parent":null,"observations":[]}},"points":{},"objects":[],"trajectory":[{"frame":0,"keyframe":0,"relative":[0,0,0,1,0,0,0],"state":"initialised"}]}"#;

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

/// Run `cmd` to its end, or kill it after `secs` seconds (a command that waits on a pipe must not hang
/// the suite): its output, and whether it had to be killed.
fn output_within(mut cmd: Command, secs: u64) -> (std::process::Output, bool) {
    use std::process::Stdio;
    let mut child = cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("starts");
    let start = std::time::Instant::now();
    let mut killed = false;
    while child.try_wait().expect("waits").is_none() {
        if start.elapsed().as_secs() >= secs {
            let _ = child.kill();
            killed = true;
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    (child.wait_with_output().expect("output"), killed)
}

/// Run every case (each within a minute); report all failures at once.
fn check(cases: Vec<Case>) -> usize {
    let mut failures = Vec::new();
    let n = cases.len();
    for c in cases {
        let mut cmd = app();
        cmd.args(&c.args);
        let (o, killed) = output_within(cmd, 60);
        if killed {
            failures.push(format!("{}: still running after 60 s (waiting on input?), killed", c.name));
            continue;
        }
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
            &["--input-size 32000: must be multiples of 32 in [32, 2048], each side"],
        ),
        case("--input-size 100", &[&"run", &"--input-size", &"100"], 1, &["--input-size 100: must be multiples of 32"]),
        case("--input-size -32", &[&"run", &"--input-size=-32"], 1, &["--input-size -32"]),
        case("--input-size 736x230", &[&"run", &"--input-size", &"736x230"], 1, &["--input-size 736x230: must be"]),
        case("--input-size 736x", &[&"run", &"--input-size", &"736x"], 2, &["expected WIDTHxHEIGHT (736x224) or N"]),
        case("--family without --onnx", &[&"run", &"--family", &"rows"], 2, &["--onnx"]),
        case("--model with --cfg", &[&"run", &"--model", &"yolox-nano", &"--cfg", &"a.cfg"], 2, &["--cfg"]),
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
        run_cfg("ratio", "[tracking]\nkeyframe_tracked_ratio = 1.5\n", &["keyframe_tracked_ratio = 1.5", "[0, 1]"]),
        run_cfg("offset-inf", "[tracking]\ndisparity_offset = inf\n", &["disparity_offset = inf"]),
        run_cfg("inliers", "[tracking]\nmin_inliers = 3\n", &["min_inliers = 3: must be at least 4"]),
        run_cfg("hamming", "[tracking]\nstereo_hamming = 300\n", &["stereo_hamming = 300", "[0, 256]"]),
        run_cfg("local", "[tracking]\nlocal_keyframes = 0\n", &["local_keyframes = 0", "[1, 1000]"]),
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
    let map_ok = MAP_OK;
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
        case("run --map missing", &[&"run", &"--map", &d.join("none.json"), &"--out", &d.join("o")], 1, &["none.json"]),
        case("run --localise-only without --map", &[&"run", &"--localise-only"], 2, &["--map"]),
        case(
            "run --map of a map without features",
            &[&"run", &"--map", &ok, &"--out", &d.join("o")],
            1,
            &["no keyframe features to track against", "version 2"],
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
            &["label_02.txt:", "is not a frame of the sequence", "the 3 poses of", "poses_orbslam3.txt"],
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

// ---- Issue 33: bad input, round two ----

/// The app under `sh`, with `setup` run first (limits: `ulimit -v`, `ulimit -f`); SIGXFSZ ignored, so a
/// write past the file-size limit fails as on a full disk instead of killing the process.
fn app_under(setup: &str) -> Command {
    let mut c = Command::new("sh");
    c.current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    c.arg("-c").arg(format!("trap '' XFSZ; {setup}; exec \"$0\" \"$@\"")).arg(env!("CARGO_BIN_EXE_slam-app"));
    c
}

/// Run `cmd`; its exit status, stdout and stderr.
fn run_cmd(cmd: Command) -> (i32, String, String) {
    let (o, killed) = output_within(cmd, 120);
    assert!(!killed, "still running after 120 s: killed");
    let text = |b: &[u8]| String::from_utf8_lossy(b).to_string();
    (o.status.code().unwrap_or(-1), text(&o.stdout), text(&o.stderr))
}

/// The names in a folder, sorted.
fn names_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| rd.flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

/// Every file under `dir` with its bytes (inputs compared before and after the cases).
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("list").flatten() {
            let p = e.path();
            let t = std::fs::symlink_metadata(&p).expect("meta").file_type();
            if t.is_dir() {
                stack.push(p);
            } else if t.is_file() {
                out.push((p.clone(), std::fs::read(&p).expect("read")));
            }
        }
    }
    out.sort();
    out
}

/// A column of a run's tracking.csv.
fn csv_column(dir: &Path, column: &str) -> Vec<String> {
    let text = std::fs::read_to_string(dir.join("tracking.csv")).expect("tracking.csv");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let head: Vec<&str> = lines.next().expect("header").split(',').collect();
    let k = head.iter().position(|h| *h == column).expect("column");
    lines.map(|l| l.split(',').nth(k).unwrap_or_default().to_string()).collect()
}

/// Class 1: one image pair named 4294967296.png among frames 0-3 took 8.5 GB (the gap list held every
/// missing id); with 2 GB of address space the run now plays all five frames, with --frames too, and the
/// largest frame id in a range does not overflow.
#[test]
fn frame_ids_far_apart_cost_no_memory() {
    let d = scratch("far-ids");
    let seq = sequence(&d, "seq", 4, None);
    for cam in ["image_0", "image_1"] {
        std::fs::copy(seq.join(cam).join("000003.png"), seq.join(cam).join("4294967296.png")).expect("copy");
    }
    let limited = |extra: &[&str], out: &str| {
        let mut c = app_under("ulimit -v 2000000");
        c.args(["run", "--detector", "none"]).arg(&seq).args(extra).arg("--out").arg(d.join(out));
        run_cmd(c)
    };
    let (code, text, err) = limited(&[], "all");
    assert_eq!(code, 0, "{err}");
    assert!(text.contains("4294967292 frame(s) missing in both cameras"), "{text}");
    assert_eq!(csv_column(&d.join("all"), "frame"), ["0", "1", "2", "3", "4294967296"]);
    let (code, _, err) = limited(&["--frames", "0..3"], "three");
    assert_eq!(code, 0, "{err}");
    assert_eq!(csv_column(&d.join("three"), "frame"), ["0", "1", "2"]);
    let (code, _, err) = limited(&["--frames", &format!("2..={}", usize::MAX)], "to-the-end");
    assert_eq!(code, 0, "{err}");
    assert_eq!(csv_column(&d.join("to-the-end"), "frame"), ["2", "3", "4294967296"]);
    std::fs::remove_dir_all(&d).ok();
}

/// Class 1, round three: one label at frame 10^8 made `assoc kitti` loop for minutes and one at
/// 2^64 - 1 made `eval` panic (index out of bounds) and `objects` drop it silently; `--frames ..0`
/// wrapped to every frame; an image pair named 2^64 - 1 said a pose file "needs at least 0 lines".
#[test]
fn one_frame_id_neither_panics_nor_hangs() {
    let d = scratch("one-id");
    let mut cases = Vec::new();
    for (name, frame) in [("huge", "100000000"), ("max", "18446744073709551615")] {
        let seq = d.join(name).join("0003");
        for f in ["label_02.txt", "poses_orbslam3.txt", "calib.txt"] {
            let text = std::fs::read_to_string(fixtures().join("kitti_tracking/0003").join(f)).expect("fixture");
            write(&seq.join(f), &text);
        }
        let labels = std::fs::read_to_string(seq.join("label_02.txt")).expect("labels");
        let extra = format!("{frame} 99 Car 0 0 -1.57 588.2 177.8 624.0 212.3 1.60 1.66 3.55 -0.22 1.86 35.6 -1.57\n");
        write(&seq.join("label_02.txt"), &format!("{labels}{extra}"));
        let want = ["label_02.txt:862:", "is not a frame of the sequence", "144 frame(s)"];
        cases.push(case(&format!("eval, label at {frame}"), &[&"eval", &seq], 1, &want));
        cases.push(case(
            &format!("objects, label at {frame}"),
            &[&"objects", &seq, &"--out", &d.join("o.json")],
            1,
            &want,
        ));
        cases.push(case(&format!("assoc kitti, label at {frame}"), &[&"assoc", &"kitti", &seq], 1, &want));
    }
    let seq = sequence(&d, "seq", 3, None);
    let poses: String = (0..3).map(|i| format!("1 0 0 0 0 1 0 0 0 0 1 {i}\n")).collect();
    let truth = write(&d.join("seq/poses/06.txt"), &poses);
    let out = d.join("out");
    cases.push(case(
        "run --frames ..0",
        &[&"run", &seq, &"--frames", &"..0", &"--out", &out],
        2,
        &["'..0' holds no frame"],
    ));
    cases.push(case(
        "trajectory-eval --frames ..0",
        &[&"trajectory-eval", &truth, &truth, &"--frames", &"..0"],
        2,
        &["'..0' holds no frame"],
    ));
    assert_eq!(check(cases), 8);
    // an image pair named 2^64 - 1 beside frames 0-2: the pose file's shortfall is said without overflow
    for cam in ["image_0", "image_1"] {
        std::fs::copy(seq.join(cam).join("000002.png"), seq.join(cam).join("18446744073709551615.png")).expect("copy");
    }
    let mut c = app();
    c.args(["run", "--detector", "none"]).arg(&seq).arg("--out").arg(d.join("max-id"));
    let (code, _, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("at least 18446744073709551616 lines") && !err.contains("at least 0 lines"), "{err}");
    std::fs::remove_dir_all(&d).ok();
}

/// A tracking sequence folder (copy of fixture 0003) with `edit` applied to one of its files.
fn tracking_with(root: &Path, name: &str, file: &str, edit: &dyn Fn(&str) -> String) -> PathBuf {
    let dir = root.join(name);
    for f in ["label_02.txt", "poses_orbslam3.txt", "calib.txt"] {
        let text = std::fs::read_to_string(fixtures().join("kitti_tracking/0003").join(f)).expect("fixture");
        write(&dir.join(f), &if f == file { edit(&text) } else { text });
    }
    dir
}

/// Replace field `k` (0-based, after the key for calibrations) of line `line` (0-based) of `text`.
fn with_field(text: &str, line: usize, k: usize, value: &str) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let mut f: Vec<String> = lines[line].split_whitespace().map(str::to_string).collect();
    f[k] = value.to_string();
    lines[line] = f.join(" ");
    lines.join("\n") + "\n"
}

/// Class 5, round three: figures that came out silently wrong. A TUM estimate against KITTI ground
/// truth was paired by line (a strided run's ATE 3.671 m instead of 0.119); a pose 1 km off, a label
/// 500 m high, a tracking calibration no camera has, a NaN in a calibration row not used, frame times
/// of 1e300 s were all accepted; a reflection was "not a rotation" without saying so.
#[test]
fn figures_that_cannot_be_right_round_three() {
    let d = scratch("round3");
    // P2 and P3 alike (lines 3 and 4): a pair whose cameras agree, which no camera has
    let calib_edit = |k: usize, v: &'static str| move |t: &str| with_field(&with_field(t, 2, k, v), 3, k, v);
    let mut cases = Vec::new();
    // P2 is line 2 of the tracking calibration: skew, fy = fx / 10, cx far outside, third row
    for (name, k, v, want) in [
        ("skew", 2, "1e308", "skew"),
        ("fy", 6, "72.15377", "a rectified pair's cameras differ along x only"),
        ("cx", 3, "50000", "principal point"),
        ("third", 11, "2", "third row"),
    ] {
        let dir = tracking_with(&d, &format!("calib-{name}"), "calib.txt", &calib_edit(k, v));
        cases.push(case(&format!("eval, P2 {name}"), &[&"eval", &dir], 1, &["calib.txt", want]));
        let out = d.join("o.json");
        cases.push(case(&format!("objects, P2 {name}"), &[&"objects", &dir, &"--out", &out], 1, &[want]));
    }
    let jump = tracking_with(&d, "pose-jump", "poses_orbslam3.txt", &|t| {
        let z: f64 = t.lines().nth(40).expect("line").split_whitespace().nth(11).expect("z").parse().expect("z");
        with_field(t, 40, 11, &(z + 1000.0).to_string())
    });
    let want = ["poses_orbslam3.txt:41:", "moved 100", "at most 10 m a frame"];
    cases.push(case("objects, a pose 1 km off", &[&"objects", &jump, &"--out", &d.join("o.json")], 1, &want));
    cases.push(case("eval, a pose 1 km off", &[&"eval", &jump], 1, &want));
    let tall = tracking_with(&d, "tall", "label_02.txt", &|t| with_field(t, 4, 10, "500"));
    cases.push(case(
        "eval, a box 500 m high",
        &[&"eval", &tall],
        1,
        &["label_02.txt:5:", "height 500 m", "at most 5 m"],
    ));
    // the odometry layout: a NaN in P2, which it does not use; times of 1e300 s; a ground-truth jump
    let calib = std::fs::read_to_string(fixtures().join("kitti_odom_06/sequences/06/calib.txt")).expect("calib");
    let unused_row = format!("{}\nP2: 707 0 601 nan 0 707 183 0 0 0 1 0\n", calib.trim_end());
    let seq = sequence(&d, "nan", 2, Some(&unused_row));
    cases.push(case(
        "run, NaN in P2",
        &[&"run", &seq, &"--detector", &"none", &"--out", &d.join("x")],
        1,
        &["calib.txt:3:", "non-finite"],
    ));
    let seq = sequence(&d, "times", 2, None);
    write(&seq.join("times.txt"), "0.0\n1e300\n");
    cases.push(case(
        "run, a time of 1e300 s",
        &[&"run", &seq, &"--detector", &"none", &"--out", &d.join("x")],
        1,
        &["times.txt:2:", "at most 1e10 s"],
    ));
    let seq = sequence(&d, "gt-jump", 3, None);
    write(
        &d.join("gt-jump/poses/06.txt"),
        "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 1000\n1 0 0 0 0 1 0 0 0 0 1 1001\n",
    );
    cases.push(case(
        "run, ground truth 1 km off",
        &[&"run", &seq, &"--detector", &"none", &"--out", &d.join("x")],
        1,
        &["06.txt:2:", "moved 1000.0 m"],
    ));
    let mirror = write(&d.join("mirror.txt"), "-1 0 0 0 0 1 0 0 0 0 1 0\n");
    cases.push(case(
        "trajectory-eval, a reflection",
        &[&"trajectory-eval", &mirror, &mirror],
        1,
        &["det = -1.000", "a reflection"],
    ));
    // stereo-check on 14 copies of one frame: one view, no interval to give (was -0.692 ± 0.000 px)
    let copies = sequence(&d, "copies", 1, None);
    for cam in ["image_0", "image_1"] {
        for i in 1..14 {
            std::fs::copy(copies.join(cam).join("000000.png"), copies.join(cam).join(format!("{i:06}.png")))
                .expect("copy");
        }
    }
    cases.push(case(
        "stereo-check on copies of one frame",
        &[&"stereo-check", &copies],
        1,
        &["13 of 14 frames repeat an earlier frame's images exactly"],
    ));
    // TUM times in nanoseconds against seconds: the error gives both files' spans
    let secs = write(&d.join("s.tum"), "0.0 0 0 0 0 0 0 1\n0.1 1 0 0 0 0 0 1\n0.2 2 0 0 0 0 0 1\n");
    let nanos = write(&d.join("ns.tum"), "0 0 0 0 0 0 0 1\n100000000 1 0 0 0 0 0 1\n200000000 2 0 0 0 0 0 1\n");
    cases.push(case(
        "trajectory-eval, nanoseconds against seconds",
        &[&"trajectory-eval", &nanos, &secs],
        1,
        &[
            "fewer than two matched poses",
            "ns.tum spans times 0 to 200000000 s",
            "s.tum spans times 0 to 0.2 s",
            "nanoseconds",
        ],
    ));
    // a wrong JSON type or a missing field is named by its path in the document
    let dets = write(&d.join("frames-map.json"), r#"{"version": 1, "frames": {}}"#);
    let seq = sequence(&d, "dets", 2, None);
    cases.push(case(
        "detections with \"frames\": {}",
        &[&"run", &seq, &"--detections", &dets, &"--out", &d.join("x")],
        1,
        &["frames-map.json:1: frames: invalid type: map, expected a sequence"],
    ));
    let bare = write(&d.join("bare.json"), &MAP_OK.replace(r#""objects":[]"#, r#""objects":[{"id":1}]"#));
    cases.push(case("map object without its fields", &[&"map", &bare], 1, &["objects[0]: missing field `class`"]));
    assert_eq!(check(cases), 19);
    // an OXTS packet that is a folder is said to be one, not "missing"
    let raw = fixtures().join("kitti_raw_0005/2011_09_26");
    let date = d.join("raw-folder/2011_09_26");
    let drive = date.join("2011_09_26_drive_0005_sync");
    for f in ["calib_cam_to_cam.txt", "calib_imu_to_velo.txt", "calib_velo_to_cam.txt"] {
        write(&date.join(f), &std::fs::read_to_string(raw.join(f)).expect("calib"));
    }
    for i in 0..3 {
        for cam in ["image_00", "image_01"] {
            let f = format!("{cam}/data/{i:010}.png");
            std::fs::create_dir_all(drive.join(cam).join("data")).expect("dir");
            std::fs::copy(raw.join("2011_09_26_drive_0005_sync").join(&f), drive.join(&f)).expect("copy");
        }
        let p = format!("oxts/data/{i:010}.txt");
        if i == 1 {
            std::fs::create_dir_all(drive.join(&p)).expect("folder");
        } else {
            std::fs::copy(raw.join("2011_09_26_drive_0005_sync").join(&p), write(&drive.join(&p), "")).expect("packet");
        }
    }
    let ts = std::fs::read_to_string(raw.join("2011_09_26_drive_0005_sync/image_00/timestamps.txt")).expect("ts");
    write(&drive.join("image_00/timestamps.txt"), &ts);
    let mut c = app();
    c.args(["run", "--detector", "none"]).arg(&drive).arg("--out").arg(d.join("raw-out"));
    let (code, _, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("0000000001.txt") && err.contains("a folder") && !err.contains("is missing"), "{err}");
    // depth-check: frame 1's scan missing, frame 2's a link to /dev/zero: skipped, logged and counted
    let src = raw.join("2011_09_26_drive_0005_sync");
    let scans = drive.join("velodyne_points/data");
    std::fs::create_dir_all(&scans).expect("dir");
    std::fs::copy(src.join("velodyne_points/data/0000000000.bin"), scans.join("0000000000.bin")).expect("scan");
    #[cfg(unix)]
    std::os::unix::fs::symlink("/dev/zero", scans.join("0000000002.bin")).expect("link");
    let mut c = app();
    c.arg("depth-check").arg(&drive);
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert!(text.contains("2 of 3 frames skipped without a readable Velodyne scan (first: frame 1"), "{text}");
    assert!(err.contains("0000000002.bin") && err.contains("character device"), "{err}");
    // a strided run's TUM file against the KITTI ground truth: matched by time, the figures of the
    // KITTI file matched with the run's own --frames/--stride
    let seq = sequence(&d, "strided", 6, None);
    let poses = std::fs::read_to_string(fixtures().join("kitti_odom_06/poses/06.txt")).expect("poses");
    let truth =
        write(&d.join("strided/poses/06.txt"), &poses.lines().take(6).map(|l| format!("{l}\n")).collect::<String>());
    let mut c = app();
    c.args(["run", "--detector", "none", "--frames", "0..6", "--stride", "2"]).arg(&seq).arg("--out").arg(d.join("s2"));
    let (code, _, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    let ate = |est: &str, extra: &[&str]| {
        let mut c = app();
        c.arg("trajectory-eval").arg(d.join("s2").join(est)).arg(&truth).args(extra);
        let (code, text, err) = run_cmd(c);
        assert_eq!(code, 0, "{err}");
        (number_after(&text, "| ATE (first poses aligned) | "), text)
    };
    let (by_time, text) = ate("trajectory.tum.txt", &[]);
    assert!(text.contains("matched to the TUM estimate by time") && text.contains("by timestamp"), "{text}");
    let (by_line, _) = ate("trajectory.kitti.txt", &["--frames", "0..6", "--stride", "2"]);
    assert_eq!(by_time, by_line, "{text}");
    std::fs::remove_dir_all(&d).ok();
}

/// Class 2: an output that is, or resolves to, an input of the same command is refused before anything
/// is read, for every command that writes files; the inputs are byte for byte what they were.
#[test]
fn no_output_is_an_input() {
    let d = scratch("overwrite");
    let run = d.join("run");
    let map = write(&run.join("map.json"), MAP_OK);
    write(&run.join("notes.txt"), "mine");
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(&map, d.join("link.json")).expect("symlink");
        std::fs::hard_link(&map, d.join("hard.json")).expect("hard link");
    }
    let tracking = d.join("tracking/0003");
    for f in ["label_02.txt", "poses_orbslam3.txt", "calib.txt"] {
        let text = std::fs::read_to_string(fixtures().join("kitti_tracking/0003").join(f)).expect("fixture");
        write(&tracking.join(f), &text);
    }
    let images = d.join("images");
    std::fs::create_dir_all(&images).expect("dir");
    let raw = fixtures().join("kitti_raw_0052/2011_09_26/2011_09_26_drive_0052_sync/image_02/data");
    for f in ["0000000007.png", "0000000014.png"] {
        std::fs::copy(raw.join(f), images.join(f)).expect("copy");
    }
    let seq = sequence(&d, "seq", 2, None);
    let config = write(&d.join("out/run.toml"), "[tracking]\nfeatures = 1000\n");
    let picture_map = write(&d.join("pic/map.svg"), MAP_OK);
    let input = "an input of this command";
    let dotted = run.join("..").join("run").join(".").join("map.json");
    let cases = vec![
        case("map --ply onto the map", &[&"map", &map, &"--ply", &map], 1, &["--ply", "is the map", input]),
        case("map --trajectory onto the map", &[&"map", &map, &"--trajectory", &map], 1, &["--trajectory", input]),
        case("map --scene onto the map", &[&"map", &map, &"--scene", &map], 1, &["--scene", input]),
        case("map --ply through ../ and ./", &[&"map", &map, &"--ply", &dotted], 1, &["which is", input]),
        case("map --ply through a symbolic link", &[&"map", &map, &"--ply", &d.join("link.json")], 1, &[input]),
        case("map --ply through a hard link", &[&"map", &map, &"--ply", &d.join("hard.json")], 1, &[input]),
        case(
            "map --ply and --scene in one file",
            &[&"map", &map, &"--ply", &d.join("x.ply"), &"--scene", &d.join("./x.ply")],
            1,
            &["--scene", "also the file of --ply"],
        ),
        case(
            "map --picture onto the map's own name",
            &[&"map", &picture_map, &"--picture", &d.join("pic")],
            1,
            &["--picture", input],
        ),
        case(
            "objects --out onto the labels",
            &[&"objects", &tracking, &"--out", &tracking.join("label_02.txt")],
            1,
            &["is the labels", input],
        ),
        case(
            "objects --out onto the poses",
            &[&"objects", &tracking, &"--out", &tracking.join("poses_orbslam3.txt")],
            1,
            &["is the poses", input],
        ),
        case(
            "objects --out onto the calibration",
            &[&"objects", &tracking, &"--out", &tracking.join("calib.txt")],
            1,
            &["is the calibration", input],
        ),
        case(
            "eval --csv onto a sequence's labels",
            &[&"eval", &d.join("tracking"), &"--csv", &tracking.join("label_02.txt")],
            1,
            &["--csv", input],
        ),
        case(
            "assoc kitti --csv onto the labels",
            &[&"assoc", &"kitti", &d.join("tracking"), &"--csv", &tracking.join("label_02.txt")],
            1,
            &["--csv", input],
        ),
        case(
            "detect --out onto an image",
            &[&"detect", &images, &"--out", &images.join("0000000014.png")],
            1,
            &["is an input image", input],
        ),
        case(
            "detect --overlays onto the image folder",
            &[&"detect", &images, &"--out", &d.join("d.json"), &"--overlays", &images],
            1,
            &["--overlays", "holds the input folder"],
        ),
        case(
            "run --out holding the sequence",
            &[&"run", &seq, &"--detector", &"none", &"--out", &d.join("seq")],
            1,
            &["--out", "holds the sequence"],
        ),
        case(
            "run --out holding its --config",
            &[&"run", &seq, &"--detector", &"none", &"--config", &config, &"--out", &d.join("out")],
            1,
            &["holds --config"],
        ),
        case(
            "run --out holding its --labels",
            &[&"run", &seq, &"--labels", &tracking.join("label_02.txt"), &"--out", &d.join("tracking")],
            1,
            &["holds --labels"],
        ),
    ];
    let mut cases = cases;
    // through a folder that does not exist yet: `nx/..` is the input's folder once the program makes `nx`
    let right = d.join("right");
    std::fs::create_dir_all(&right).expect("dir");
    std::fs::copy(raw.join("0000000007.png"), right.join("0000000007.png")).expect("copy");
    let own_run = d.join("own-run");
    write(&own_run.join("map.json"), MAP_OK);
    write(&own_run.join("trajectory.kitti.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n");
    let own_sim = d.join("own-sim");
    write(&own_sim.join("simulation.csv"), "mine\n");
    let model = write(&d.join("model/my.cfg"), "[net]\n");
    write(&seq.join("times.txt"), "0.0\n0.1\n");
    cases.extend([
        case(
            "objects --out through a new folder's ..",
            &[&"objects", &tracking, &"--out", &tracking.join("nx/../poses_orbslam3.txt")],
            1,
            &["is the poses", input],
        ),
        case(
            "map --ply through a new folder's ..",
            &[&"map", &map, &"--ply", &run.join("nx/../map.json")],
            1,
            &[input],
        ),
        case(
            "eval --csv through a new folder's ..",
            &[&"eval", &d.join("tracking"), &"--csv", &tracking.join("nx2/../label_02.txt")],
            1,
            &["--csv", input],
        ),
        case(
            "detect --out through a new folder's ..",
            &[&"detect", &images, &"--out", &images.join("nx3/../0000000007.png")],
            1,
            &["is an input image", input],
        ),
        case(
            "detect --overlays through a new folder's ..",
            &[&"detect", &images, &"--out", &d.join("d.json"), &"--overlays", &d.join("nx/../images")],
            1,
            &["--overlays", "holds the input folder"],
        ),
        // a folder without the marker is never replaced, even with only names the command writes
        case(
            "detect --overlays onto another camera's images",
            &[&"detect", &images, &"--out", &d.join("d.json"), &"--overlays", &right],
            1,
            &["--overlays", "0000000007.png", ".slam-app-output"],
        ),
        case(
            "run --out onto a user's own map.json",
            &[&"run", &seq, &"--detector", &"none", &"--out", &own_run],
            1,
            &["--out", "map.json, trajectory.kitti.txt", ".slam-app-output"],
        ),
        case("sim --out onto a user's simulation.csv", &[&"sim", &"--out", &own_sim], 1, &["simulation.csv"]),
        // model files are inputs; files inside an input folder are the dataset's
        case(
            "detect --out onto its --cfg",
            &[&"detect", &images, &"--cfg", &model, &"--out", &model],
            1,
            &["--cfg", input],
        ),
        case(
            "detect --out onto a sequence's times.txt",
            &[&"detect", &seq, &"--out", &seq.join("times.txt")],
            1,
            &["inside the input folder", "choose a file outside it"],
        ),
        case(
            "assoc kitti --csv onto a calibration it does not read",
            &[&"assoc", &"kitti", &d.join("tracking"), &"--csv", &tracking.join("calib.txt")],
            1,
            &["is the sequence file", input],
        ),
    ]);
    let before = snapshot(&d);
    let n = check(cases);
    assert_eq!(n, 29);
    for made in [tracking.join("nx"), run.join("nx"), tracking.join("nx2"), images.join("nx3"), d.join("nx")] {
        assert!(!made.exists(), "{} was created", made.display());
    }
    let after = snapshot(&d);
    let names = |v: &[(PathBuf, Vec<u8>)]| v.iter().map(|f| f.0.clone()).collect::<Vec<_>>();
    assert_eq!(names(&before), names(&after), "files made or lost");
    let changed: Vec<&PathBuf> = before.iter().zip(&after).filter(|(a, b)| a != b).map(|(a, _)| &a.0).collect();
    assert!(changed.is_empty(), "inputs changed: {changed:?}");
    std::fs::remove_dir_all(&d).ok();
}

/// Class 3: every reader takes only regular files and at most its limit: /dev/zero, a named pipe, a
/// folder, a link that loops and files past their limit are refused at once, naming what they are (or
/// the limit), and an image that is no file is an unreadable frame with that reason.
#[test]
fn readers_take_regular_files_within_a_limit() {
    let d = scratch("readers");
    let zero = Path::new("/dev/zero");
    let pipe = d.join("pipe");
    assert!(Command::new("mkfifo").arg(&pipe).status().expect("mkfifo").success());
    let big_map = d.join("big.json");
    std::fs::File::create(&big_map).expect("file").set_len(2 << 30).expect("sparse 2 GiB");
    let big_config = write(&d.join("big.toml"), &format!("# {}\n", "x".repeat(2 << 20)));
    let tracking = fixtures().join("kitti_tracking/0003");
    let gt = fixtures().join("kitti_odom_06/poses/06.txt");
    let out = d.join("o");
    let device = "it is a character device, not a regular file";
    let named = "it is a named pipe, not a regular file";
    let mut cases = vec![
        case("run --config /dev/zero", &[&"run", &"--config", &zero, &"--out", &out], 1, &[device]),
        case("run --config a pipe", &[&"run", &"--config", &pipe, &"--out", &out], 1, &[named]),
        case("run --config 2 MiB", &[&"run", &"--config", &big_config, &"--out", &out], 1, &["more than the 1 MiB"]),
        case("run --config a folder", &[&"run", &"--config", &d, &"--out", &out], 1, &["it is a folder"]),
        case(
            "run --detections /dev/zero",
            &[&"run", &"--detections", &zero, &"--max-frames", &"2", &"--out", &out],
            1,
            &[device],
        ),
        case(
            "run --detections a pipe",
            &[&"run", &"--detections", &pipe, &"--max-frames", &"2", &"--out", &out],
            1,
            &[named],
        ),
        case(
            "run --labels /dev/zero",
            &[&"run", &"--detector", &"none", &"--labels", &zero, &"--max-frames", &"2", &"--out", &out],
            1,
            &[device],
        ),
        case(
            "run --cfg /dev/zero",
            &[&"run", &"--cfg", &zero, &"--out", &out],
            1,
            &["cannot load detector model", "character device"],
        ),
        case(
            "run --onnx a pipe",
            &[&"run", &"--onnx", &pipe, &"--out", &out],
            1,
            &["cannot load detector model", "named pipe"],
        ),
        case("trajectory-eval /dev/zero", &[&"trajectory-eval", &zero, &gt], 1, &[device]),
        case("trajectory-eval against a pipe", &[&"trajectory-eval", &gt, &pipe], 1, &[named]),
        case("map /dev/zero", &[&"map", &zero], 1, &[device]),
        case("map a pipe", &[&"map", &pipe], 1, &[named]),
        case("map of 2 GiB", &[&"map", &big_map], 1, &["holds 2147483648 bytes", "more than the 1 GiB"]),
        case(
            "objects --poses /dev/zero",
            &[&"objects", &tracking, &"--poses", &zero, &"--out", &d.join("x.json")],
            1,
            &[device],
        ),
        case(
            "objects --calib a pipe",
            &[&"objects", &tracking, &"--calib", &pipe, &"--out", &d.join("x.json")],
            1,
            &[named],
        ),
        case(
            "objects --labels /dev/zero",
            &[&"objects", &tracking, &"--labels", &zero, &"--out", &d.join("x.json")],
            1,
            &[device],
        ),
        case("stereo-check --config a pipe", &[&"stereo-check", &"--config", &pipe], 1, &[named]),
    ];
    // a calibration that is a pipe, in an otherwise whole sequence
    let seq = sequence(&d, "pipecalib", 2, None);
    std::fs::remove_file(seq.join("calib.txt")).expect("rm");
    assert!(Command::new("mkfifo").arg(seq.join("calib.txt")).status().expect("mkfifo").success());
    cases.push(case("a sequence whose calib.txt is a pipe", &[&"run", &seq, &"--out", &out], 1, &[named]));
    check(cases);
    // images that are no files: frame 1 a folder, frame 2 a link to itself, frame 3 a pipe; the run goes on
    let seq = sequence(&d, "images", 5, None);
    let left = seq.join("image_0");
    std::fs::remove_file(left.join("000001.png")).expect("rm");
    std::fs::create_dir(left.join("000001.png")).expect("folder");
    std::fs::remove_file(left.join("000002.png")).expect("rm");
    #[cfg(unix)]
    std::os::unix::fs::symlink("000002.png", left.join("000002.png")).expect("self-link");
    std::fs::remove_file(left.join("000003.png")).expect("rm");
    assert!(Command::new("mkfifo").arg(left.join("000003.png")).status().expect("mkfifo").success());
    let mut c = app();
    c.args(["run", "--detector", "none"]).arg(&seq).arg("--out").arg(d.join("images-out"));
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert_eq!(number_after(&text, "unreadable "), 3.0, "{text}");
    for why in ["000001.png: it is a folder", "000002.png: it is a symbolic link", "000003.png: it is a named pipe"] {
        assert!(err.contains(why), "{why}: {err}");
    }
    std::fs::remove_dir_all(&d).ok();
}

/// Class 4: a keyframe needs new information. Twelve copies of one stereo pair (a car standing still)
/// make one keyframe, not one every four frames; a drive forward, back and forward again over frames
/// 0-10 is tracked in both directions, relocalised only where it turns.
#[test]
fn keyframes_need_new_information_and_reversing_is_tracked() {
    let d = scratch("long");
    let src = fixtures().join("kitti_odom_06/sequences/06");
    let copy = |name: &str, frames: &[usize]| -> PathBuf {
        let dst = d.join(name).join("sequences/06");
        for cam in ["image_0", "image_1"] {
            std::fs::create_dir_all(dst.join(cam)).expect("dir");
            for (i, f) in frames.iter().enumerate() {
                std::fs::copy(src.join(cam).join(format!("{f:06}.png")), dst.join(cam).join(format!("{i:06}.png")))
                    .expect("copy");
            }
        }
        std::fs::copy(src.join("calib.txt"), dst.join("calib.txt")).expect("calib");
        dst
    };
    let run = |seq: &Path, out: &str| {
        let mut c = app();
        c.args(["run", "--detector", "none"]).arg(seq).arg("--out").arg(d.join(out));
        let (code, text, err) = run_cmd(c);
        assert_eq!(code, 0, "{err}");
        text
    };
    let still = copy("still", &[10; 12]);
    let text = run(&still, "still-out");
    assert_eq!(number_after(&text, "keyframes "), 1.0, "{text}");
    assert_eq!(csv_column(&d.join("still-out"), "state").iter().filter(|s| *s == "tracked").count(), 11);
    // 0..=10, 9..=0, 1..=10: two turns
    let frames: Vec<usize> = (0..=10).chain((0..10).rev()).chain(1..=10).collect();
    let back = copy("back", &frames);
    run(&back, "back-out");
    let states = csv_column(&d.join("back-out"), "state");
    let relocalised: Vec<usize> = (0..states.len()).filter(|&k| states[k] == "relocalised").collect();
    assert!(relocalised.len() <= 4, "relocalised at {relocalised:?} of {states:?}");
    assert!(relocalised.iter().all(|&k| (10..=13).contains(&k) || (20..=23).contains(&k)), "{relocalised:?}");
    assert!(states.iter().filter(|s| *s == "tracked").count() >= 25, "{states:?}");
    std::fs::remove_dir_all(&d).ok();
}

/// Class 5, trajectories: a TUM estimate is taken in time order whatever its line order, a time given
/// twice is an error, a trajectory that does not move prints no NaN; a run whose first image cannot be
/// read is scored from where tracking started (the figures of a run from that frame), and unreadable
/// frames are left out, each said.
#[test]
fn trajectory_figures_follow_time_and_what_was_tracked() {
    let d = scratch("figures");
    let times: Vec<f64> = (0..20).map(|i| 0.1 * i as f64).collect();
    let tum = |name: &str, order: &[usize], step: f64| {
        let text: String = order
            .iter()
            .map(|&i| format!("{:.1} {} 0 {} 0 0 0 1\n", times[i], 0.02 * step * i as f64, step * i as f64))
            .collect();
        write(&d.join(name), &text)
    };
    let order: Vec<usize> = (0..20).collect();
    let shuffled: Vec<usize> = (0..20).map(|i| (i * 7) % 20).collect();
    let (est, shuf, gt) = (tum("est.tum", &order, 1.0), tum("shuf.tum", &shuffled, 1.0), tum("gt.tum", &order, 1.02));
    let eval = |e: &Path, g: &Path| {
        let mut c = app();
        c.arg("trajectory-eval").arg(e).arg(g);
        run_cmd(c)
    };
    let (code, sorted, err) = eval(&est, &gt);
    assert_eq!(code, 0, "{err}");
    let (code, text, err) = eval(&shuf, &gt);
    assert_eq!(code, 0, "{err}");
    assert!(text.contains("not in time order"), "{text}");
    let table = |t: &str| t.lines().filter(|l| l.starts_with('|')).collect::<Vec<_>>().join("\n");
    assert_eq!(table(&text), table(&sorted), "the shuffled estimate scores as the sorted one");
    let mut dup = std::fs::read_to_string(&est).expect("read");
    dup.push_str("0.5 9 9 9 0 0 0 1\n");
    let dup = write(&d.join("dup.tum"), &dup);
    let still = tum("still.tum", &order, 0.0);
    let cases = vec![case(
        "TUM time twice",
        &[&"trajectory-eval", &dup, &gt],
        1,
        &["dup.tum:21: time 0.5 s again (first on line 6)"],
    )];
    check(cases);
    for (e, g) in [(&still, &gt), (&gt, &still), (&still, &still)] {
        let (code, text, err) = eval(e, g);
        assert_eq!(code, 0, "{err}");
        assert!(!text.contains("NaN") && text.contains("does not move"), "{text}");
    }
    // an unreadable first image (its left file missing): scored as the run from frame 1 is
    let seq = sequence(&d, "first", 8, None);
    let poses = std::fs::read_to_string(fixtures().join("kitti_odom_06/poses/06.txt")).expect("poses");
    write(&d.join("first/poses/06.txt"), &poses);
    let run = |extra: &[&str], out: &str| {
        let mut c = app();
        c.args(["run", "--detector", "none"]).arg(&seq).args(extra).arg("--out").arg(d.join(out));
        let (code, text, err) = run_cmd(c);
        assert_eq!(code, 0, "{err}");
        text
    };
    let from_one = run(&["--frames", "1.."], "from-one");
    std::fs::remove_file(seq.join("image_0/000000.png")).expect("rm");
    let text = run(&[], "first-unreadable");
    assert!(text.contains("left out: the 1 frame before frame 1, where tracking started"), "{text}");
    assert_eq!(number_after(&text, "; ATE "), number_after(&from_one, "; ATE "), "{text}\n{from_one}");
    // an unreadable frame in the middle: left out, and said
    std::fs::copy(fixtures().join("kitti_odom_06/sequences/06/image_0/000000.png"), seq.join("image_0/000000.png"))
        .expect("restore");
    std::fs::remove_file(seq.join("image_1/000004.png")).expect("rm");
    let text = run(&[], "middle-unreadable");
    assert!(text.contains("scored over the 7 frames") && text.contains("1 unreadable frame (a held pose"), "{text}");
    std::fs::remove_dir_all(&d).ok();
}

/// Class 5, values no sensor, label or run produces: labels, a run folder that is not a run's,
/// detection options of another source, calibrations that are no rectified rig, OXTS packets and
/// frame times no vehicle or camera makes, a stereo-check without evidence, a map point beyond a
/// 32-bit float.
#[test]
fn values_that_cannot_be_right_are_errors() {
    let d = scratch("values");
    let src = fixtures().join("kitti_tracking/0003");
    let labels = std::fs::read_to_string(src.join("label_02.txt")).expect("labels");
    let car = labels.lines().find(|l| l.contains(" Car ")).expect("a car").to_string();
    let f: Vec<&str> = car.split_whitespace().collect();
    let with = |name: &str, line: String| -> PathBuf {
        let dir = d.join(name);
        for file in ["poses_orbslam3.txt", "calib.txt"] {
            std::fs::create_dir_all(&dir).expect("dir");
            std::fs::copy(src.join(file), dir.join(file)).expect("copy");
        }
        write(&dir.join("label_02.txt"), &format!("{labels}{line}\n"));
        dir
    };
    let field = |k: usize, v: &str| {
        let mut g = f.clone();
        g[k] = v;
        g.join(" ")
    };
    let objects =
        |dir: &Path| -> Vec<OsString> { vec!["objects".into(), dir.into(), "--out".into(), d.join("o.json").into()] };
    let mk = |name: &str, args: Vec<OsString>, want: &[&str]| Case {
        name: name.into(),
        args,
        code: 1,
        want: want.iter().map(|s| s.to_string()).collect(),
    };
    let mut cases = vec![
        mk("label track id -2", objects(&with("below", field(1, "-2"))), &["label_02.txt:", "track id -2 for a Car"]),
        mk("label at z = 1e12", objects(&with("far", field(15, "1e12"))), &["location coordinate 1.000e12 m"]),
        mk(
            "label track twice in a frame",
            objects(&with("twice", car.clone())),
            &["again in frame", "labelled once per frame"],
        ),
    ];
    // a run folder (hand-written, two frames) that is not a run's: camera.json with fx 0 or width -5,
    // an object seen in frame 7
    let camera = r#"{"fx":721.5,"fy":721.5,"cx":609.6,"cy":172.9,"width":1242,"height":375,"label_offset":[0,0,0],"colour":false}"#;
    let object = r#"{"version":1,"frame":"world","objects":[{"id":1,"class":2,"center":[0,0,10],"semi_axes":[2,1,1],"rotation":[1,0,0,0,1,0,0,0,1],"frames":[0,1],"dynamic":false}]}"#;
    let run_folder = |name: &str, camera: &str, objects: &str| -> PathBuf {
        let dir = d.join(name);
        write(&dir.join("camera.json"), camera);
        write(&dir.join("objects.json"), objects);
        write(&dir.join("trajectory.kitti.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 1\n");
        write(&dir.join("tracking.csv"), "frame,state\n0,initialised\n1,tracked\n");
        dir
    };
    let label_file = src.join("label_02.txt");
    let eval = |dir: PathBuf| -> Vec<OsString> {
        vec!["eval".into(), dir.into(), "--labels".into(), label_file.clone().into()]
    };
    cases.extend([
        mk(
            "camera.json fx 0",
            eval(run_folder("fx0", &camera.replace("721.5,\"fy\"", "0,\"fy\""), object)),
            &["camera.json", "fx 0"],
        ),
        mk(
            "camera.json width -5",
            eval(run_folder("w-5", &camera.replace("1242", "-5"), object)),
            &["camera.json", "width -5"],
        ),
        mk(
            "an object in a frame the run did not play",
            eval(run_folder("frame7", camera, &object.replace("[0,1]", "[0,7]"))),
            &["object 1 is seen in frame 7, which the run did not play"],
        ),
    ]);
    // options of the network detector with a detection file
    let dets = fixtures().join("kitti_odom_06/detections/yolo_fastest_tiles3.json");
    for (flag, value) in [("--score", "0.5"), ("--mode", "squash"), ("--tiles", "2"), ("--input-size", "416")] {
        cases.push(case(
            &format!("--detections with {flag}"),
            &[&"run", &"--detections", &dets, &flag, &value, &"--max-frames", &"2", &"--out", &d.join("o")],
            1,
            &["--detections (detector file)", &format!("{flag} (detector dnn)"), "conflict"],
        ));
    }
    // calibrations that are no rectified rig (odometry 06's P0 and P1 with one number changed)
    let rig = [
        ("skew", "P0", 1, "1e308", "skew"),
        ("third row", "P0", 10, "2", "third row"),
        ("P1 fx halved", "P1", 0, "353.5456", "shares its intrinsics"),
        ("P1 cy moved", "P1", 6, "283.1104", "cy 183.1104 and P1 283.1104"),
        ("P1 ty", "P1", 7, "50", "differ along x only"),
        ("P1 tz", "P1", 11, "0.2", "along the optical axis"),
        ("negative focal", "P0", 0, "-707.0912", "a camera's focal lengths are positive"),
    ];
    for (name, key, k, value, want) in rig {
        let seq = sequence(&d, &format!("rig-{k}-{key}"), 2, Some(&calib_with(key, k, value)));
        cases.push(case(
            &format!("calibration: {name}"),
            &[&"run", &seq, &"--out", &d.join("o")],
            1,
            &["calib.txt", want],
        ));
    }
    let text = std::fs::read_to_string(fixtures().join("kitti_odom_06/sequences/06/calib.txt")).expect("calib");
    let swapped: String = text
        .lines()
        .map(|l| l.replacen("P0:", "Px:", 1).replacen("P1:", "P0:", 1).replacen("Px:", "P1:", 1) + "\n")
        .collect();
    let seq = sequence(&d, "swapped", 2, Some(&swapped));
    cases.push(case(
        "calibration: P0 and P1 swapped",
        &[&"run", &seq, &"--out", &d.join("o")],
        1,
        &["-0.5372 m", "swapped"],
    ));
    // frame times no camera records (times.txt 0.1 ms and 1e-300 s apart)
    for (name, times) in [("0.1 ms", "0\n0.0001\n0.2\n"), ("1e-300 s", "0\n1e-300\n2e-300\n")] {
        let seq = sequence(&d, &format!("times-{}", name.len()), 3, None);
        write(&seq.join("times.txt"), times);
        cases.push(case(
            &format!("frame times {name} apart"),
            &[&"run", &seq, &"--out", &d.join("o")],
            1,
            &["times.txt:2", "at least 0.001 s apart"],
        ));
    }
    // a raw drive whose third packet jumps 1.1 km, and one whose packet turns 90° in a frame
    let raw = fixtures().join("kitti_raw_0005/2011_09_26");
    for (name, k, change) in [("jump", 0usize, 0.01), ("turn", 5, std::f64::consts::FRAC_PI_2)] {
        let date = d.join(format!("raw-{name}/2011_09_26"));
        let drive = date.join("2011_09_26_drive_0005_sync");
        for f in ["calib_cam_to_cam.txt", "calib_imu_to_velo.txt", "calib_velo_to_cam.txt"] {
            write(&date.join(f), &std::fs::read_to_string(raw.join(f)).expect("calib"));
        }
        for i in 0..4 {
            for cam in ["image_00", "image_01"] {
                let f = format!("{cam}/data/{i:010}.png");
                std::fs::create_dir_all(drive.join(cam).join("data")).expect("dir");
                std::fs::copy(raw.join("2011_09_26_drive_0005_sync").join(&f), drive.join(&f)).expect("copy");
            }
            let p = format!("oxts/data/{i:010}.txt");
            let packet = std::fs::read_to_string(raw.join("2011_09_26_drive_0005_sync").join(&p)).expect("packet");
            let mut v: Vec<String> = packet.split_whitespace().map(str::to_string).collect();
            if i == 2 {
                v[k] = (v[k].parse::<f64>().expect("number") + change).to_string();
            }
            write(&drive.join(&p), &(v.join(" ") + "\n"));
        }
        let ts = std::fs::read_to_string(raw.join("2011_09_26_drive_0005_sync/image_00/timestamps.txt")).expect("ts");
        write(&drive.join("image_00/timestamps.txt"), &ts);
        let want = if name == "jump" { "the IMU moved 111" } else { "the IMU turned" };
        cases.push(case(
            &format!("OXTS {name}"),
            &[&"run", &drive, &"--out", &d.join("o")],
            1,
            &["0000000002.txt", want],
        ));
    }
    // stereo-check with too few frame pairs, and a map point beyond a 32-bit float (and the Earth)
    cases.push(case(
        "stereo-check on 3 frames",
        &[&"stereo-check", &"--max-frames", &"3"],
        1,
        &["frame pairs", "at least 10"],
    ));
    let far = MAP_OK.replace(r#""points":{}"#, r#""points":{"1":{"position":[0,1e300,0],"observed_by":[0]}}"#);
    let far = write(&d.join("far.json"), &far);
    cases.push(case(
        "map point at 1e300",
        &[&"map", &far, &"--ply", &d.join("p.ply")],
        1,
        &["points.1.position", "Earth's diameter"],
    ));
    let n = check(cases);
    assert_eq!(n, 24);
    assert!(!d.join("o").exists() && !d.join("p.ply").exists() && !d.join("o.json").exists(), "nothing written");
    std::fs::remove_dir_all(&d).ok();
}

/// Classes 6 and 7: errors that say what is wrong (a byte-order mark is no error; a detection file
/// that is an array says so), a run folder scored by `eval` stays the run's to replace, and a full disk
/// (a file-size limit of 0: every byte written fails) leaves no temporary file or folder behind.
#[test]
fn clear_errors_and_nothing_left_on_a_full_disk() {
    let d = scratch("clear");
    // a UTF-8 byte-order mark in a calibration and in a detection file
    let bom = format!(
        "\u{feff}{}",
        std::fs::read_to_string(fixtures().join("kitti_odom_06/sequences/06/calib.txt")).expect("calib")
    );
    let seq = sequence(&d, "bom", 3, Some(&bom));
    let dets = write(&d.join("bom.json"), "\u{feff}{\"version\":1,\"frames\":[]}");
    let mut c = app();
    c.args(["run", "--detections"]).arg(&dets).arg(&seq).arg("--out").arg(d.join("bom-out"));
    let (code, _, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    let array = write(&d.join("array.json"), "[{\"frame\":0,\"detections\":[]}]");
    check(vec![case(
        "detections: a top-level array",
        &[&"run", &"--detections", &array, &seq, &"--out", &d.join("o")],
        1,
        &["array.json:1: the file is an array: a detection file is one object"],
    )]);
    // eval writes objects_score.json into a run's folder; the next run may still replace the folder
    let out = d.join("scored");
    let run = |extra: &[&str]| {
        let mut c = app();
        c.args(["run", "--detector", "none"]).args(extra).arg(&seq).arg("--out").arg(&out);
        run_cmd(c)
    };
    assert_eq!(run(&[]).0, 0);
    let mut c = app();
    c.arg("eval").arg(&out).arg("--labels").arg(fixtures().join("kitti_tracking/0003/label_02.txt"));
    let (code, _, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert!(out.join("objects_score.json").is_file());
    let (code, _, err) = run(&["--max-frames", "2"]);
    assert_eq!(code, 0, "run --out replaces the scored folder: {err}");
    // a full disk: each command fails, naming what it could not write, and leaves only what was there
    let full = d.join("full");
    std::fs::create_dir_all(&full).expect("dir");
    let map = write(&full.join("map.json"), MAP_OK);
    let tracking = fixtures().join("kitti_tracking/0003");
    let attempts: Vec<(&str, Vec<OsString>)> = vec![
        (
            "run --out",
            vec![
                "run".into(),
                "--detector".into(),
                "none".into(),
                seq.clone().into(),
                "--out".into(),
                full.join("run").into(),
            ],
        ),
        ("map --ply", vec!["map".into(), map.clone().into(), "--ply".into(), full.join("points.ply").into()]),
        ("map --scene", vec!["map".into(), map.clone().into(), "--scene".into(), full.join("scene.ply").into()]),
        ("objects --out", vec!["objects".into(), tracking.into(), "--out".into(), full.join("x.obj.json").into()]),
        (
            "sim --out",
            vec![
                "sim".into(),
                "--objects".into(),
                "1".into(),
                "--noise-seeds".into(),
                "1".into(),
                "--out".into(),
                full.join("sim").into(),
            ],
        ),
    ];
    for (name, args) in attempts {
        let mut c = app_under("ulimit -f 0");
        c.args(&args);
        let (code, _, err) = run_cmd(c);
        assert_eq!(code, 1, "{name}: {err}");
        assert!(err.contains("cannot write") || err.contains("File too large"), "{name}: {err}");
        assert_eq!(names_in(&full), ["map.json"], "{name} left files behind");
    }
    std::fs::remove_dir_all(&d).ok();
}

// ---- Issue 39: bad input, round three ----

/// A grey image scaled by `num / den` in each direction (nearest pixel), for images that do not have
/// their calibration's size.
fn scaled(img: &slam_core::Image, num: u32, den: u32) -> slam_core::Image {
    let (w, h) = (img.width * num / den, img.height * num / den);
    let data = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| img.data[((y * den / num) * img.width + x * den / num) as usize])
        .collect();
    slam_core::Image::new(w, h, 1, data).expect("image")
}

/// Rewrite both images of frames `frames` of `seq` through `edit`.
fn edit_frames(seq: &Path, frames: std::ops::Range<usize>, edit: &dyn Fn(&slam_core::Image) -> slam_core::Image) {
    for i in frames {
        for cam in ["image_0", "image_1"] {
            let f = seq.join(format!("{cam}/{i:06}.png"));
            let img = slam_frontend::read_image(&f, false).expect("read");
            slam_frontend::write_image(&f, &edit(&img)).expect("write");
        }
    }
}

/// A PNG file's bytes: signature, an `IHDR` declaring `w × h` of `depth` bits and colour `kind` (0 grey,
/// 2 RGB), then `body` (further chunks, or nothing: a file that only declares its size).
fn png_with(w: u32, h: u32, depth: u8, kind: u8, body: &[u8]) -> Vec<u8> {
    let mut v = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([depth, kind, 0, 0, 0]);
    v.extend(png_chunk(b"IHDR", &ihdr));
    v.extend_from_slice(body);
    v
}

/// One PNG chunk: length, type, data, CRC-32 of type and data.
fn png_chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in kind.iter().chain(data) {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    let mut v = (data.len() as u32).to_be_bytes().to_vec();
    v.extend_from_slice(kind);
    v.extend_from_slice(data);
    v.extend((!crc).to_be_bytes());
    v
}

/// A 16-bit grey PNG of `w × h` samples (zlib's stored blocks: no compression needed for a test).
fn png16(w: u32, h: u32, samples: &[u16]) -> Vec<u8> {
    let mut raw = Vec::new();
    for row in samples.chunks(w as usize) {
        raw.push(0u8);
        for s in row {
            raw.extend(s.to_be_bytes());
        }
    }
    let mut z = vec![0x78, 0x01];
    let blocks: Vec<&[u8]> = raw.chunks(65_535).collect();
    for (k, b) in blocks.iter().enumerate() {
        z.push(u8::from(k + 1 == blocks.len()));
        z.extend((b.len() as u16).to_le_bytes());
        z.extend((!(b.len() as u16)).to_le_bytes());
        z.extend_from_slice(b);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &x in &raw {
        a = (a + u32::from(x)) % 65_521;
        b = (b + a) % 65_521;
    }
    z.extend(((b << 16) | a).to_be_bytes());
    let body = [png_chunk(b"IDAT", &z), png_chunk(b"IEND", &[])].concat();
    png_with(w, h, 16, 0, &body)
}

/// Class 1 (R01, R06, R14 9): images must fit their calibration, and no image is decoded before its
/// header's size is checked. Images half or twice the calibrated size are refused before any frame by
/// every command that tracks them (the principal point's place names both); a first frame cropped to
/// another size no longer makes the others unreadable; a PNG or JPEG declaring 30000 × 30000 pixels is
/// refused from its header (unreadable frame, skipped image), or as the first frame, an error.
#[test]
fn images_must_fit_their_calibration_and_their_header_bounds_decoding() {
    let d = scratch("fit");
    let half = sequence(&d, "half", 3, None);
    edit_frames(&half, 0..3, &|img| scaled(img, 1, 2));
    let double = sequence(&d, "double", 3, None);
    edit_frames(&double, 0..3, &|img| scaled(img, 2, 1));
    // a 33-byte PNG and a 23-byte JPEG that declare 30000 × 30000 pixels
    let bomb = png_with(30_000, 30_000, 8, 2, &[]);
    let jpeg_bomb = [
        &[0xFF, 0xD8, 0xFF, 0xC0, 0x00, 0x11, 0x08][..],
        &30_000u16.to_be_bytes(),
        &30_000u16.to_be_bytes(),
        &[3, 1, 0x22, 0, 2, 0x11, 1, 3, 0x11, 1],
    ]
    .concat();
    let first_bomb = sequence(&d, "firstbomb", 3, None);
    for cam in ["image_0", "image_1"] {
        std::fs::write(first_bomb.join(format!("{cam}/000000.png")), &bomb).expect("bomb");
    }
    let out = d.join("o");
    let half_msg = [
        "calib.txt: the principal point (601.9, 183.1) px lies 48 % of the width",
        "613×185",
        "implies about 1204×366",
    ];
    let mut cases = vec![
        case(
            "run, images half the calibrated size",
            &[&"run", &"--detector", &"none", &half, &"--out", &out],
            1,
            &half_msg,
        ),
        case(
            "run, images twice the calibrated size",
            &[&"run", &"--detector", &"none", &double, &"--out", &out],
            1,
            &["lies 25 % of the width", "2452×740"],
        ),
        case("stereo-check, half size", &[&"stereo-check", &half], 1, &half_msg),
        case("track-bench, half size", &[&"track-bench", &"--only-cases", &"--case", &half], 1, &half_msg),
        case(
            "run, a 30000 × 30000 first frame",
            &[&"run", &"--detector", &"none", &first_bomb, &"--out", &out],
            1,
            &["000000.png", "declares 30000×30000 pixels", "not decoded"],
        ),
    ];
    // depth-check on a raw drive whose images are half the size
    let raw = fixtures().join("kitti_raw_0005/2011_09_26");
    let date = d.join("raw/2011_09_26");
    let drive = date.join("2011_09_26_drive_0005_sync");
    for f in ["calib_cam_to_cam.txt", "calib_imu_to_velo.txt", "calib_velo_to_cam.txt"] {
        std::fs::copy(raw.join(f), date.join(f)).ok().or_else(|| {
            std::fs::create_dir_all(&date).expect("dir");
            std::fs::copy(raw.join(f), date.join(f)).ok()
        });
    }
    for cam in ["image_00", "image_01"] {
        std::fs::create_dir_all(drive.join(cam).join("data")).expect("dir");
        for i in 0..2 {
            let f = format!("{cam}/data/{i:010}.png");
            let img = slam_frontend::read_image(raw.join("2011_09_26_drive_0005_sync").join(&f), false).expect("read");
            slam_frontend::write_image(drive.join(&f), &scaled(&img, 1, 2)).expect("write");
        }
    }
    cases.push(case(
        "depth-check, half size",
        &[&"depth-check", &drive],
        1,
        &["calib_cam_to_cam.txt: the principal point", "621×187"],
    ));
    check(cases);
    assert!(!out.exists(), "no output folder from refused runs");
    // counted: a bomb in the middle of a run, and among the images of detect
    let seq = sequence(&d, "bomb", 4, None);
    for cam in ["image_0", "image_1"] {
        std::fs::write(seq.join(format!("{cam}/000002.png")), &bomb).expect("bomb");
    }
    let mut c = app();
    c.args(["run", "--detector", "none"]).arg(&seq).arg("--out").arg(d.join("bomb-out"));
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert_eq!(number_after(&text, "unreadable ") as usize, 1, "{text}");
    assert!(err.contains("000002.png") && err.contains("declares 30000×30000 pixels"), "{err}");
    let imgs = d.join("imgs");
    std::fs::create_dir_all(&imgs).expect("dir");
    std::fs::copy(seq.join("image_0/000000.png"), imgs.join("000000.png")).expect("copy");
    std::fs::write(imgs.join("000001.png"), &bomb).expect("bomb");
    std::fs::write(imgs.join("000002.jpg"), &jpeg_bomb).expect("bomb");
    let mut c = app();
    c.arg("detect").arg(&imgs).arg("--out").arg(d.join("det.json"));
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert!(text.contains("3 frames") && text.contains("2 unreadable frames skipped"), "{text}");
    assert!(err.contains("000002.jpg") && err.contains("its JPEG header declares 30000×30000"), "{err}");
    // the first frame cropped to 1000 px (both cameras): that frame is the odd one, the others track
    let crop = sequence(&d, "crop", 6, None);
    edit_frames(&crop, 0..1, &|img| {
        let data = img.data.chunks(img.width as usize).flat_map(|r| r[..1000].to_vec()).collect();
        slam_core::Image::new(1000, img.height, 1, data).expect("image")
    });
    std::fs::create_dir_all(d.join("crop/poses")).expect("dir");
    let poses = std::fs::read_to_string(fixtures().join("kitti_odom_06/poses/06.txt")).expect("poses");
    write(&d.join("crop/poses/06.txt"), &poses.lines().take(6).map(|l| format!("{l}\n")).collect::<String>());
    let mut c = app();
    c.args(["run", "--detector", "none"]).arg(&crop).arg("--out").arg(d.join("crop-out"));
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert!(text.contains("1 frame(s) of another image size than the others' 1226×370 (first: frame 0)"), "{text}");
    assert_eq!(number_after(&text, "unreadable ") as usize, 1, "{text}");
    assert_eq!(number_after(&text, "tracking states: tracked ") as usize, 4, "{text}");
    assert!(text.contains("ground truth: path"), "scored from the first tracked frame: {text}");
    assert!(err.contains("000000.png is 1000×370, most of the sequence's frames 1226×370"), "{err}");
    std::fs::remove_dir_all(&d).ok();
}

/// Class 3 (R02, R14 2): a detector model is checked against its description before any frame. Darknet
/// weights cut short, empty, padded, or for another cfg, and a cfg of other classes, are refused naming
/// both files and the byte counts (they gave 1600 junk boxes a frame, or none); an ONNX model whose
/// output is not what its decode reads is refused naming both shapes; an input size is echoed as
/// written, and one that needs more memory than the process can have is refused with the figure.
#[test]
fn models_are_checked_against_their_description() {
    let d = scratch("models");
    let shipped = fixtures().join("detector");
    let weights = std::fs::read(shipped.join("yolo-fastest-1.1.weights")).expect("weights");
    let cfg = std::fs::read_to_string(shipped.join("yolo-fastest-1.1.cfg")).expect("cfg");
    let half = d.join("half.weights");
    std::fs::write(&half, &weights[..700_000]).expect("write");
    let empty = write(&d.join("empty.weights"), "");
    let padded = d.join("padded.weights");
    std::fs::write(&padded, [&weights[..], &[0u8; 4096][..]].concat()).expect("write");
    // another model's cfg (a wider first layer), and one of 3 classes
    let wider = write(&d.join("wider.cfg"), &cfg.replacen("filters=8", "filters=16", 1));
    let three = write(&d.join("three.cfg"), &cfg.replace("classes=80", "classes=3"));
    let imgs = d.join("imgs");
    std::fs::create_dir_all(&imgs).expect("dir");
    std::fs::copy(fixtures().join("kitti_odom_06/sequences/06/image_0/000000.png"), imgs.join("000000.png"))
        .expect("copy");
    let json = d.join("d.json");
    let detect = |extra: &[&dyn AsRef<std::ffi::OsStr>]| {
        let mut v: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![&"detect", &imgs, &"--out", &json];
        v.extend_from_slice(extra);
        v.iter().map(|a| a.as_ref().to_os_string()).collect::<Vec<_>>()
    };
    let mk = |name: &str, args: Vec<OsString>, want: &[&str]| Case {
        name: name.into(),
        args,
        code: 1,
        want: want.iter().map(|s| s.to_string()).collect(),
    };
    let onnx = fixtures().join("yolox_nano/yolox_nano.onnx");
    let cases = vec![
        mk(
            "weights cut short",
            detect(&[&"--weights", &half]),
            &["half.weights: holds 700000 bytes", "needs 1384268", "684268 bytes too few"],
        ),
        mk(
            "empty weights",
            detect(&[&"--weights", &empty]),
            &["empty.weights: holds 0 bytes, too few for a Darknet weights header"],
        ),
        mk("weights padded", detect(&[&"--weights", &padded]), &["padded.weights", "4096 bytes too many"]),
        mk(
            "weights of another cfg",
            detect(&[&"--cfg", &wider]),
            &["yolo-fastest-1.1.weights: holds 1384268 bytes, but", "wider.cfg needs"],
        ),
        mk("cfg of 3 classes", detect(&[&"--cfg", &three]), &["three.cfg", "classes=3", "COCO's 80 classes"]),
        mk(
            "onnx read as rows",
            detect(&[&"--onnx", &onnx, &"--family", &"rows"]),
            &["yolox_nano.onnx", "its output is 1×2100×85", "2-D outputs of 85 columns"],
        ),
        mk("input size 0x0 as written", detect(&[&"--input-size", &"0x0"]), &["--input-size 0x0: must be"]),
        case(
            "run with weights cut short",
            &[&"run", &"--weights", &half, &"--out", &d.join("o")],
            1,
            &["half.weights", "684268 bytes too few"],
        ),
    ];
    check(cases);
    assert!(!json.exists() && !d.join("o").exists(), "nothing written");
    // the shipped pair loads; at an input of 2048 × 2048 OpenCV's network (the Darknet model) needs more
    // than 0.9 GB of address space leaves (about 0.8 GB: a quarter of OpenCV's estimate of 3.2 GB)
    let mut c = app();
    c.arg("detect").arg(&imgs).arg("--out").arg(&json).arg("--model").arg("yolo-fastest");
    let (code, _, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    let mut c = app_under("ulimit -v 900000");
    c.arg("detect").arg(&imgs).arg("--out").arg(d.join("big.json")).args(["--input-size", "2048"]);
    c.args(["--model", "yolo-fastest"]);
    let (code, _, err) = run_cmd(c);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("the network at an input of 2048x2048 needs about")
            && err.contains("choose a smaller --input-size"),
        "{err}"
    );
    std::fs::remove_dir_all(&d).ok();
}

/// Class 4 (R04, R05, R14 5): a figure of an empty set is a dash (an empty CSV field), never 0.000 or
/// NaN, in every table; and the labels' line order does not change `eval`'s figures.
#[test]
fn figures_of_empty_sets_are_dashes_and_line_order_does_not_matter() {
    let d = scratch("dashes");
    let csv = d.join("e.csv");
    let mut c = app();
    c.arg("eval").arg(fixtures().join("kitti_tracking/0000")).args(["--min-frames", "100000", "--csv"]).arg(&csv);
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    let row = text.lines().find(|l| l.starts_with("0000")).expect("row").to_string();
    assert_eq!(row.split_whitespace().filter(|c| *c == "–").count(), 8, "{row}");
    for tag in ["0000", "avg", "all"] {
        let line = text.lines().find(|l| l.starts_with(tag)).expect("line");
        assert!(!line.contains("NaN") && !line.contains("0.000"), "{line}");
    }
    let fields = std::fs::read_to_string(&csv).expect("csv");
    assert_eq!(fields.lines().nth(1), Some("0000,0,0,,,,,,,,"), "{fields}");
    // the same labels reversed line by line: the same figures, and the log says the file was sorted
    let seq = |name: &str, reverse: bool| {
        let dir = d.join(name);
        for f in ["calib.txt", "poses_orbslam3.txt", "label_02.txt"] {
            let text = std::fs::read_to_string(fixtures().join("kitti_tracking/0000").join(f)).expect("fixture");
            let text = if reverse && f == "label_02.txt" {
                text.lines().rev().map(|l| format!("{l}\n")).collect()
            } else {
                text
            };
            write(&dir.join(f), &text);
        }
        dir
    };
    let eval = |dir: &Path| {
        let mut c = app();
        c.arg("eval").arg(dir);
        let (code, text, err) = run_cmd(c);
        assert_eq!(code, 0, "{err}");
        (
            text.lines()
                .filter(|l| l.starts_with("0000") || l.starts_with("what the ground-truth"))
                .collect::<Vec<_>>()
                .join("\n"),
            err,
        )
    };
    let (forward, _) = eval(&seq("forward", false));
    let (backward, err) = eval(&seq("backward", true));
    assert_eq!(forward, backward);
    assert!(err.contains("labels are not in frame order") && err.contains("read in frame order"), "{err}");
    // track-bench with a stride past the sequence (one frame), detect-recall with an input where
    // nothing is found, run-bench over one frame: dashes where a figure has nothing to stand on
    let shipped = fixtures().join("kitti_odom_06/sequences/06");
    let mut c = app();
    c.args(["track-bench", "--only-cases", "--case"]).arg(format!("{}:99999", shipped.display()));
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    let row = text.lines().find(|l| l.contains("stride 99999")).expect("row");
    assert!(row.ends_with("| – | – |") && !row.contains("NaN"), "{row}");
    let mut c = app();
    c.args(["detect-recall", "--input-size", "32"]);
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    let row = text.lines().find(|l| l.contains("32x32")).expect("row");
    assert!(row.contains("| 0/27 | 0.000 | – |") && !row.contains("NaN"), "{row}");
    let mut c = app();
    c.args(["run-bench", "--repeat", "1", "--max-frames", "1"]);
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    let rows: Vec<&str> =
        text.lines().filter(|l| l.starts_with("| no objects") || l.starts_with("| detections")).collect();
    assert_eq!(rows.len(), 2, "{text}");
    assert!(
        rows.iter().all(|r| r.starts_with("| no objects (--detector none) | – |")
            || r.starts_with("| detections from a file | – |")),
        "{rows:?}"
    );
    assert!(!text.contains("NaN"), "{text}");
    std::fs::remove_dir_all(&d).ok();
}

/// Class 5 (R08, R09, R11, R14 7, item 5): every command's outputs follow `run`'s rules. `map --picture`
/// does not replace a user's map.png / map.svg (it may replace its own, and a run's); an output file
/// inside an output folder is refused as such, before any folder is made; every path is checked before
/// any work: all of track-bench's cases, map's exports before the map is read, optim-bench's problem
/// files before the first solve; a symbolic link that loops is named as one.
#[test]
fn outputs_follow_runs_rules_and_paths_are_checked_first() {
    let d = scratch("outputs");
    let run_dir = d.join("run");
    let mut c = app();
    c.args(["run", "--detector", "none", "--max-frames", "3", "--out"]).arg(&run_dir);
    let (code, _, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    let map = run_dir.join("map.json");
    let mine = d.join("mine");
    write(&mine.join("map.png"), "my own picture");
    write(&mine.join("map.svg"), "my own svg");
    let loop_a = d.join("loopA");
    std::os::unix::fs::symlink(d.join("loopB"), &loop_a).expect("link");
    std::os::unix::fs::symlink(&loop_a, d.join("loopB")).expect("link");
    let bad_map = write(&d.join("bad.json"), "{");
    let optim = d.join("optim");
    std::fs::create_dir_all(&optim).expect("dir");
    std::fs::copy(fixtures().join("optim/problem-49-7776-pre.txt"), optim.join("problem-49-7776-pre.txt"))
        .expect("copy");
    let imgs = d.join("imgs");
    std::fs::create_dir_all(&imgs).expect("dir");
    std::fs::copy(fixtures().join("kitti_odom_06/sequences/06/image_0/000000.png"), imgs.join("000000.png"))
        .expect("copy");
    let cases = vec![
        case(
            "map --picture over a user's pictures",
            &[&"map", &map, &"--picture", &mine],
            1,
            &["--picture", "holds map.svg, map.png that `slam-app map` did not write"],
        ),
        case(
            "detect --out inside --overlays",
            &[&"detect", &imgs, &"--out", &d.join("ov1/x.json"), &"--overlays", &d.join("ov1")],
            1,
            &["--out", "ov1/x.json: lies inside --overlays", "replaces as a whole"],
        ),
        case(
            "detect --out below --overlays",
            &[&"detect", &imgs, &"--out", &d.join("ov2/sub/x.json"), &"--overlays", &d.join("ov2")],
            1,
            &["ov2/sub/x.json: lies inside --overlays"],
        ),
        case(
            "track-bench, a missing last case",
            &[
                &"track-bench",
                &"--only-cases",
                &"--case",
                &fixtures().join("kitti_odom_06/sequences/06"),
                &"--case",
                &d.join("typo"),
            ],
            1,
            &["case", "typo", "not a folder"],
        ),
        case(
            "map exports checked before the map is read",
            &[&"map", &bad_map, &"--ply", &d.join("loopA/p.ply")],
            1,
            &["loopA is a symbolic link", "loops or leads nowhere"],
        ),
        case(
            "run --out below a link that loops",
            &[&"run", &"--max-frames", &"2", &"--out", &d.join("loopA/sub")],
            1,
            &["loopA is a symbolic link to", "loops or leads nowhere"],
        ),
        case(
            "optim-bench, a problem file missing",
            &[&"optim-bench", &"--data", &optim],
            1,
            &["--data", "problem-16-22106-pre.txt"],
        ),
    ];
    check(cases);
    assert_eq!(std::fs::read_to_string(mine.join("map.svg")).expect("svg"), "my own svg", "the user's file is kept");
    assert!(!d.join("ov1").exists() && !d.join("ov2").exists(), "no folder made by a refused command");
    // track-bench printed nothing before the error (no case ran)
    let mut c = app();
    c.args(["track-bench", "--only-cases", "--case"])
        .arg(fixtures().join("kitti_odom_06/sequences/06"))
        .arg("--case")
        .arg(d.join("typo"));
    let (code, text, _) = run_cmd(c);
    assert!(code == 1 && text.is_empty(), "{text}");
    // a run's own pictures, and map's own in a new folder, are replaced again
    for dir in [&run_dir, &d.join("pictures"), &d.join("pictures")] {
        let mut c = app();
        c.arg("map").arg(&map).arg("--picture").arg(dir);
        let (code, text, err) = run_cmd(c);
        assert_eq!(code, 0, "{err}");
        assert!(text.contains("map.svg") && text.contains("map.png"), "{text}");
    }
    let marker = std::fs::read_to_string(d.join("pictures/.slam-app-output")).expect("marker");
    assert_eq!(marker, "slam-app map\nmap.png\nmap.svg\n");
    std::fs::remove_dir_all(&d).ok();
}

/// Class 6 (R12): unusable stereo gets a diagnosis. Cameras swapped, or 12-bit data in 16-bit PNG files:
/// no frame is tracked, the run says what its images show, writes its output and exits with status 1.
#[test]
fn unusable_stereo_gets_a_diagnosis() {
    let d = scratch("diagnosis");
    let swapped = sequence(&d, "swapped", 6, None);
    for i in 0..6 {
        let (l, r) = (swapped.join(format!("image_0/{i:06}.png")), swapped.join(format!("image_1/{i:06}.png")));
        let tmp = swapped.join("swap.png");
        std::fs::rename(&l, &tmp).expect("swap");
        std::fs::rename(&r, &l).expect("swap");
        std::fs::rename(&tmp, &r).expect("swap");
    }
    // 10-bit data in 16-bit files: read as 8 bits, a grey value of at most 3 (12-bit data, at most 15,
    // still holds enough contrast for the low-threshold FAST pass to track some frames)
    let deep = sequence(&d, "bit10", 6, None);
    for i in 0..6 {
        for cam in ["image_0", "image_1"] {
            let f = deep.join(format!("{cam}/{i:06}.png"));
            let img = slam_frontend::read_image(&f, false).expect("read");
            let samples: Vec<u16> = img.data.iter().map(|&v| u16::from(v) * 4).collect();
            std::fs::write(&f, png16(img.width, img.height, &samples)).expect("write");
        }
    }
    for (seq, want) in [
        (&swapped, "the cameras look swapped"),
        (&deep, "the images are nearly black: 99 % of the left image's pixels are at most 3 of 255; the files hold 16-bit samples"),
    ] {
        let out = d.join(format!("out-{}", seq.parent().and_then(Path::parent).expect("root").file_name().expect("name").to_string_lossy()));
        let mut c = app();
        c.args(["run", "--detector", "none"]).arg(seq).arg("--out").arg(&out);
        let (code, text, err) = run_cmd(c);
        assert_eq!(code, 1, "{text}\n{err}");
        let states = text.lines().find(|l| l.starts_with("tracking states:")).expect("states");
        assert!(states.contains("tracked 0,") && states.contains("most frames were not tracked (0 of the 5 after the first)") && states.contains(want), "{states}");
        assert!(err.contains("no frame after the first") && err.contains("was tracked"), "{err}");
        assert!(out.join("tracking.csv").is_file(), "the output is written for inspection");
    }
    // the shipped frames track, and say nothing of the kind
    let mut c = app();
    c.args(["run", "--detector", "none", "--max-frames", "6", "--out"]).arg(d.join("good"));
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert!(!text.contains("most frames were not tracked"), "{text}");
    std::fs::remove_dir_all(&d).ok();
}

/// Class 7 (R07, R13, R14 1/3/4/6/8, R15): values that cannot be right, caught with the figure or range.
#[test]
fn values_that_cannot_be_right_round_four() {
    let d = scratch("values4");
    // a lidar a kilometre from the camera
    let raw = fixtures().join("kitti_raw_0005/2011_09_26");
    let date = d.join("velo/2011_09_26");
    std::fs::create_dir_all(&date).expect("dir");
    for f in ["calib_cam_to_cam.txt", "calib_imu_to_velo.txt"] {
        std::fs::copy(raw.join(f), date.join(f)).expect("copy");
    }
    let v2c = std::fs::read_to_string(raw.join("calib_velo_to_cam.txt")).expect("calib");
    let far: String =
        v2c.lines().map(|l| if l.starts_with("T:") { "T: 1000 0 0\n".into() } else { format!("{l}\n") }).collect();
    write(&date.join("calib_velo_to_cam.txt"), &far);
    std::os::unix::fs::symlink(raw.join("2011_09_26_drive_0005_sync"), date.join("2011_09_26_drive_0005_sync"))
        .expect("link");
    let huge = write(&d.join("huge.toml"), "[tracking]\nransac_px = 1e308\n");
    // a ground truth of 40 lines beside a times.txt of 20
    let gt = d.join("t/poses/06.txt");
    let poses = std::fs::read_to_string(fixtures().join("kitti_odom_06/poses/06.txt")).expect("poses");
    write(&gt, &poses.lines().take(40).map(|l| format!("{l}\n")).collect::<String>());
    write(&d.join("t/sequences/06/times.txt"), &(0..20).map(|i| format!("{:e}\n", 0.1 * i as f64)).collect::<String>());
    // a run's TUM trajectory (times 0.1 s apart) is matched to the KITTI ground truth by its times.txt
    let est = write(
        &d.join("est.tum.txt"),
        &(0..20).map(|i| format!("{:.6} {i} 0 0 0 0 0 1\n", 0.1 * i as f64)).collect::<String>(),
    );
    // labels: occlusion 9, alpha 100
    // (line 5 of sequence 0003's labels is its first object: the lines before are DontCare regions)
    let occluded = tracking_with(&d, "occluded", "label_02.txt", &|t| with_field(t, 4, 4, "9"));
    let alpha = tracking_with(&d, "alpha", "label_02.txt", &|t| with_field(t, 4, 5, "100"));
    // a detection whose class name is another class's
    let banana = write(
        &d.join("banana.json"),
        r#"{"version":1,"frames":[{"frame":0,"detections":[{"class":2,"class_name":"banana","score":0.9,"box":[10,10,50,50]}]}]}"#,
    );
    let cases = vec![
        case(
            "depth-check: lidar 1 km from the camera",
            &[&"depth-check", &date.join("2011_09_26_drive_0005_sync")],
            1,
            &["calib_velo_to_cam.txt:", "T puts the two sensors 1000.000 m apart", "at most 26 m"],
        ),
        case(
            "ransac_px = 1e308",
            &[&"run", &"--config", &huge, &"--print-config"],
            1,
            &["huge.toml", "[tracking] ransac_px = 1e308: beyond the range"],
        ),
        case(
            "stereo-check --step 0",
            &[&"stereo-check", &"--step", &"0"],
            1,
            &["--step 0: must be a finite number in (0.00006, 0.6] px"],
        ),
        case(
            "run-bench --repeat 0",
            &[&"run-bench", &"--repeat", &"0"],
            1,
            &["--repeat 0: must be an integer in [1, 100]"],
        ),
        case("run-bench --repeat 1000000", &[&"run-bench", &"--repeat", &"1000000"], 1, &["--repeat 1000000"]),
        case(
            "trajectory-eval: ground truth longer than times.txt",
            &[&"trajectory-eval", &est, &gt],
            1,
            &["times.txt: 20 times but the lines of the ground truth", "06.txt go up to frame 39"],
        ),
        case(
            "label occlusion 9",
            &[&"objects", &occluded, &"--out", &d.join("o.json")],
            1,
            &["label_02.txt:5: occluded 9"],
        ),
        case(
            "label alpha 100",
            &[&"objects", &alpha, &"--out", &d.join("o.json")],
            1,
            &["label_02.txt:5: alpha 100 rad"],
        ),
        case(
            "class_name of another class",
            &[&"run", &"--detections", &banana, &"--max-frames", &"2", &"--out", &d.join("r")],
            1,
            &["banana.json", "class 2 is COCO's \"car\" but class_name \"banana\" names class 46"],
        ),
    ];
    check(cases);
    // two frames: the scale needs three poses, and says so
    let mut c = app();
    c.args(["run", "--detector", "none", "--frames", "49..", "--out"]).arg(d.join("two"));
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert!(text.contains("scale – (the alignment needs 3 poses, 2 here)"), "{text}");
    // labels of frames beyond a 20-frame run are reported
    let mut c = app();
    c.args(["run", "--detector", "none", "--frames", "0..20", "--labels"])
        .arg(fixtures().join("kitti_tracking/0000/label_02.txt"))
        .arg("--out")
        .arg(d.join("labels"));
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert!(
        text.contains("unused labels: ") && text.contains("lie after the last frame played, 19 (first: frame 20)"),
        "{text}"
    );
    // optim-bench --generated: a problem beyond this process's memory is refused with the figure before it
    // is built; the dense path alone beyond it is left out with its figure, the sparse row runs
    let mut c = app_under("ulimit -v 3000000");
    c.args(["optim-bench", "--generated", "100000", "--iterations", "1"]);
    let (code, _, err) = run_cmd(c);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("--generated 100000: the generated BA of 100000 cameras on the sparse path needs about 6.9 GB"),
        "{err}"
    );
    let mut c = app_under("ulimit -v 3000000");
    c.args(["optim-bench", "--generated", "2000", "--iterations", "1"]);
    let (code, text, err) = run_cmd(c);
    assert_eq!(code, 0, "{err}");
    assert!(text.lines().any(|l| l.starts_with("sparse")), "{text}");
    assert!(
        text.contains("dense: not run: the dense path's 11988 × 11988 reduced matrix needs about 3.6 GB"),
        "{text}"
    );
    std::fs::remove_dir_all(&d).ok();
}
