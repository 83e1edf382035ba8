//! The CLI as a user runs it.

use std::process::Command;

fn app() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_slam-app"));
    c.current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    c
}

#[test]
fn assoc_kitti_on_shipped_labels() {
    let out = app().args(["assoc", "kitti"]).output().expect("runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(text.lines().filter(|l| l.starts_with("00")).count(), 17, "{text}");
    let total = text.lines().find(|l| l.starts_with("total")).expect("total row");
    // first column pair: clean boxes, "ODA / IoU"
    let cell = total.split('|').nth(1).expect("cell");
    let nums: Vec<usize> = cell.split('/').map(|s| s.trim().parse().expect("number")).collect();
    assert!(nums[0] < nums[1], "ODA should switch less than IoU-only: {total}");
}

#[test]
fn assoc_kitti_missing_dir_is_a_clear_error() {
    let out = app().args(["assoc", "kitti", "/no/such/dir"]).output().expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/no/such/dir"), "{err}");
}

#[test]
fn help_lists_commands() {
    let out = app().arg("--help").output().expect("runs");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && text.contains("assoc"), "{text}");
}
