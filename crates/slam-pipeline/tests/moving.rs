//! Moving objects from stereo points, in the threaded system with a scripted tracker: a car driving
//! ahead at the camera's speed (its boxes barely change) and one at half the speed (its boxes are those
//! of a static car twice as far) are both found moving from their points and neither is mapped; the
//! parked car beside the road is mapped.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use slam_core::{
    geometry::BBox, ClassId, DetectError, Detection, DetectionSource, Image, KeyframeCorrection, KeyframeData,
    KeyframePoint, PointPair, StageTimes, StereoTracker, TrackError, TrackState, TrackedFrame,
};
use slam_pipeline::system::{run, FrameInput, SystemConfig};
use slam_quadric::{metrics, project, Camera, Ellipsoid, ImageSize, Intrinsics};

const K: Intrinsics = Intrinsics { fx: 721.5377, fy: 721.5377, skew: 0.0, cx: 609.5593, cy: 172.854 };
const B: f64 = 0.54;
const IMAGE: ImageSize = ImageSize::new(1242.0, 375.0);
const FRAMES: usize = 36;

fn pose(i: usize) -> Isometry3<f64> {
    Isometry3::translation(0.0, 0.0, 1.0 * i as f64)
}

fn car(x: f64, z: f64) -> Ellipsoid {
    Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(x, 0.9, z),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -std::f64::consts::FRAC_PI_2),
        ),
        Vector3::new(2.0, 0.78, 0.85),
    )
}

fn parked() -> Ellipsoid {
    car(5.0, 30.0)
}

/// Ahead in the left lane at the camera's speed (1 m per frame).
fn same_speed(i: usize) -> Ellipsoid {
    car(-3.0, 14.0 + 1.0 * i as f64)
}

/// Ahead in the right lane at half the camera's speed.
fn half_speed(i: usize) -> Ellipsoid {
    car(2.5, 30.0 + 0.5 * i as f64)
}

fn cars(i: usize) -> [Ellipsoid; 3] {
    [parked(), same_speed(i), half_speed(i)]
}

/// Exact poses, a keyframe every third frame with exact stereo points: a static field and texture on
/// each car's surface facing the camera (fresh ids on the moving ones: not the same world points).
struct Scripted {
    field: Vec<Vector3<f64>>,
    next_kf: u64,
    reference: Option<(u64, Isometry3<f64>)>,
}

impl StereoTracker for Scripted {
    fn track(&mut self, frame: usize, _: &Image, _: &Image, _: &[BBox]) -> Result<TrackedFrame, TrackError> {
        let t = pose(frame);
        let (ref_id, ref_pose) = self.reference.unwrap_or((0, t));
        let keyframe = (frame % 3 == 0).then(|| {
            let cam = Camera::new(K, t);
            let boxes: Vec<(BBox, f64)> = cars(frame)
                .iter()
                .filter_map(|e| {
                    let b = project(e, &cam).and_then(|c| c.clipped_bounds(&IMAGE)).ok()?;
                    Some((b, (t.inverse() * Point3::from(e.centre())).z))
                })
                .collect();
            let observe = |id: u64, x: &Vector3<f64>| -> Option<KeyframePoint> {
                let c = t.inverse() * Point3::from(*x);
                if c.z < 1.0 {
                    return None;
                }
                let u = K.fx * c.x / c.z + K.cx;
                let v = K.fy * c.y / c.z + K.cy;
                ((0.0..IMAGE.width).contains(&u) && (0.0..IMAGE.height).contains(&v))
                    .then_some(KeyframePoint { id, camera_point: c.coords, observation: [u, v, u - K.fx * B / c.z] })
            };
            let mut points: Vec<KeyframePoint> = self
                .field
                .iter()
                .enumerate()
                .filter_map(|(id, x)| observe(id as u64, x))
                // the cars hide the field behind them
                .filter(|p| {
                    !boxes.iter().any(|(b, depth)| {
                        p.camera_point.z > depth - 1.0 && b.contains_point(p.observation[0], p.observation[1])
                    })
                })
                .collect();
            // texture: the parked car's side facing the road, the moving cars' rears
            for k in 0..30 {
                let x = Vector3::new(4.15, 0.5 + 0.03 * (k % 10) as f64, 28.6 + 0.1 * k as f64);
                points.extend(observe(10_000 + k, &x));
            }
            for (n, e) in [same_speed(frame), half_speed(frame)].iter().enumerate() {
                let m = e.centre();
                for k in 0..20u64 {
                    let x = Vector3::new(m.x - 0.5 + 0.05 * k as f64, 0.5 + 0.03 * (k % 10) as f64, m.z - 1.9);
                    points.extend(observe(100_000 * (n as u64 + 1) + 100 * frame as u64 + k, &x));
                }
            }
            let id = self.next_kf;
            self.next_kf += 1;
            let parent = self.reference.map(|(rid, rp)| (rid, rp.inverse() * t));
            KeyframeData { id, frame, world_from_camera: t, parent, points, earlier: vec![] }
        });
        let relative = ref_pose.inverse() * t;
        if let Some(kf) = &keyframe {
            self.reference = Some((kf.id, t));
        }
        Ok(TrackedFrame {
            world_from_camera: t,
            reference: (ref_id, if frame == 0 { Isometry3::identity() } else { relative }),
            state: if frame == 0 { TrackState::Initialised } else { TrackState::Tracked { inliers: 100 } },
            stereo_points: 100,
            tracked_map_points: 100,
            reprojection_rms_px: 0.5,
            keyframe,
            times: StageTimes::default(),
        })
    }

