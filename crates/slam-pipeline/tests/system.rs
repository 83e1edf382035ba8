//! The threaded system with a scripted tracker (no OpenCV): keyframes reach local mapping, its
//! corrections come back and fix the tracker's scale drift, a parked car is mapped, a moving one is
//! flagged, an unreadable frame is counted, two runs give identical output, and driving the system
//! frame by frame ([`System::step`]) gives what a whole run does.

use std::collections::BTreeMap;

mod common;

use common::{car, field, lm, Scene, ScriptedBoxes, ScriptedTracker, B, IMAGE, K};
use nalgebra::{Isometry3, Vector3};
use slam_pipeline::system::{run, FrameInput, FrameRecord, RunOutput, SystemBuilder, SystemConfig, SystemError};
use slam_quadric::{metrics, Ellipsoid};

const FRAMES: usize = 40;

fn truth(i: usize) -> Isometry3<f64> {
    Isometry3::translation(0.05 * i as f64, 0.0, 1.0 * i as f64)
}

fn parked() -> Ellipsoid {
    car(5.0, 28.0, 0.05)
}

fn moving(i: usize) -> Ellipsoid {
    car(-4.0, 12.0 + 1.8 * i as f64, 0.0)
}

fn cars(i: usize) -> Vec<Ellipsoid> {
    vec![parked(), moving(i)]
}

/// The poses the tracker reports: 3 % too long (a scale drift).
fn believed(i: usize) -> Isometry3<f64> {
    let t = truth(i);
    Isometry3::translation(0.0, 0.0, 0.03 * t.translation.vector.z) * t
}

/// Texture on the parked car's side facing the road (x = 5 − 0.85), and on the overtaking car's rear
/// where the car is now (fresh ids: they are not the same world points).
fn texture(frame: usize) -> Vec<(u64, Vector3<f64>)> {
    let mut t: Vec<(u64, Vector3<f64>)> =
        (0..30).map(|k| (600 + k, Vector3::new(4.15, 0.4 + 0.03 * (k % 10) as f64, 26.5 + 0.1 * k as f64))).collect();
    let m = moving(frame).centre();
    for k in 0..20 {
        let x = Vector3::new(m.x - 0.5 + 0.05 * k as f64, 0.5 + 0.03 * (k % 10) as f64, m.z - 1.9);
        t.push((100_000 + 100 * frame as u64 + k, x));
    }
    t
}

/// A tracker with the drift of [`believed`], taking a keyframe every third frame with exact stereo
/// observations of a static point field (ids fixed per point).
fn tracker() -> Box<ScriptedTracker> {
    Box::new(ScriptedTracker::new(Scene { truth, believed, cars, field: field(11, 600), texture }))
}

/// Exact boxes of both cars in the true cameras.
fn boxes() -> Option<Box<dyn slam_core::DetectionSource>> {
    Some(Box::new(ScriptedBoxes { truth, cars }))
}

/// Every frame, frame 17 unreadable.
fn frames() -> Box<dyn Iterator<Item = FrameInput> + Send> {
    common::frames(FRAMES, Some(17))
}

fn config() -> SystemConfig {
    let mut c = SystemConfig::default();
    c.objects.image = IMAGE;
    c
}

