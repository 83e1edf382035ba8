//! Interrupted runs: SIGKILL at seeded random moments of `run --out` into a folder holding a previous run
//! leaves that folder exactly as the old run or exactly as the new run wrote it; Ctrl-C stops cleanly and
//! keeps the old output.

use std::{
    collections::BTreeMap,
    io::{BufRead, BufReader},
    path::{Path, PathBuf},
    process::{Command, Stdio},
    time::{Duration, Instant},
};

fn app() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_slam-app"));
    c.current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    c
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("slam-kill-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch");
    d
}

/// Every file under `dir` (relative path → bytes).
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        let Ok(rd) = std::fs::read_dir(dir) else { return };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.insert(p.strip_prefix(root).expect("inside").join(""), Vec::new());
                walk(root, &p, out);
            } else {
                let mut bytes = std::fs::read(&p).expect("read");
                if p.file_name().is_some_and(|n| n == "tracking.csv") {
                    // the last column is each frame's processing time, which differs between runs
                    let text = String::from_utf8_lossy(&bytes).into_owned();
                    bytes = text
                        .lines()
                        .map(|l| l.rsplit_once(',').map_or(l, |(a, _)| a))
                        .collect::<Vec<_>>()
                        .join("\n")
                        .into_bytes();
                }
                out.insert(p.strip_prefix(root).expect("inside").to_path_buf(), bytes);
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn run_args(frames: &str, out: &Path) -> Vec<std::ffi::OsString> {
    let mut v: Vec<std::ffi::OsString> =
        ["run", "--detector", "none", "--overlays", "--max-frames", frames, "--out"].iter().map(Into::into).collect();
    v.push(out.into());
    v
}

fn run_to_end(frames: &str, out: &Path) -> Duration {
    let start = Instant::now();
    let o = app().args(run_args(frames, out)).output().expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    start.elapsed()
}

#[test]
fn sigkill_at_random_moments_leaves_the_old_or_the_new_run() {
    let d = scratch("sigkill");
    let out = d.join("out");
    // the two outputs a run may leave: 3 frames (with overlays) and 5 frames
    let configs = ["3", "5"];
    let mut refs = Vec::new();
    let mut longest = Duration::ZERO;
    for c in configs {
        let r = d.join(format!("ref{c}"));
        longest = longest.max(run_to_end(c, &r));
        refs.push(snapshot(&r));
    }
    assert_ne!(refs[0], refs[1]);
    run_to_end(configs[0], &out);
    assert!(snapshot(&out) == refs[0]);
    let mut current = 0;
    // seeded delays over the whole run, start-up and the final swap included
    let mut state: u64 = 20261123;
    let mut seen = [0usize; 2];
    for k in 0..10 {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let u = (state >> 11) as f64 / (1u64 << 53) as f64;
        let delay = if k == 0 { Duration::ZERO } else { longest.mul_f64(1.3 * u) };
        let next = 1 - current;
        let mut child = app()
            .args(run_args(configs[next], &out))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn");
        std::thread::sleep(delay);
        let _ = child.kill(); // SIGKILL
        let _ = child.wait();
        let now = snapshot(&out);
        let which = refs.iter().position(|r| *r == now);
        let Some(which) = which else {
            let names: Vec<&PathBuf> = now.keys().collect();
            panic!("kill {k} after {delay:?}: {} is neither the old nor the new run: {names:?}", out.display());
        };
        assert!(which == current || which == next);
        seen[(which == next) as usize] += 1;
        current = which;
    }
    assert!(seen[0] >= 1, "the immediate kill keeps the old run: {seen:?}");
    println!("10 kills over {longest:?}: {} left the old run, {} the new one", seen[0], seen[1]);
    // a finished run afterwards removes what the killed runs left beside the folder
    run_to_end(configs[1 - current], &out);
    let left: Vec<String> = std::fs::read_dir(&d)
        .expect("list")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".out."))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn ctrl_c_stops_cleanly_and_keeps_the_previous_run() {
    let d = scratch("ctrlc");
    let out = d.join("out");
    run_to_end("3", &out);
    let before = snapshot(&out);
    let mut child = app()
        .args(["run", "--detector", "none", "--out"])
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    // the first line is printed once the handler is in place and the sequence is open
    let mut stdout = BufReader::new(child.stdout.take().expect("stdout"));
    let mut line = String::new();
    stdout.read_line(&mut line).expect("first line");
    assert!(line.starts_with("quadric SLAM on"), "{line}");
    let pid = child.id().to_string();
    let sent = Command::new("kill").args(["-INT", &pid]).status().expect("kill");
    assert!(sent.success());
    let o = child.wait_with_output().expect("waits");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{err}");
    assert!(
        err.contains("Ctrl-C after") && err.contains("nothing written") && err.contains("keeps the previous run"),
        "{err}"
    );
    assert!(snapshot(&out) == before, "the previous run is untouched");
    let left: Vec<String> =
        std::fs::read_dir(&d).expect("list").flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left, ["out"], "no temporary folder left");
    std::fs::remove_dir_all(&d).ok();
}

/// Ctrl-C in a command that does not stop by itself (issue 39: `detect` left `.det.json.tmp-PID` behind
/// for good): the temporary file it was writing is removed, the message says so, exit status 130; a
/// temporary left by a process that no longer runs is removed by the next write of the same file.
#[test]
fn ctrl_c_in_any_command_removes_its_temporary_files() {
    let d = scratch("ctrlc-detect");
    // 400 frames (links to the shipped images): tens of seconds of detection, time enough to interrupt
    let imgs = d.join("imgs");
    std::fs::create_dir_all(&imgs).expect("dir");
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/kitti_odom_06/sequences/06/image_0");
    for i in 0..400 {
        std::os::unix::fs::symlink(shipped.join(format!("{:06}.png", i % 51)), imgs.join(format!("{i:06}.png")))
            .expect("link");
    }
    let out = d.join("det.json");
    // left by a process that no longer runs (pid 0 is never one)
    let stale = d.join(".det.json.tmp-0");
    std::fs::write(&stale, "left").expect("write");
    let child = app()
        .arg("detect")
        .arg(&imgs)
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    // the temporary output is made before the model loads: once it exists, the command is at work
    let tmp = d.join(format!(".det.json.tmp-{}", child.id()));
    let start = Instant::now();
    while !tmp.exists() && start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(tmp.exists(), "detect made its temporary output");
    assert!(!stale.exists(), "a dead process's temporary is removed when the same file is written");
    std::thread::sleep(Duration::from_millis(1500));
    let sent = Command::new("kill").args(["-INT", &child.id().to_string()]).status().expect("kill");
    assert!(sent.success());
    let o = child.wait_with_output().expect("waits");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted: Ctrl-C") && err.contains("1 temporary file(s) or folder(s) removed"), "{err}");
    let left: Vec<String> =
        std::fs::read_dir(&d).expect("list").flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left, ["imgs"], "nothing but the input is left");
    std::fs::remove_dir_all(&d).ok();
}
