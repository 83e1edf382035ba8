//! Pieces shared by the pipeline's integration tests: the KITTI-like camera ([`K`], [`B`], [`IMAGE`]),
//! cars as ellipsoids ([`car`]), the optimiser ([`lm`]), and a scripted scene for the threaded system:
//! a tracker with exact stereo observations ([`ScriptedTracker`]), exact detection boxes
//! ([`ScriptedBoxes`]) and blank frames ([`frames`]). No OpenCV.

#![allow(dead_code)] // each test file uses its own part

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use std::{collections::HashMap, sync::Arc};

use slam_core::{
    geometry::BBox,
    map::{Features, Keypoint},
    ClassId, DetectError, Detection, DetectionSource, FramePoint, Image, KeyframeId, KeyframePoint, Map, MovingRegion,
    NewKeyframe, ObjectInputs, ObjectMeasurements, PointId, PointPair, Sightings, StageTimes, StereoTracker,
    TrackError, TrackState, TrackedFrame,
};
use slam_pipeline::system::FrameInput;
use slam_quadric::{Camera, Ellipsoid, ImageSize, Intrinsics};

/// KITTI odometry 06's left camera.
pub const K: Intrinsics = Intrinsics { fx: 721.5377, fy: 721.5377, skew: 0.0, cx: 609.5593, cy: 172.854 };
/// Stereo baseline, metres.
pub const B: f64 = 0.54;
/// KITTI's image size.
pub const IMAGE: ImageSize = ImageSize::new(1242.0, 375.0);

/// A car-sized ellipsoid (4 × 1.56 × 1.7 m) on the road at `(x, z)`, its long axis along the road
/// turned by `yaw` radians.
pub fn car(x: f64, z: f64, yaw: f64) -> Ellipsoid {
    Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(x, 0.9, z),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -std::f64::consts::FRAC_PI_2 + yaw),
        ),
        Vector3::new(2.0, 0.78, 0.85),
    )
}

/// The box a detector draws around a box-shaped object: the bounds of the projected corners of the
/// ellipsoid's circumscribed cuboid (the mapper's default box model), clipped to the image; `None`
/// when a corner lies behind the camera or the box leaves the image.
pub fn detected_box(e: &Ellipsoid, cam: &Camera) -> Option<BBox> {
    slam_quadric::cuboid_bounds(e, cam)?.clipped(&IMAGE)
}

/// The optimiser of these tests (the project's Levenberg–Marquardt).
pub fn lm() -> slam_optim::SharedOptimizer {
    std::sync::Arc::new(slam_lm::LevenbergMarquardt::default())
}

/// `n` seeded static points around the road ahead (x ±20 m, y −3..1.5 m, z 5..90 m).
pub fn field(seed: u64, n: usize) -> Vec<Vector3<f64>> {
    let mut rng = slam_core::rng::SimRng::new(seed);
    (0..n).map(|_| Vector3::new(rng.uniform(-20.0, 20.0), rng.uniform(-3.0, 1.5), rng.uniform(5.0, 90.0))).collect()
}

/// What a scripted tracker sees.
pub struct Scene {
    /// True camera-to-world pose of frame `i` (the observations are made from it).
    pub truth: fn(usize) -> Isometry3<f64>,
    /// The pose the tracker reports for frame `i` (a drift when it differs from the truth).
    pub believed: fn(usize) -> Isometry3<f64>,
    /// The cars in frame `i`: they hide the field points behind them.
    pub cars: fn(usize) -> Vec<Ellipsoid>,
    /// Static points, ids `0..len`, hidden behind cars.
    pub field: Vec<Vector3<f64>>,
    /// Texture points on the cars in frame `i`, `(id, world point)`, never hidden.
    pub texture: fn(usize) -> Vec<(u64, Vector3<f64>)>,
}