#[test]
fn threads_correct_the_drift_and_map_the_parked_car() {
    let mut seen = Vec::new();
    let out = run(frames(), tracker(), boxes(), K, B, &config(), lm(), &mut |r| seen.push(r.index)).expect("runs");
    assert_eq!(seen, (0..FRAMES).collect::<Vec<_>>(), "every frame reported, in order");
    assert_eq!(out.poses.len(), FRAMES);
    assert_eq!(out.counts.unreadable, 1);
    assert_eq!(out.counts.keyframes, FRAMES.div_ceil(3) - usize::from(17 % 3 == 0));
    // the tracker's poses are 3 % long; local BA against exact stereo observations removes most of it
    let err = |poses: &dyn Fn(usize) -> Isometry3<f64>| -> f64 {
        (0..FRAMES).map(|i| (poses(i).translation.vector - truth(i).translation.vector).norm()).sum::<f64>()
            / FRAMES as f64
    };
    let before = err(&believed);
    let after = err(&|i| out.poses[i]);
    assert!(after < 0.3 * before, "mean position error {after:.3} m (tracker {before:.3} m)");
    // the parked car: one static ellipsoid near the truth; the moving car: flagged, not mapped
    let with: Vec<_> = out.objects.iter().filter(|o| o.ellipsoid.is_some() && !o.dynamic).collect();
    assert_eq!(with.len(), 1, "{:?}", out.objects.iter().map(|o| (o.id, o.dynamic, o.moving)).collect::<Vec<_>>());
    let e = with[0].ellipsoid.expect("ellipsoid");
    assert!(metrics::e_trans(&e, &parked()) < 0.6, "centre error {:.2} m", metrics::e_trans(&e, &parked()));
    assert!(!with[0].points.is_empty(), "the car's texture points are attached");
    assert!(out.objects.iter().any(|o| o.moving), "the overtaking car is detected as moving");
    // the map holds the same objects and one pose per frame
    assert_eq!(out.map.trajectory.len(), FRAMES);
    assert_eq!(out.map.trajectory[17].state, "unreadable");
    assert!(out.map.objects.iter().any(|o| !o.dynamic));
}

#[test]
fn two_runs_give_identical_output() {
    let a = run(frames(), tracker(), boxes(), K, B, &config(), lm(), &mut |_| {}).expect("runs");
    let b = run(frames(), tracker(), boxes(), K, B, &config(), lm(), &mut |_| {}).expect("runs");
    assert_eq!(a.map, b.map);
    let by_id = |o: &slam_pipeline::system::RunOutput| -> BTreeMap<u64, Option<Vector3<f64>>> {
        o.objects.iter().map(|x| (x.id.0, x.ellipsoid.map(|e| e.centre()))).collect()
    };
    assert_eq!(by_id(&a), by_id(&b));
}

/// What a run decided per frame (its records without the wall-clock times).
fn decisions(r: &FrameRecord) -> (usize, Option<slam_core::TrackState>, bool, usize, Vec<Option<slam_core::TrackId>>) {
    (r.index, r.state, r.keyframe, r.tracked_map_points, r.tracks.clone())
}

fn ellipsoids(o: &RunOutput) -> BTreeMap<u64, (Option<Ellipsoid>, bool, bool)> {
    o.objects.iter().map(|x| (x.id.0, (x.ellipsoid, x.dynamic, x.moving))).collect()
}

#[test]
fn stepping_frame_by_frame_gives_what_run_gives() {
    let ran = run(frames(), tracker(), boxes(), K, B, &config(), lm(), &mut |_| {}).expect("runs");
    let mut system = SystemBuilder::new(K, B)
        .config(config())
        .tracker(tracker())
        .detector(boxes())
        .optimizer(lm())
        .build()
        .expect("builds");
    let mut seen = Vec::new();
    for f in frames() {
        seen.push(decisions(system.step(f).expect("steps")));
        assert_eq!(system.tracking_thread().records().len(), seen.len());
    }
    let stepped = system.finish().expect("finishes");
    assert_eq!(seen, ran.frames.iter().map(decisions).collect::<Vec<_>>(), "per-frame decisions");
    assert_eq!(stepped.frames.iter().map(decisions).collect::<Vec<_>>(), seen);
    assert_eq!(stepped.map, ran.map, "map: keyframes, points, trajectory, objects");
    assert_eq!(stepped.poses, ran.poses);
    assert_eq!(stepped.counts, ran.counts);
    assert_eq!(ellipsoids(&stepped), ellipsoids(&ran));
    assert!(ellipsoids(&ran).values().any(|e| e.0.is_some()), "the comparison includes a fitted object");
}

