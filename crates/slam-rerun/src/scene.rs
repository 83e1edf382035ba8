//! What a recording shows, as plain data and without rerun: the entity paths, one frame's content
//! ([`FrameScene`], made from a running system's [`FrameView`] or from a [`SavedMap`]), and the rules
//! that keep a recording's size proportional to the run's length (trajectory blocks, a bound on the map
//! points recorded per keyframe).

use std::collections::HashSet;

use nalgebra::{Isometry3, Matrix3, Rotation3, UnitQuaternion, Vector3};
use slam_core::{Image, KeyframeId, PointId, TrackId};
use slam_pipeline::{
    objects::MappedObject,
    saved_map::{SavedMap, SavedObject},
    system::FrameView,
};
use slam_quadric::{Camera, ImageSize, Intrinsics};
use slam_viz::{box_style, projected_object, ObjectState};

/// Entity paths of a recording (docs/system.md lists what each holds).
pub mod path {
    /// The world frame: the first camera's (x right, y down, z forward), so the 3-D view is
    /// right-down-forward.
    pub const WORLD: &str = "world";
    /// The left camera's pose, world from camera.
    pub const CAMERA: &str = "world/camera";
    /// The left camera's pinhole (the frustum in 3-D) and its image.
    pub const IMAGE: &str = "world/camera/image";
    /// Detection boxes on the image.
    pub const DETECTIONS: &str = "world/camera/image/detections";
    /// Projected ellipsoids on the image (outlines).
    pub const ELLIPSES: &str = "world/camera/image/ellipses";
    /// The estimated trajectory at tracking time, in blocks of [`super::TRAJECTORY_BLOCK`] frames:
    /// `world/trajectory/estimate/b000`, `…/b001`, ….
    pub const ESTIMATE: &str = "world/trajectory/estimate";
    /// The trajectory at the end of the run (local mapping's corrections applied), logged at the last frame.
    pub const FINAL: &str = "world/trajectory/final";
    /// The ground-truth trajectory (static), re-anchored at the first played frame.
    pub const TRUTH: &str = "world/trajectory/truth";
    /// Map points, one entity per keyframe: `world/points/kf00012`.
    pub const POINTS: &str = "world/points";
    /// The object map: ellipsoids with `#id class` labels, coloured by state.
    pub const OBJECTS: &str = "world/objects";
    /// The frame's tracking state as text (its level: INFO, WARN for predicted or unreadable, ERROR for lost).
    pub const STATE: &str = "tracking/state";
    /// The tracking state as a number ([`super::state_level`]).
    pub const LEVEL: &str = "tracking/level";
    /// Inliers of the frame's pose.
    pub const INLIERS: &str = "tracking/inliers";
    /// Map points tracked in the frame.
    pub const TRACKED_POINTS: &str = "tracking/map_points";
    /// RMS reprojection error of the tracked map points, pixels.
    pub const REPROJECTION: &str = "tracking/reprojection_rms_px";
    /// Wall time from the previous frame's end to this one's, milliseconds.
    pub const FRAME_MS: &str = "tracking/frame_ms";
    /// What the colours mean (static text).
    pub const LEGEND: &str = "legend";
}

/// The timeline of frame ids.
pub const FRAME_TIMELINE: &str = "frame";
/// The timeline of frame times, seconds from the sequence's start.
pub const TIME_TIMELINE: &str = "time";

/// Frames per trajectory block. Each frame re-logs the strip of its block, so a frame costs at most
/// this many positions (12 bytes each) whatever the run's length, and a run of `n` frames makes
/// `n / 100` entities under [`path::ESTIMATE`]; a single strip re-logged every frame would grow the
/// recording with the square of the run's length.
pub const TRAJECTORY_BLOCK: usize = 100;

/// Most map points recorded per keyframe. A point is 12 bytes in the recording, so a keyframe's points
/// stay below the size of one image (a 1242 × 375 JPEG is about 60-100 KB) whatever the front end's
/// feature count; at KITTI's 10 Hz our front end adds about 500 new points per keyframe (11,051 points
/// over 21 keyframes on the shipped sequence), all of which fit.
pub const MAX_POINTS_PER_KEYFRAME: usize = 1000;

