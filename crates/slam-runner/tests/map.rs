//! A map saved by one run and loaded by the next (issue 38), on the shipped odometry excerpts: a run
//! over road the map holds is placed in it from its first frame and tracks in the map's frame as well
//! as the run that made it; another road (odometry 01, localising only) places no frame and writes no
//! pose; a map made with another camera is not extended.

mod common;

use common::fixture;
use slam_dataset::kitti::stereo::FrameSelection;
use slam_runner::{
    in_map::{in_map, unaligned_errors},
    prepare, Outcome, RunSettings,
};

fn settings(sequence: &str, first: usize, end: usize) -> RunSettings {
    common::settings(sequence, FrameSelection { first: Some(first), end: Some(end), stride: 1 }, None)
}

fn play(s: &RunSettings) -> slam_runner::Result<Outcome> {
    prepare(s)?.run(s, &mut |_| {}, || false)
}

/// Unaligned RMS position error of the placed frames with ids in `ids` (the map's frame).
fn unaligned(o: &Outcome, ids: std::ops::RangeInclusive<usize>) -> f64 {
    unaligned_errors(&o.out, &o.seq, |id| ids.contains(&id)).expect("ground truth and placed frames").0
}

#[test]
fn a_saved_map_places_the_same_road_and_nothing_of_another() {
    const ODOMETRY: &str = "kitti_odom_06/sequences/06";
    let dir = std::env::temp_dir().join(format!("slam-runner-map-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let first = play(&settings(ODOMETRY, 0, 21)).expect("the map run");
    let file = dir.join("map.json");
    first.out.map.save(&file).expect("saved");
    let made = first.out.map.stats().keyframes;

    // frames 10-20 again, in the map: placed from the first frame, as accurate as the map run
    let mut again = settings(ODOMETRY, 10, 21);
    again.map = Some(file.clone());
    let o = play(&again).expect("runs in the map");
    let m = in_map(&o.out, &o.seq);
    assert_eq!((m.frames, m.placed, m.first_placed), (11, 11, Some(10)));
    assert!(o.out.placed.iter().all(|p| *p));
    let (ours, theirs) = (unaligned(&o, 10..=20), unaligned(&first, 10..=20));
    assert!(ours <= theirs + 0.05, "ATE in the map's frame {ours:.3} m, the map run's {theirs:.3} m");
    assert_eq!(o.out.counts.new_segments, 0);
    // the output map holds the loaded keyframes and what this run added
    let st = o.out.map.stats();
    assert!(st.keyframes >= made, "{} keyframes after, {made} loaded", st.keyframes);
    assert!(o.summary(100).contains("placed in the map: 11 of 11 frames, from frame 10"), "{}", o.summary(100));

    // the same road driven back (frames 20 down to 0 of a reversed layout): placed, as accurate
    let back = slam_dataset::layout::write_layout(
        &fixture(ODOMETRY),
        slam_dataset::layout::Order::Reversed,
        &dir.join("back"),
    )
    .expect("layout");
    let mut reverse = settings(ODOMETRY, 30, 51);
    (reverse.path, reverse.map) = (back, Some(file.clone()));
    let o = play(&reverse).expect("runs back in the map");
    let m = in_map(&o.out, &o.seq);
    assert_eq!((m.frames, m.placed, m.first_placed), (21, 21, Some(30)));
    let (ours, theirs) = (unaligned(&o, 30..=50), unaligned(&first, 0..=20));
    assert!(ours <= theirs + 0.10, "driven back: ATE in the map's frame {ours:.3} m, the map run's {theirs:.3} m");

    // another road, localising only: nothing placed, every frame lost, no pose written, nothing added
    let mut other = settings("kitti_odom_01/sequences/01", 0, 4);
    (other.map, other.localise_only) = (Some(file.clone()), true);
    let o = play(&other).expect("runs");
    assert!(o.loaded.as_ref().is_some_and(|l| l.reexpressed), "01's calibration differs: re-expressed");
    assert_eq!(in_map(&o.out, &o.seq).placed, 0);
    assert_eq!(o.out.counts.lost, 4, "every frame lost");
    assert!(o.out.map.trajectory.iter().all(|f| f.keyframe.is_none() && f.state == "lost"));
    assert_eq!(o.out.map.stats().keyframes, made, "nothing added");
    assert!(o.nothing_tracked().is_none(), "not placed is the map's answer, not an error");
    let out = dir.join("other");
    std::fs::create_dir_all(&out).expect("dir");
    o.write_files(&out, &out).expect("writes");
    assert_eq!(std::fs::read_to_string(out.join("trajectory.kitti.txt")).expect("kitti").lines().count(), 0);
    assert_eq!(std::fs::read_to_string(out.join("tracking.csv")).expect("csv").lines().count(), 5);

    // extending a map made with another camera is refused, naming the difference
    other.localise_only = false;
    let e = play(&other).err().expect("another camera").to_string();
    assert!(e.contains("made with another camera") && e.contains("fx 707.0912 px in the map"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
