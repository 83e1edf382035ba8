//! The threaded system with a scripted tracker (no OpenCV): keyframes reach local mapping, its
//! corrections come back and fix the tracker's scale drift, a parked car is mapped, a moving one is
//! flagged, an unreadable frame is counted, two runs give identical output, and driving the system
//! frame by frame ([`System::step`]) gives what a whole run does.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use slam_core::{
    geometry::BBox, ClassId, DetectError, Detection, DetectionSource, Image, KeyframeCorrection, KeyframeData,
    KeyframePoint, PointPair, StageTimes, StereoTracker, TrackError, TrackState, TrackedFrame,
};
use slam_pipeline::system::{run, FrameInput, FrameRecord, RunOutput, SystemBuilder, SystemConfig, SystemError};
use slam_quadric::{metrics, project, Camera, Ellipsoid, ImageSize, Intrinsics};

const K: Intrinsics = Intrinsics { fx: 721.5377, fy: 721.5377, skew: 0.0, cx: 609.5593, cy: 172.854 };
const B: f64 = 0.54;
const IMAGE: ImageSize = ImageSize::new(1242.0, 375.0);
const FRAMES: usize = 40;

fn truth(i: usize) -> Isometry3<f64> {
    Isometry3::translation(0.05 * i as f64, 0.0, 1.0 * i as f64)
}

fn parked() -> Ellipsoid {
    Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(5.0, 0.9, 28.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -std::f64::consts::FRAC_PI_2 + 0.05),
        ),
        Vector3::new(2.0, 0.78, 0.85),
    )
}

fn moving(i: usize) -> Ellipsoid {
    Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(-4.0, 0.9, 12.0 + 1.8 * i as f64),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -std::f64::consts::FRAC_PI_2),
        ),
        Vector3::new(2.0, 0.78, 0.85),
    )
}

/// A tracker whose poses are 3 % too long (a scale drift), taking a keyframe every third frame with
/// exact stereo observations of a static point field (ids fixed per point).
struct Scripted {
    points: Vec<Vector3<f64>>,
    /// `(keyframe id, its pose as the tracker believes it)`.
    reference: Option<(u64, Isometry3<f64>)>,
    next_kf: u64,
    corrections: usize,
}

impl Scripted {
    fn new() -> Self {
        let mut rng = slam_core::rng::SimRng::new(11);
        let mut points: Vec<Vector3<f64>> = (0..600)
            .map(|_| Vector3::new(rng.uniform(-20.0, 20.0), rng.uniform(-3.0, 1.5), rng.uniform(5.0, 90.0)))
            .collect();
        // texture on the parked car's side facing the road (x = 5 − 0.85)
        for k in 0..30 {
            points.push(Vector3::new(4.15, 0.4 + 0.03 * (k % 10) as f64, 26.5 + 0.1 * k as f64));
        }
        Self { points, reference: None, next_kf: 0, corrections: 0 }
    }

    fn believed(i: usize) -> Isometry3<f64> {
        let t = truth(i);
        Isometry3::translation(0.0, 0.0, 0.03 * t.translation.vector.z) * t
    }
}

impl StereoTracker for Scripted {
    fn track(&mut self, frame: usize, _: &Image, _: &Image, _: &[BBox]) -> Result<TrackedFrame, TrackError> {
        let pose = Self::believed(frame);
        let (ref_id, ref_pose) = self.reference.unwrap_or((0, pose));
        let keyframe = (frame % 3 == 0).then(|| {
            let t = truth(frame);
            let cam = Camera::new(K, t);
            let cars: Vec<(BBox, f64)> = [parked(), moving(frame)]
                .iter()
                .filter_map(|e| {
                    let b = project(e, &cam).and_then(|c| c.clipped_bounds(&IMAGE)).ok()?;
                    Some((b, (t.inverse() * Point3::from(e.centre())).z))
                })
                .collect();
            let points: Vec<KeyframePoint> = self
                .points
                .iter()
                .enumerate()
                .filter_map(|(id, x)| {
                    let c = t.inverse() * Point3::from(*x);
                    if c.z < 1.0 {
                        return None;
                    }
                    let u = K.fx * c.x / c.z + K.cx;
                    let v = K.fy * c.y / c.z + K.cy;
                    // the cars hide the field points behind them
                    let hidden = id < 600 && cars.iter().any(|(b, depth)| c.z > depth - 1.0 && b.contains_point(u, v));
                    (!hidden && (0.0..IMAGE.width).contains(&u) && (0.0..IMAGE.height).contains(&v)).then_some(
                        KeyframePoint {
                            id: id as u64,
                            camera_point: c.coords,
                            observation: [u, v, u - K.fx * B / c.z],
                        },
                    )
                })
                .collect();
            // texture on the overtaking car's rear, where the car is now (fresh ids: they are not the
            // same world points)
            let mut points: Vec<KeyframePoint> = points;
            let m = moving(frame).centre();
            for k in 0..20 {
                let x = Vector3::new(m.x - 0.5 + 0.05 * k as f64, 0.5 + 0.03 * (k % 10) as f64, m.z - 1.9);
                let c = t.inverse() * Point3::from(x);
                let u = K.fx * c.x / c.z + K.cx;
                points.push(KeyframePoint {
                    id: 100_000 + 100 * frame as u64 + k,
                    camera_point: c.coords,
                    observation: [u, K.fy * c.y / c.z + K.cy, u - K.fx * B / c.z],
                });
            }
            let id = self.next_kf;
            self.next_kf += 1;
            let parent = self.reference.map(|(rid, rp)| (rid, rp.inverse() * pose));
            KeyframeData { id, frame, world_from_camera: pose, parent, points, earlier: vec![] }
        });
        let relative = ref_pose.inverse() * pose;
        if let Some(kf) = &keyframe {
            self.reference = Some((kf.id, pose));
        }
        Ok(TrackedFrame {
            world_from_camera: pose,
            reference: (ref_id, if frame == 0 { Isometry3::identity() } else { relative }),
            state: if frame == 0 { TrackState::Initialised } else { TrackState::Tracked { inliers: 100 } },
            stereo_points: 100,
            tracked_map_points: 100,
            reprojection_rms_px: 0.5,
            keyframe,
            times: StageTimes::default(),
        })
    }