/// JPEG quality of the recorded images: 1242 × 375 grey KITTI frames come out at about 60-90 KB.
pub const JPEG_QUALITY: u8 = 80;

/// What a recording of a run needs besides the frames: the camera, the frame times and the ground truth.
#[derive(Debug, Clone)]
pub struct SceneSetup {
    /// Left-camera intrinsics.
    pub k: Intrinsics,
    /// Image size.
    pub image: ImageSize,
    /// Frame id and time (seconds) of each played frame.
    pub times: Vec<(usize, f64)>,
    /// Ground truth of the played frames, re-anchored at the first (world from camera).
    pub truth: Option<Vec<Isometry3<f64>>>,
}

impl SceneSetup {
    /// The time of frame `id`, if known.
    pub fn time_of(&self, id: usize) -> Option<f64> {
        self.times.iter().find(|(i, _)| *i == id).map(|(_, t)| *t)
    }
}

/// A detection box as recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxShape {
    /// Top-left corner, pixels.
    pub min: [f32; 2],
    /// Width and height, pixels.
    pub size: [f32; 2],
    /// RGB ([`box_colour`]).
    pub colour: [u8; 3],
    /// `#id class score`, or `class score` for a box given to no object ([`slam_viz::box_style`]).
    pub label: String,
    /// Its object (track), if any.
    pub track: Option<u64>,
}

/// A projected ellipsoid as recorded: a closed outline (its first point repeated at the end).
#[derive(Debug, Clone, PartialEq)]
pub struct Outline {
    /// Points, pixels.
    pub points: Vec<[f32; 2]>,
    /// RGB: the object's state colour.
    pub colour: [u8; 3],
    /// `#id class` (` dynamic` appended).
    pub label: String,
}

/// An object's ellipsoid as recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectShape {
    /// The object's id (its track's).
    pub id: u64,
    /// COCO class index.
    pub class: u16,
    /// `#id class`, with ` dynamic` or ` moving` appended.
    pub label: String,
    /// Centre, world frame, metres.
    pub centre: [f64; 3],
    /// Semi-axes along the object's x, y, z, metres.
    pub half_sizes: [f64; 3],
    /// Orientation, world from object, as a unit quaternion `[x, y, z, w]`.
    pub quaternion: [f64; 4],
    /// Its state (colour).
    pub state: ObjectState,
}

impl ObjectShape {
    fn new(
        id: u64,
        class: u16,
        class_name: &str,
        centre: [f64; 3],
        half_sizes: [f64; 3],
        rotation: Matrix3<f64>,
        state: ObjectState,
    ) -> Self {
        let tail = match state {
            ObjectState::Static => "",
            ObjectState::Dynamic => " dynamic",
            ObjectState::Moving => " moving",
        };
        // a fitted rotation is orthonormal to rounding; this finds the nearest rotation in any case
        let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&rotation));
        Self {
            id,
            class,
            label: format!("#{id} {class_name}{tail}"),
            centre,
            half_sizes,
            quaternion: [q.i, q.j, q.k, q.w],
            state,
        }
    }

    /// A running system's object, once it has an ellipsoid (as `objects.json` lists it).
    pub fn of_mapped(o: &MappedObject) -> Option<Self> {
        let e = o.ellipsoid.as_ref()?;
        let c = e.centre();
        Some(Self::new(
            o.id.0,
            o.class.0,
            o.class.name(),
            [c.x, c.y, c.z],
            [e.semi_axes.x, e.semi_axes.y, e.semi_axes.z],
            e.rotation(),
            ObjectState::of(o.dynamic, o.moving),
        ))
    }

    /// A saved map's object.
    pub fn of_map(o: &SavedObject) -> Self {
        Self::new(
            o.id,
            o.class,
            &o.class_name,
            o.center,
            o.semi_axes,
            Matrix3::from_row_slice(&o.rotation),
            ObjectState::of(o.dynamic, o.moving),
        )
    }

    /// RGB.
    pub fn colour(&self) -> [u8; 3] {
        self.state.rgb()
    }
}