    fn correct(&mut self, _: &KeyframeCorrection) {}

    fn flow(&mut self, _: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        Ok(Vec::new())
    }
}

/// Exact boxes of the three cars.
struct Boxes;

impl DetectionSource for Boxes {
    fn name(&self) -> &str {
        "scripted"
    }
    fn needs_image(&self) -> bool {
        false
    }
    fn detect(&mut self, frame: usize, _: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
        let cam = Camera::new(K, pose(frame));
        Ok(cars(frame)
            .iter()
            .filter_map(|e| project(e, &cam).and_then(|c| c.clipped_bounds(&IMAGE)).ok())
            .filter(|b| b.width() > 4.0)
            .map(|b| Detection::new(ClassId(2), 0.9, b))
            .collect())
    }
}

#[test]
fn cars_driving_ahead_are_found_moving_and_not_mapped() {
    let mut rng = slam_core::rng::SimRng::new(5);
    let field = (0..600)
        .map(|_| Vector3::new(rng.uniform(-20.0, 20.0), rng.uniform(-3.0, 1.5), rng.uniform(5.0, 90.0)))
        .collect();
    let tracker = Scripted { field, next_kf: 0, reference: None };
    let frames = Box::new((0..FRAMES).map(|i| FrameInput {
        index: i,
        images: Ok((Image::new(1, 1, 1, vec![0]).expect("image"), Image::new(1, 1, 1, vec![0]).expect("image"))),
    }));
    let mut config = SystemConfig::default();
    config.objects.image = IMAGE;
    let out = run(frames, Box::new(tracker), Some(Box::new(Boxes)), K, B, &config, lm(), &mut |_| {}).expect("runs");
    // which object took the boxes of which car: by the first detection's box
    let cam0 = Camera::new(K, pose(0));
    let box_of = |e: &Ellipsoid| project(e, &cam0).and_then(|c| c.clipped_bounds(&IMAGE)).expect("in view");
    let object_of = |e: &Ellipsoid| {
        let b = box_of(e);
        let k = out.frames[0].detections.iter().position(|d| d.bbox.iou(&b) > 0.9).expect("detected");
        out.frames[0].tracks[k].expect("associated")
    };
    let find = |e: &Ellipsoid| out.objects.iter().find(|o| o.id == object_of(e)).expect("object");
    for (name, e) in [("same speed", same_speed(0)), ("half speed", half_speed(0))] {
        let o = find(&e);
        assert!(o.moving && o.dynamic, "{name}: flagged moving ({o:?})");
    }
    let statics: Vec<&Ellipsoid> =
        out.objects.iter().filter(|o| !o.dynamic).filter_map(|o| o.ellipsoid.as_ref()).collect();
    assert_eq!(statics.len(), 1, "only the parked car is in the static map");
    assert!(metrics::e_trans(statics[0], &parked()) < 1.0, "{}", metrics::e_trans(statics[0], &parked()));
    // the saved map agrees
    assert!(out.map.objects.iter().filter(|o| !o.dynamic).count() == 1);
}

/// The optimiser of these tests (the project's Levenberg–Marquardt).
fn lm() -> slam_optim::SharedOptimizer {
    std::sync::Arc::new(slam_lm::LevenbergMarquardt::default())
}
