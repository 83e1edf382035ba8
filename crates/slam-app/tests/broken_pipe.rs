//! A reader that closes the pipe early (`slam-app … | head`) ends the program quietly.

use std::{
    io::Read,
    process::{Command, Stdio},
};

#[test]
fn closed_stdout_is_a_quiet_success() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_slam-app"))
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .args(["run", "--print-config"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starts");
    // close the reading end before the program has printed anything: its first write meets a broken pipe
    drop(child.stdout.take());
    let mut err = String::new();
    child.stderr.take().expect("piped").read_to_string(&mut err).expect("stderr reads");
    let status = child.wait().expect("ends");
    assert!(status.success(), "status {status:?}, stderr: {err}");
    assert!(!err.contains("panicked"), "a panic on a closed pipe: {err}");
    assert!(!err.contains("error"), "a closed pipe reported as an error: {err}");
}

#[test]
fn print_config_still_reaches_an_open_pipe() {
    let out = Command::new(env!("CARGO_BIN_EXE_slam-app"))
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .args(["run", "--print-config"])
        .output()
        .expect("runs");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.lines().count() > 5, "print-config printed: {text}");
    assert!(text.ends_with('\n'), "the last line lost its end: {text:?}");
}