/// The grey of a box given to no object.
pub const UNMATCHED_GREY: [u8; 3] = [170, 170, 170];

/// The colour of a detection box: its object's state colour once the object has an ellipsoid or moves
/// (the overlays' legend); before that a light colour of its own per track, so that a track can be
/// followed from frame to frame before it is fitted; grey for a box given to no object.
pub fn box_colour(state: Option<ObjectState>, track: Option<TrackId>) -> [u8; 3] {
    match (state, track) {
        (Some(s), _) => s.rgb(),
        (None, Some(t)) => track_colour(t.0),
        (None, None) => UNMATCHED_GREY,
    }
}

/// A light colour per track id: hues a golden-ratio turn apart (neighbouring ids far apart on the
/// colour wheel), saturation 0.35 so that they stay apart from the saturated state colours.
pub fn track_colour(id: u64) -> [u8; 3] {
    let h = (id as f64 * 0.618_033_988_749_895).fract() * 6.0;
    let (s, v) = (0.35, 0.95);
    let f = h.fract();
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match h as u8 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [(r * 255.0).round() as u8, (g * 255.0).round() as u8, (b * 255.0).round() as u8]
}

/// A tracking state as a number, by how far its pose can be trusted: 5 tracked (or initialised), 4
/// relocalised, 3 weak, 2 predicted, 1 lost, 0 unreadable (names as in `tracking.csv`); `None` for a
/// name the map format does not use.
pub fn state_level(name: &str) -> Option<f64> {
    Some(match name {
        "tracked" | "initialised" => 5.0,
        "relocalised" => 4.0,
        "weak" => 3.0,
        "predicted" => 2.0,
        "lost" => 1.0,
        "unreadable" => 0.0,
        _ => return None,
    })
}

/// The log level of a tracking state's text: ERROR for a lost frame, WARN for a predicted or unreadable
/// one (no measured pose), INFO otherwise.
pub fn state_log_level(name: &str) -> &'static str {
    match name {
        "lost" => "ERROR",
        "predicted" | "unreadable" => "WARN",
        _ => "INFO",
    }
}

/// The map points already recorded, and the choice of the new ones a keyframe adds.
#[derive(Debug, Default)]
pub struct NewPoints {
    recorded: HashSet<PointId>,
}

impl NewPoints {
    /// The points of `points` not recorded before, at most [`MAX_POINTS_PER_KEYFRAME`] of them spread
    /// evenly over the new ones (every k-th, in the given order), as `f32`; marks them recorded.
    pub fn take(&mut self, points: impl IntoIterator<Item = (PointId, Vector3<f64>)>) -> Vec<[f32; 3]> {
        let fresh: Vec<(PointId, Vector3<f64>)> = points
            .into_iter()
            .filter(|(id, x)| !self.recorded.contains(id) && x.iter().all(|v| v.is_finite()))
            .collect();
        let step = fresh.len().div_ceil(MAX_POINTS_PER_KEYFRAME).max(1);
        fresh
            .iter()
            .step_by(step)
            .map(|(id, x)| {
                self.recorded.insert(*id);
                [x.x as f32, x.y as f32, x.z as f32]
            })
            .collect()
    }

    /// How many points have been recorded.
    pub fn count(&self) -> usize {
        self.recorded.len()
    }
}

/// The estimated trajectory cut into blocks of [`TRAJECTORY_BLOCK`] frames.
#[derive(Debug, Default)]
pub struct PathBlocks {
    block: usize,
    positions: Vec<[f32; 3]>,
    count: usize,
}

