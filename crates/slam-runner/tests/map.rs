//! A map saved by one run and loaded by the next (issue 38), on the shipped odometry excerpts: a run
//! over road the map holds is placed in it from its first frame and tracks in the map's frame as well
//! as the run that made it; another road (odometry 01, localising only) places no frame and writes no
//! pose; a map made with another camera is not extended. A run that starts before the mapped road
//! (issue 46) is placed once it reaches it: its segment joins the map, and its errors are taken against
//! the ground truth expressed in the map's world.

mod common;

use common::fixture;
use slam_dataset::kitti::stereo::FrameSelection;
use slam_runner::{
    in_map::{in_map, truth_in_map, unaligned_errors},
    prepare, Outcome, RunSettings,
};

fn settings(sequence: &str, first: usize, end: usize) -> RunSettings {
    common::settings(sequence, FrameSelection { first: Some(first), end: Some(end), stride: 1 }, None)
}

fn play(s: &RunSettings) -> slam_runner::Result<Outcome> {
    prepare(s)?.run(s, &mut |_| {}, || false)
}

/// Unaligned RMS position error of the placed frames with ids in `ids` in the map's frame (a run in
/// a loaded map: the ground truth expressed in the map's world; the run that made a map: its own
/// ground truth from its first frame).
fn unaligned(o: &Outcome, ids: std::ops::RangeInclusive<usize>) -> f64 {
    let truth = match &o.loaded {
        Some(load) => truth_in_map(&o.seq, load).expect("the map's world in the ground truth").0,
        None => o.seq.truth_from_first().expect("ground truth"),
    };
    unaligned_errors(&o.out, &truth, &o.seq.ids, |id| ids.contains(&id)).expect("ground truth and placed frames").0
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
    let m = in_map(&o.out, &o.seq, o.loaded.as_ref().expect("loaded"));
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
    let m = in_map(&o.out, &o.seq, o.loaded.as_ref().expect("loaded"));
    assert_eq!((m.frames, m.placed, m.first_placed), (21, 21, Some(30)));
    let (ours, theirs) = (unaligned(&o, 30..=50), unaligned(&first, 0..=20));
    assert!(ours <= theirs + 0.10, "driven back: ATE in the map's frame {ours:.3} m, the map run's {theirs:.3} m");

    // another road, localising only: nothing placed, every frame lost, no pose written, nothing added
    let mut other = settings("kitti_odom_01/sequences/01", 0, 4);
    (other.map, other.localise_only) = (Some(file.clone()), true);
    let o = play(&other).expect("runs");
    assert!(o.loaded.as_ref().is_some_and(|l| l.reexpressed), "01's calibration differs: re-expressed");
    assert_eq!(in_map(&o.out, &o.seq, o.loaded.as_ref().expect("loaded")).placed, 0);
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

/// A segment meets the map (issue 46): a map of odometry 06 frames 30-50 (its world the camera of
/// frame 30, recorded with that frame's ground-truth pose), and a run over frames 0-50 in it. The run
/// starts outside the mapped road, so its first frames are not placed and it starts a segment of its
/// own frame; once that segment reaches the road its frame is placed and the segment joins the map:
/// every frame from then on is placed, and the segment's frames are too, all within 0.3 m of the ground
/// truth expressed in the map's world (the same poses were 35.8 m off against the ground truth as given);
/// the written map is one segment holding the loaded keyframes where they were, and adds over frames
/// 30-50 fewer keyframes than half the loaded ones there (a second copy of the road had added a
/// keyframe for each). Without the recorded world the figures are taken through the sequence's frame 30
/// (the same numbers); a map whose first frame the sequence lacks gives no figure, saying why.
#[test]
fn a_run_that_starts_before_the_mapped_road_joins_the_map_when_it_reaches_it() {
    const ODOMETRY: &str = "kitti_odom_06/sequences/06";
    let dir = std::env::temp_dir().join(format!("slam-runner-meets-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let made = play(&settings(ODOMETRY, 30, 51)).expect("the map run");
    let file = dir.join("map.json");
    let world = made.out.map.ground_truth_world.expect("the map's world in the ground truth");
    assert_eq!(world.frame, 30);
    made.out.map.save(&file).expect("saved");
    let loaded: std::collections::BTreeMap<u64, usize> =
        made.out.map.keyframes.iter().filter(|(_, k)| !k.culled).map(|(&id, k)| (id, k.frame)).collect();

    let mut run = settings(ODOMETRY, 0, 51);
    run.map = Some(file.clone());
    let o = play(&run).expect("runs in the map");
    let load = o.loaded.as_ref().expect("loaded");
    let m = in_map(&o.out, &o.seq, load);
    assert_eq!(o.out.counts.joined_segments, 1, "the segment joined the map");
    let first = m.first_placed.expect("placed");
    assert!(first < 30, "placed from frame {first}");
    assert!((first..=50).all(|id| o.out.placed[id]), "every frame from {first} on placed: {:?}", o.out.placed);
    let (rms, largest) = m.errors.expect("errors in the map's frame");
    assert!(largest < 0.3, "against the ground truth in the map's world: RMS {rms:.3} m, largest {largest:.3} m");
    assert!(m.truth.as_ref().is_ok_and(|t| t.contains("camera of frame 30")), "{:?}", m.truth);
    // one road: one segment, the loaded keyframes kept at their frames, no second copy over 30-50
    let map = &o.out.map;
    assert_eq!(map.stats().segments, 1, "one segment");
    for (id, frame) in &loaded {
        assert_eq!(map.keyframes.get(id).map(|k| k.frame), Some(*frame), "loaded keyframe {id} kept");
    }
    let added_on_road = map
        .keyframes
        .iter()
        .filter(|(id, k)| !loaded.contains_key(id) && !k.culled && (30..=50).contains(&k.frame))
        .count();
    assert!(
        2 * added_on_road < loaded.len(),
        "{added_on_road} keyframes added over frames 30-50, {} loaded",
        loaded.len()
    );
    assert_eq!(map.ground_truth_world, Some(world), "the extended map keeps its world");

    // without the recorded world: through the sequence's frame 30, the same figures
    let through_id = slam_runner::run::MapLoad { ground_truth_world: None, ..load.clone() };
    let again = in_map(&o.out, &o.seq, &through_id);
    assert!(again.truth.as_ref().is_ok_and(|t| t.contains("through this sequence's frame 30")), "{:?}", again.truth);
    let (a, b) = (m.errors.expect("e").0, again.errors.expect("e").0);
    assert!((a - b).abs() < 1e-6, "{a} {b}");
    let unknown = slam_runner::run::MapLoad { ground_truth_world: None, first_frame: Some(99), ..load.clone() };
    let none = in_map(&o.out, &o.seq, &unknown);
    assert!(none.errors.is_none() && none.truth.as_ref().is_err_and(|e| e.contains("no ground truth of a frame 99")));
    std::fs::remove_dir_all(&dir).ok();
}