    fn correct(&mut self, c: &KeyframeCorrection) {
        self.corrections += 1;
        assert!(c.world_from_camera.translation.vector.iter().all(|v| v.is_finite()));
    }

    fn flow(&mut self, _: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        Ok(Vec::new())
    }
}

/// Exact boxes of both cars in the true cameras.
struct Boxes;

impl DetectionSource for Boxes {
    fn name(&self) -> &str {
        "scripted"
    }
    fn needs_image(&self) -> bool {
        false
    }
    fn detect(&mut self, frame: usize, _: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
        let cam = Camera::new(K, truth(frame));
        Ok([parked(), moving(frame)]
            .iter()
            .filter_map(|e| project(e, &cam).and_then(|c| c.clipped_bounds(&IMAGE)).ok())
            .filter(|b| b.width() > 4.0)
            .map(|b| Detection::new(ClassId(2), 0.9, b))
            .collect())
    }
}

fn frames() -> Box<dyn Iterator<Item = FrameInput> + Send> {
    Box::new((0..FRAMES).map(|i| FrameInput {
        index: i,
        images: if i == 17 {
            Err("frame 17: file missing".to_string())
        } else {
            Ok((Image::new(1, 1, 1, vec![0]).expect("image"), Image::new(1, 1, 1, vec![0]).expect("image")))
        },
    }))
}

fn config() -> SystemConfig {
    let mut c = SystemConfig::default();
    c.objects.image = IMAGE;
    c
}

#[test]
fn threads_correct_the_drift_and_map_the_parked_car() {
    let mut seen = Vec::new();
    let out = run(frames(), Box::new(Scripted::new()), Some(Box::new(Boxes)), K, B, &config(), lm(), &mut |r| {
        seen.push(r.index)
    })
    .expect("runs");
    assert_eq!(seen, (0..FRAMES).collect::<Vec<_>>(), "every frame reported, in order");
    assert_eq!(out.poses.len(), FRAMES);
    assert_eq!(out.counts.unreadable, 1);
    assert_eq!(out.counts.keyframes, FRAMES.div_ceil(3) - usize::from(17 % 3 == 0));
    // the tracker's poses are 3 % long; local BA against exact stereo observations removes most of it
    let err = |poses: &dyn Fn(usize) -> Isometry3<f64>| -> f64 {
        (0..FRAMES).map(|i| (poses(i).translation.vector - truth(i).translation.vector).norm()).sum::<f64>()
            / FRAMES as f64
    };
    let before = err(&Scripted::believed);
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
    let a = run(frames(), Box::new(Scripted::new()), Some(Box::new(Boxes)), K, B, &config(), lm(), &mut |_| {})
        .expect("runs");
    let b = run(frames(), Box::new(Scripted::new()), Some(Box::new(Boxes)), K, B, &config(), lm(), &mut |_| {})
        .expect("runs");
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
    let ran = run(frames(), Box::new(Scripted::new()), Some(Box::new(Boxes)), K, B, &config(), lm(), &mut |_| {})
        .expect("runs");
    let mut system = SystemBuilder::new(K, B)
        .config(config())
        .tracker(Box::new(Scripted::new()))
        .detector(Some(Box::new(Boxes)))
        .optimizer(lm())
        .build()
        .expect("builds");
    let mut seen = Vec::new();
    for f in frames() {
        seen.push(decisions(system.step(f).expect("steps")));
        assert_eq!(system.tracking().records().len(), seen.len());
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

#[test]
fn a_builder_without_a_tracker_or_an_optimiser_is_an_error() {
    let no_tracker = SystemBuilder::new(K, B).optimizer(lm()).build();
    assert!(matches!(no_tracker, Err(SystemError::Missing("tracker"))));
    let no_optimizer = SystemBuilder::new(K, B).tracker(Box::new(Scripted::new())).build();
    assert!(matches!(no_optimizer, Err(SystemError::Missing("optimizer"))));
    // run needs a source
    let no_source = SystemBuilder::new(K, B).tracker(Box::new(Scripted::new())).optimizer(lm()).build().expect("builds");
    assert!(matches!(no_source.run(&mut |_| {}), Err(SystemError::Missing("frame source"))));
}

/// The optimiser of these tests (the project's Levenberg–Marquardt).
fn lm() -> slam_optim::SharedOptimizer {
    std::sync::Arc::new(slam_lm::LevenbergMarquardt::default())
}