impl PathBlocks {
    /// Add the next position; returns its block's number and the block's strip so far (from the last
    /// position of the block before, so that the blocks join).
    pub fn push(&mut self, p: [f32; 3]) -> (usize, &[[f32; 3]]) {
        if self.count > 0 && self.count % TRAJECTORY_BLOCK == 0 {
            let last = self.positions.last().copied();
            self.positions.clear();
            self.positions.extend(last);
            self.block += 1;
        }
        self.positions.push(p);
        self.count += 1;
        (self.block, &self.positions)
    }
}

/// The entity of trajectory block `b`.
pub fn estimate_block(b: usize) -> String {
    format!("{}/b{b:03}", path::ESTIMATE)
}

/// The entity of keyframe `id`'s map points.
pub fn keyframe_points(id: KeyframeId) -> String {
    format!("{}/kf{id:05}", path::POINTS)
}

/// A frame's tracking figures.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameState {
    /// The state's name (`tracking.csv`'s).
    pub name: String,
    /// Inliers of the pose (none in a saved map).
    pub inliers: Option<usize>,
    /// Map points tracked (none in a saved map).
    pub tracked_map_points: Option<usize>,
    /// RMS reprojection error, pixels (none when not measured).
    pub reprojection_rms_px: Option<f64>,
    /// Wall time of the frame, milliseconds (none in a saved map).
    pub frame_ms: Option<f64>,
}

/// Everything one frame adds to a recording, owned (it goes to the writer's thread).
#[derive(Debug, Clone)]
pub struct FrameScene {
    /// Frame id.
    pub frame: usize,
    /// Frame time, seconds (none in a saved map).
    pub time_s: Option<f64>,
    /// Tracking state and figures.
    pub state: FrameState,
    /// Pose of the left camera, world from camera (none for an unreadable frame).
    pub pose: Option<Isometry3<f64>>,
    /// Whether the frame comes with the camera's view (a run's frames: image, boxes, projected
    /// ellipsoids; a saved map's have none).
    pub camera_view: bool,
    /// The left image (none in a saved map or for an unreadable frame).
    pub image: Option<Image>,
    /// Detection boxes.
    pub boxes: Vec<BoxShape>,
    /// Projected ellipsoids.
    pub outlines: Vec<Outline>,
    /// The objects with an ellipsoid as they stand at this frame.
    pub objects: Vec<ObjectShape>,
    /// New map points, per keyframe whose points arrived at this frame.
    pub points: Vec<(KeyframeId, Vec<[f32; 3]>)>,
}

impl FrameScene {
    /// A running system's frame ([`FrameView`]): boxes and projected ellipsoids as the overlays draw
    /// them (with [`box_colour`]), the objects as they stand, the map points of the keyframes whose
    /// local mapping reached the map just before this frame (new ones only, bounded).
    pub fn of_view(view: &FrameView<'_>, setup: &SceneSetup, recorded: &mut NewPoints) -> Self {
        let rec = view.record;
        let objects: Vec<&MappedObject> = view.objects.objects().collect();
        let boxes = rec
            .detections
            .iter()
            .zip(&rec.tracks)
            .map(|(d, t)| {
                let (state, label) = box_style(d, *t, &objects);
                let b = d.bbox;
                BoxShape {
                    min: [b.xmin as f32, b.ymin as f32],
                    size: [b.width() as f32, b.height() as f32],
                    colour: box_colour(state, *t),
                    label,
                    track: t.map(|t| t.0),
                }
            })
            .collect();
        let outlines = view
            .world_from_camera
            .map(|pose| {
                let camera = Camera::new(setup.k, pose);
                objects
                    .iter()
                    .filter_map(|o| projected_object(o, &camera, rec.index, setup.image))
                    .map(|p| {
                        let mut points: Vec<[f32; 2]> = p.outline.iter().map(|q| [q[0] as f32, q[1] as f32]).collect();
                        points.extend(points.first().copied());
                        Outline { points, colour: p.state.rgb(), label: p.label }
                    })
                    .collect()
            })
            .unwrap_or_default();
        let points = mapped_points(view.map, view.mapped, recorded);
        let name = rec.state.map_or("unreadable", |s| s.name());
        FrameScene {
            frame: rec.index,
            time_s: setup.time_of(rec.index),
            state: FrameState {
                name: name.to_string(),
                inliers: rec.state.map(|s| s.inliers()),
                tracked_map_points: Some(rec.tracked_map_points),
                reprojection_rms_px: rec.reprojection_rms_px.is_finite().then_some(rec.reprojection_rms_px),
                frame_ms: Some(rec.times.interval),
            },
            pose: view.world_from_camera,
            camera_view: true,
            image: view.left.cloned(),
            boxes,
            outlines,
            objects: objects.iter().filter_map(|o| ObjectShape::of_mapped(o)).collect(),
            points,
        }
    }