/// A tracker that reports the scene's believed poses and makes a keyframe every third frame with exact
/// stereo observations (from the true pose) of the visible field points and the texture, each keypoint
/// matched to the map point its scene point became (learnt from the map once the keyframe is in).
pub struct ScriptedTracker {
    scene: Scene,
    /// `(keyframe id, its pose as the tracker believes it)`.
    reference: Option<(u64, Isometry3<f64>)>,
    /// The stereo points of the frame before and of the last frame (optical flow follows ids).
    seen: [Vec<KeyframePoint>; 2],
    /// The last keyframe handed over and the scene point of each of its keypoints.
    handed: Option<(KeyframeId, Vec<u64>)>,
    /// The map point each scene point became.
    map_id: HashMap<u64, PointId>,
}

impl ScriptedTracker {
    /// A tracker at the start of `scene`.
    pub fn new(scene: Scene) -> Self {
        Self { scene, reference: None, seen: [Vec::new(), Vec::new()], handed: None, map_id: HashMap::new() }
    }

    /// A scene point's descriptor: its id spread over 256 bits (distinct ids differ in many bits).
    fn descriptor(id: u64) -> [u8; 32] {
        let mut x = id.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x5851_F42D_4C95_7F2D;
        std::array::from_fn(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
    }

    /// The visible points of frame `frame` seen from `t`.
    fn observations(&self, frame: usize, t: Isometry3<f64>) -> Vec<KeyframePoint> {
        let cam = Camera::new(K, t);
        let cars: Vec<(BBox, f64)> = (self.scene.cars)(frame)
            .iter()
            .filter_map(|e| {
                let b = detected_box(e, &cam)?;
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
            ((0.0..IMAGE.width).contains(&u) && (0.0..IMAGE.height).contains(&v)).then_some(KeyframePoint {
                id,
                camera_point: c.coords,
                observation: [u, v, u - K.fx * B / c.z],
            })
        };
        let mut points: Vec<KeyframePoint> = self
            .scene
            .field
            .iter()
            .enumerate()
            .filter_map(|(id, x)| observe(id as u64, x))
            .filter(|p| {
                !cars.iter().any(|(b, depth)| {
                    p.camera_point.z > depth - 1.0 && b.contains_point(p.observation[0], p.observation[1])
                })
            })
            .collect();
        points.extend((self.scene.texture)(frame).iter().filter_map(|(id, x)| observe(*id, x)));
        points
    }
}

impl StereoTracker for ScriptedTracker {
    fn track(
        &mut self,
        frame: usize,
        _: &Image,
        _: &Image,
        exclude: &[MovingRegion],
        map: &Map,
    ) -> Result<TrackedFrame, TrackError> {
        // the map points the last keyframe's scene points became
        if let Some((id, scene_ids)) = self.handed.take() {
            if let Some(kf) = map.keyframe(id) {
                for (kp, &scene) in scene_ids.iter().enumerate() {
                    if let Some(p) = kf.points[kp] {
                        self.map_id.insert(scene, p);
                    }
                }
            }
        }
        let pose = (self.scene.believed)(frame);
        let (ref_id, ref_pose) = self.reference.unwrap_or((0, pose));
        let keyframe = (frame % 3 == 0).then(|| {
            let points = self.observations(frame, (self.scene.truth)(frame));
            let keypoints: Vec<Keypoint> = points
                .iter()
                .map(|p| Keypoint {
                    u: p.observation[0],
                    v: p.observation[1],
                    u_right: p.observation[2],
                    level: 0,
                    angle: 0.0,
                })
                .collect();
            let descriptors = points.iter().map(|p| Self::descriptor(p.id)).collect();
            let features = Features::new(keypoints, descriptors, (IMAGE.width, IMAGE.height)).expect("lengths");
            let matched =
                points.iter().map(|p| self.map_id.get(&p.id).copied().filter(|m| map.point(*m).is_some())).collect();
            let id = map.next_keyframe_id();
            self.handed = Some((id, points.iter().map(|p| p.id).collect()));
            NewKeyframe {
                id,
                frame,
                pose,
                parent: self.reference.map(|(rid, _)| rid),
                features: Arc::new(features),
                matched,
            }
        });
        let relative = ref_pose.inverse() * pose;
        if let Some(kf) = &keyframe {
            self.reference = Some((kf.id, pose));
        }
        let seen = self.observations(frame, (self.scene.truth)(frame));
        self.seen.swap(0, 1);
        self.seen[1] = seen.clone();
        Ok(TrackedFrame {
            world_from_camera: pose,
            reference: (ref_id, if frame == 0 { Isometry3::identity() } else { relative }),
            state: if frame == 0 { TrackState::Initialised } else { TrackState::Tracked { inliers: 100 } },
            stereo_points: 100,
            object_inputs: ObjectInputs {
                points: frame_points(&seen, exclude, false),
                masked_points: frame_points(&seen, exclude, true),
            },
            tracked_map_points: 100,
            reprojection_rms_px: 0.5,
            keyframe,
            sightings: Sightings::default(),
            times: StageTimes::default(),
            placed: true,
            segment: None,
            joined: None,
        })
    }
}

/// No optical flow of boxes and no dense stereo (the defaults); the scene flow is exact.
impl ObjectMeasurements for ScriptedTracker {
    /// Exact flow: the points of the frame before inside `regions` to the same ids in the last frame.
    fn stereo_flow(&mut self, regions: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        let [before, now] = &self.seen;
        Ok(before
            .iter()
            .filter(|p| regions.iter().any(|b| b.contains_point(p.observation[0], p.observation[1])))
            .filter_map(|p| {
                let q = now.iter().find(|q| q.id == p.id)?;
                Some(PointPair {
                    reference: [p.observation[0], p.observation[1]],
                    current: [q.observation[0], q.observation[1]],
                })
            })
            .collect())
    }
}

/// The points of `seen` on (`masked`) or off the moving regions `exclude`, as `StereoVo` splits them.
fn frame_points(seen: &[KeyframePoint], exclude: &[MovingRegion], masked: bool) -> Vec<FramePoint> {
    seen.iter()
        .filter(|p| {
            exclude.iter().any(|r| r.covers(p.observation[0], p.observation[1], Some(p.camera_point.z))) == masked
        })
        .map(|p| FramePoint { camera_point: p.camera_point, observation: p.observation })
        .collect()
}

/// Exact boxes (class car, score 0.9) of the scene's cars in the true cameras, those wider than 4 px.
pub struct ScriptedBoxes {
    /// True camera-to-world pose of frame `i`.
    pub truth: fn(usize) -> Isometry3<f64>,
    /// The cars in frame `i`.
    pub cars: fn(usize) -> Vec<Ellipsoid>,
}

impl DetectionSource for ScriptedBoxes {
    fn name(&self) -> &str {
        "scripted"
    }
    fn needs_image(&self) -> bool {
        false
    }
    fn detect(&mut self, frame: usize, _: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
        let cam = Camera::new(K, (self.truth)(frame));
        Ok((self.cars)(frame)
            .iter()
            .filter_map(|e| detected_box(e, &cam))
            .filter(|b| b.width() > 4.0)
            .map(|b| Detection::new(ClassId(2), 0.9, b))
            .collect())
    }
}

/// Frames `0..n` with blank 1 × 1 images; frame `unreadable`, if given, failed to load.
pub fn frames(n: usize, unreadable: Option<usize>) -> Box<dyn Iterator<Item = FrameInput> + Send> {
    Box::new((0..n).map(move |i| FrameInput {
        index: i,
        images: if Some(i) == unreadable {
            Err(format!("frame {i}: file missing"))
        } else {
            Ok((Image::new(1, 1, 1, vec![0]).expect("image"), Image::new(1, 1, 1, vec![0]).expect("image")))
        },
    }))
}