/// What `System::run` shows its observer of each frame: the pose tracking gave it (the tracker's
/// believed pose), the left image unless the frame is unreadable, each keyframe's local mapping once,
/// `correction_lag` frames after the keyframe (or before the next keyframe goes in), and the objects
/// mapped so far.
#[test]
fn each_frame_is_shown_with_its_pose_image_corrections_and_objects() {
    let system = SystemBuilder::new(K, B)
        .config(config())
        .source(frames())
        .tracker(tracker())
        .detector(boxes())
        .optimizer(lm())
        .build()
        .expect("builds");
    let (mut corrected, mut keyframes, mut with_objects) = (Vec::new(), Vec::new(), 0);
    let out = system
        .run(&mut |v| {
            let i = v.record.index;
            assert_eq!(v.left.is_some(), i != 17, "frame {i}: the left image unless unreadable");
            match v.world_from_camera {
                Some(p) => assert!((p.translation.vector - believed(i).translation.vector).norm() < 1e-9, "frame {i}"),
                None => assert_eq!(i, 17, "only the unreadable frame has no pose"),
            }
            if v.record.keyframe {
                keyframes.push(i);
            }
            for &k in v.mapped {
                let kf = v.map.keyframe(k).expect("a keyframe whose local mapping was applied is in the map");
                assert!(kf.observed() > 0, "a mapped keyframe observes points");
                corrected.push(i);
            }
            with_objects += usize::from(v.objects.objects().any(|o| o.ellipsoid.is_some()));
        })
        .expect("runs");
    // every keyframe but those of the last `correction_lag` frames is shown corrected 2 frames later
    // (frame 17 is unreadable, so the lag counts played frames: ids and positions agree here)
    let lag = config().correction_lag;
    let due: Vec<usize> = keyframes.iter().map(|k| k + lag).filter(|&f| f < FRAMES).collect();
    assert_eq!(corrected, due);
    assert_eq!(keyframes.len(), out.counts.keyframes);
    assert!(with_objects > 0 && with_objects < FRAMES, "objects appear during the run: {with_objects} frames");
}

#[test]
fn a_builder_without_a_tracker_or_an_optimiser_is_an_error() {
    let no_tracker = SystemBuilder::new(K, B).optimizer(lm()).build();
    assert!(matches!(no_tracker, Err(SystemError::Missing("tracker"))));
    let no_optimizer = SystemBuilder::new(K, B).tracker(tracker()).build();
    assert!(matches!(no_optimizer, Err(SystemError::Missing("optimizer"))));
    // run needs a source
    let no_source = SystemBuilder::new(K, B).tracker(tracker()).optimizer(lm()).build().expect("builds");
    assert!(matches!(no_source.run(&mut |_| {}), Err(SystemError::Missing("frame source"))));
}

/// `detect_every` counts the frames played, not their ids: played every 2nd id from an odd one (ids 1,
/// 3, 5, ...), every 2nd frame gets boxes; counting ids would give none (no odd id is a multiple of 2).
#[test]
fn detect_every_counts_played_frames_not_ids() {
    let odd: Box<dyn Iterator<Item = FrameInput> + Send> =
        Box::new(common::frames(16, None).map(|f| FrameInput { index: 2 * f.index + 1, ..f }));
    let cfg = SystemConfig { detect_every: 2, ..config() };
    let out = run(odd, tracker(), boxes(), K, B, &cfg, lm(), &mut |_| {}).expect("runs");
    let with_boxes: Vec<usize> =
        out.frames.iter().enumerate().filter(|(_, r)| !r.detections.is_empty()).map(|(k, _)| k).collect();
    assert_eq!(with_boxes, (0..16).step_by(2).collect::<Vec<_>>(), "the 1st, 3rd, 5th ... played frame");
}