    /// The frames of a saved map, in trajectory order: each frame's final pose and state, the points
    /// of the keyframe made at that frame (new ones only, bounded) and the objects first seen by then
    /// (their final ellipsoids: a map keeps no history). No images, boxes or times.
    pub fn of_map(map: &SavedMap) -> impl Iterator<Item = FrameScene> + '_ {
        let poses = map.frame_poses();
        let mut recorded = NewPoints::default();
        let objects: Vec<(usize, ObjectShape)> =
            map.objects.iter().map(|o| (o.frames.iter().copied().min().unwrap_or(0), ObjectShape::of_map(o))).collect();
        map.trajectory.iter().zip(poses).map(move |(f, pose)| {
            let points = map
                .keyframes
                .iter()
                .filter(|(_, k)| k.frame == f.frame)
                .map(|(id, k)| {
                    let xs = k.observations.iter().filter_map(|(p, _)| map.point(*p).map(|x| (*p, x)));
                    (*id, recorded.take(xs))
                })
                .filter(|(_, xs)| !xs.is_empty())
                .collect();
            FrameScene {
                frame: f.frame,
                time_s: None,
                state: FrameState {
                    name: f.state.clone(),
                    inliers: None,
                    tracked_map_points: None,
                    reprojection_rms_px: None,
                    frame_ms: None,
                },
                pose,
                camera_view: false,
                image: None,
                boxes: Vec::new(),
                outlines: Vec::new(),
                objects: objects.iter().filter(|(first, _)| *first <= f.frame).map(|(_, o)| o.clone()).collect(),
                points,
            }
        })
    }
}

/// The new map points of each keyframe of `mapped` still in the map, bounded per keyframe (keyframes
/// without new points left out).
fn mapped_points(
    map: &slam_core::Map,
    mapped: &[KeyframeId],
    recorded: &mut NewPoints,
) -> Vec<(KeyframeId, Vec<[f32; 3]>)> {
    mapped
        .iter()
        .filter_map(|&id| map.keyframe(id).map(|k| (id, k)))
        .map(|(id, k)| {
            let xs = k.observations().filter_map(|(_, p)| map.position(p).map(|x| (p, x)));
            (id, recorded.take(xs))
        })
        .filter(|(_, xs)| !xs.is_empty())
        .collect()
}

/// A pose's position as `f32` (rerun's precision).
pub fn position(p: &Isometry3<f64>) -> [f32; 3] {
    let t = p.translation.vector;
    [t.x as f32, t.y as f32, t.z as f32]
}

/// A pose's rotation matrix as `f32` columns (rerun's matrices are column-major).
pub fn rotation_columns(p: &Isometry3<f64>) -> [[f32; 3]; 3] {
    let r = p.rotation.to_rotation_matrix();
    std::array::from_fn(|c| std::array::from_fn(|row| r[(row, c)] as f32))
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion};
    use slam_pipeline::saved_map::{pose_to_array, FramePose, SavedKeyframe, SavedMapPoint};

    use super::*;

    /// Blocks join (each starts at the last position of the one before) and no strip is longer than a
    /// block plus that joint, however long the path.
    #[test]
    fn trajectory_blocks_join_and_stay_short() {
        let mut blocks = PathBlocks::default();
        let mut seen = Vec::new();
        for i in 0..250 {
            let (b, strip) = blocks.push([i as f32, 0.0, 0.0]);
            assert!(strip.len() <= TRAJECTORY_BLOCK + 1, "frame {i}: {} positions", strip.len());
            assert_eq!(strip.last(), Some(&[i as f32, 0.0, 0.0]));
            seen.push((b, strip[0][0]));
        }
        assert_eq!(seen[99], (0, 0.0));
        assert_eq!(seen[100], (1, 99.0), "block 1 starts at block 0's last position");
        assert_eq!(seen[249], (2, 199.0));
        assert_eq!(estimate_block(2), "world/trajectory/estimate/b002");
    }

    /// A keyframe records at most the bound of new points, spread over them; points recorded before
    /// and non-finite ones are left out; the ones not chosen can come with a later keyframe.
    #[test]
    fn new_points_are_bounded_per_keyframe_and_recorded_once() {
        let points: Vec<(PointId, Vector3<f64>)> =
            (0..2500).map(|i| (i as PointId, Vector3::new(i as f64, 1.0, 2.0))).collect();
        let mut recorded = NewPoints::default();
        let first = recorded.take(points.iter().copied());
        assert!(first.len() <= MAX_POINTS_PER_KEYFRAME && first.len() > MAX_POINTS_PER_KEYFRAME / 2, "{}", first.len());
        assert_eq!(first[0], [0.0, 1.0, 2.0]);
        assert!(first[first.len() - 1][0] > 2400.0, "spread over all 2500, not the first 1000");
        let second = recorded.take(points.iter().copied());
        assert!(second.iter().all(|p| !first.contains(p)), "a recorded point is not recorded again");
        assert_eq!(recorded.count(), first.len() + second.len());
        let again = recorded.take(points.iter().copied().step_by(3));
        assert!(again.is_empty(), "every third point was taken first");
        let bad = recorded.take([(9999, Vector3::new(f64::NAN, 0.0, 0.0))]);
        assert!(bad.is_empty(), "a non-finite position is not recorded");
    }

    /// Box colours: the state's once an object is fitted or moves, a light colour per track before,
    /// grey for a box of no object; track colours differ between neighbouring ids and from the states'.
    #[test]
    fn boxes_are_coloured_by_state_then_by_track() {
        assert_eq!(box_colour(Some(ObjectState::Moving), Some(TrackId(4))), ObjectState::Moving.rgb());
        assert_eq!(box_colour(None, None), UNMATCHED_GREY);
        let colours: Vec<[u8; 3]> = (1..=8).map(|id| box_colour(None, Some(TrackId(id)))).collect();
        for (i, a) in colours.iter().enumerate() {
            for b in &colours[i + 1..] {
                let far = a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).max().unwrap_or(0);
                assert!(far >= 20, "{a:?} and {b:?} too close");
            }
            for s in ObjectState::ALL {
                assert_ne!(*a, s.rgb());
            }
            assert!(a.iter().all(|&c| c >= 150), "light: {a:?}");
        }
    }

    /// The state as a number orders the states by how far their pose can be trusted; lost is an error,
    /// predicted and unreadable warnings.
    #[test]
    fn tracking_states_have_levels() {
        let order = ["unreadable", "lost", "predicted", "weak", "relocalised", "tracked"];
        let levels: Vec<f64> = order.iter().filter_map(|s| state_level(s)).collect();
        assert_eq!(levels.len(), order.len());
        assert!(levels.windows(2).all(|w| w[0] < w[1]), "{levels:?}");
        assert_eq!(state_level("initialised"), state_level("tracked"));
        assert_eq!(state_level("flying"), None);
        assert_eq!(state_log_level("lost"), "ERROR");
        assert_eq!(state_log_level("unreadable"), "WARN");
        assert_eq!(state_log_level("weak"), "INFO");
    }

    /// A rotation reaches rerun as the quaternion and the columns of the same rotation.
    #[test]
    fn rotations_keep_their_axes() {
        let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        let pose = Isometry3::from_parts(Translation3::new(1.0, 2.0, 3.0), r);
        let cols = rotation_columns(&pose);
        let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
        assert!(close(cols[0], [0.0, 1.0, 0.0]), "x turns into y: {cols:?}");
        assert!(close(cols[1], [-1.0, 0.0, 0.0]), "{cols:?}");
        assert_eq!(position(&pose), [1.0, 2.0, 3.0]);
        let o = SavedObject {
            id: 7,
            class: 2,
            class_name: "car".into(),
            center: [1.0, 2.0, 3.0],
            semi_axes: [2.0, 0.8, 0.9],
            rotation: {
                let m = r.to_rotation_matrix();
                std::array::from_fn(|k| m[(k / 3, k % 3)])
            },
            frames: vec![3, 4],
            dynamic: true,
            moving: false,
            points: vec![],
            views: vec![],
            earlier_views: 0,
        };
        let shape = ObjectShape::of_map(&o);
        let [x, y, z, w] = shape.quaternion;
        let back = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        assert!(back.angle_to(&r) < 1e-9, "{:?}", shape.quaternion);
        assert_eq!(shape.label, "#7 car dynamic");
        assert_eq!(shape.colour(), ObjectState::Dynamic.rgb());
    }

    /// A saved map's frames: one per trajectory entry with its state and final pose, each keyframe's
    /// points at its frame, each object from the first frame it was seen in.
    #[test]
    fn a_saved_map_is_played_frame_by_frame() {
        let mut map = SavedMap::default();
        for (id, frame, z) in [(0u64, 0usize, 0.0), (1, 2, 2.0)] {
            let pose = Isometry3::translation(0.0, 0.0, z);
            let observations = (0..3).map(|k| (10 * id + k, [1.0, 2.0, 3.0])).collect();
            map.keyframes.insert(
                id,
                SavedKeyframe { frame, pose: pose_to_array(&pose), parent: None, observations, culled: false },
            );
            for k in 0..3 {
                map.points
                    .insert(10 * id + k, SavedMapPoint { position: [k as f64, 0.0, 10.0 + z], observed_by: vec![id] });
            }
        }
        for (frame, kf, state) in [(0, 0, "initialised"), (1, 0, "tracked"), (2, 1, "tracked"), (3, 1, "lost")] {
            let relative = pose_to_array(&Isometry3::translation(0.0, 0.0, if frame % 2 == 1 { 1.0 } else { 0.0 }));
            map.trajectory.push(FramePose { frame, keyframe: Some(kf), relative, state: state.into() });
        }
        map.objects.push(SavedObject {
            id: 3,
            class: 2,
            class_name: "car".into(),
            center: [1.0, 0.5, 12.0],
            semi_axes: [2.0, 0.8, 0.9],
            rotation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            frames: vec![2, 3],
            dynamic: false,
            moving: false,
            points: vec![],
            views: vec![],
            earlier_views: 0,
        });
        let frames: Vec<FrameScene> = FrameScene::of_map(&map).collect();
        assert_eq!(frames.iter().map(|f| f.frame).collect::<Vec<_>>(), [0, 1, 2, 3]);
        assert_eq!(frames[3].state.name, "lost");
        let z: Vec<f64> = frames.iter().map(|f| f.pose.map_or(f64::NAN, |p| p.translation.z)).collect();
        assert_eq!(z, [0.0, 1.0, 2.0, 3.0], "frame poses follow their keyframes");
        let points: Vec<(usize, KeyframeId, usize)> =
            frames.iter().flat_map(|f| f.points.iter().map(move |(id, xs)| (f.frame, *id, xs.len()))).collect();
        assert_eq!(points, [(0, 0, 3), (2, 1, 3)]);
        assert_eq!(frames.iter().map(|f| f.objects.len()).collect::<Vec<_>>(), [0, 0, 1, 1]);
        assert!(frames.iter().all(|f| !f.camera_view && f.image.is_none() && f.time_s.is_none()));
    }
}
