//! The running system: the paper's threads, talking through `crossbeam-channel` messages.
//!
//! ```text
//!  reader ──frames──▶ detection ──frames+boxes──▶ tracking ──keyframes+fit jobs──▶ local mapping
//!                                                    ▲                                   │
//!                                                    └──── corrections + fitted objects ─┘
//! ```
//! - **reader**: decodes the stereo pairs (the caller's iterator) ahead of time.
//! - **detection**: runs the [`DetectionSource`] on every `detect_every`-th left image.
//! - **tracking** (the calling thread): the [`StereoTracker`], optical flow in the boxes, object
//!   association ([`ObjectMapper::associate`]), the moving-object test, and on keyframes the fit jobs.
//! - **local mapping**: the only owner of the [`Map`]: keyframe insertion, local bundle adjustment,
//!   culling, and the object fits (texture planes from the map points). The tracking thread reads the
//!   map only through the mapper's replies (keyframe corrections, fitted objects); `on_frame` observers
//!   get per-frame records, and the final map is handed over when the run ends. No locks are shared.
//!
//! Determinism: the tracker applies the mapper's reply for a keyframe made at the `k`-th input frame just
//! before it tracks the `(k + correction_lag)`-th (waiting for it if need be), never "whenever it
//! arrives", so a run gives the same output however the threads are scheduled.
//!
//! Frame identity: [`FrameInput::index`] is the frame's id in its sequence (the number in the file
//! names), not its position: records, the map's trajectory and keyframes, and the detector's `frame`
//! argument all carry that id, so a run over a subset or a sequence with gaps stays aligned with
//! ground truth, labels and detection files.

use std::{collections::VecDeque, time::Instant};

use crossbeam_channel::{bounded, unbounded, Receiver, Sender};
use nalgebra::{Isometry3, Point3, Vector3};
use slam_core::{
    geometry::{BBox, Camera, Intrinsics},
    ClassId, Detection, DetectionSource, Image, KeyframeCorrection, KeyframeData, StereoTracker, TrackId, TrackState,
};
use slam_optim::SharedOptimizer;

use crate::{
    map::{pose_to_array, FramePose, Map},
    mapping::{LocalMapper, MappingConfig},
    objects::{class_prior, suppress_duplicate_boxes, FitJob, FitResult, MappedObject, MapperConfig, ObjectMapper, PointsCentroid},
    texture::{texture_planes, TextureConfig},
};

/// The box misfit (RMS, pixels) that flags an object dynamic in the running system, where boxes come
/// from a detector: detector boxes are partial and jitter from frame to frame, so a parked car's fitted
/// ellipsoid misses them by 3 to 22 px RMS on KITTI odometry 06 (9 objects whose map points stayed put)
/// and up to about 25 px on raw drive 0005; the object mapper's own default (12 px) is for label-quality
/// boxes and flagged 5 of those 9 parked cars on 06 dynamic. Moving objects are caught by their map
/// points' motion in the running system (docs/system.md, "Settings").
pub const DETECTOR_DYNAMIC_RMS_PX: f64 = 25.0;

/// Settings of the system (its own keys are the `[system]` table of `slam-app run --config`; the stages'
/// settings are tables of their own there, `[mapping]`, `[objects]`, `[texture]`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, documented::DocumentedFieldsOpt)]
#[serde(default, deny_unknown_fields)]
pub struct SystemConfig {
    /// Local mapping.
    #[serde(skip)]
    pub mapping: MappingConfig,
    /// Object mapping. Default: the mapper's defaults with `dynamic_rms_px` at
    /// [`DETECTOR_DYNAMIC_RMS_PX`].
    #[serde(skip)]
    pub objects: MapperConfig,
    /// Texture planes.
    #[serde(skip)]
    pub texture: TextureConfig,
    /// Input frames between a keyframe and the application of the mapper's reply to it. Default 2.
    pub correction_lag: usize,
    /// Run the detector on frames whose id is a multiple of n (others get no boxes). Default 1.
    pub detect_every: usize,
    /// Keep keypoints of moving objects out of tracking. Default on.
    pub exclude_moving: bool,
    /// Map points inside the central part of a box (this fraction of its width and height) belong to
    /// the object. Default 0.6.
    pub object_core: f64,
    /// Standard deviation of a stereo disparity, pixels: the depth noise `σ_z = z² σ_d / (f b)` of the
    /// objects' points in the moving-object test. Default 0.5 (ORB keypoints from pyramid levels up
    /// to 1.2⁴ coarser, matched with sub-pixel refinement).
    pub disparity_sigma_px: f64,
    /// Suppress duplicate and part boxes (same class group, IoU above 0.45 or nested) before
    /// association. Default on.
    pub suppress_duplicates: bool,
    /// ODA gate: a detection is never given to an object whose projected ellipsoid overlaps it by less
    /// than this IoU. Default `Some(0.1)`; `None` (0 in a settings file) is the paper's cost alone.
    #[serde(with = "crate::settings::zero_is_off")]
    pub projected_gate: Option<f64>,
    /// Most detections kept per frame (the highest scores; the rest are dropped and counted). The busiest
    /// labelled frame of the KITTI tracking fixtures has 25 boxes; association cost grows with the cube of
    /// the count (1,000 boxes per frame once took 297 s for 51 frames). Default 100.
    pub max_detections: usize,
}

impl Default for SystemConfig {
    fn default() -> Self {
        Self {
            mapping: MappingConfig::default(),
            objects: MapperConfig { dynamic_rms_px: DETECTOR_DYNAMIC_RMS_PX, ..MapperConfig::default() },
            texture: TextureConfig::default(),
            correction_lag: 2,
            detect_every: 1,
            exclude_moving: true,
            object_core: 0.6,
            disparity_sigma_px: 0.5,
            suppress_duplicates: true,
            projected_gate: Some(0.1),
            max_detections: 100,
        }
    }
}

/// One input frame: its stereo pair, or why it could not be read.
#[derive(Debug)]
pub struct FrameInput {
    /// Frame id in the sequence (the number in the file names), increasing; not a position.
    pub index: usize,
    /// Left and right images, or the reason they are missing.
    pub images: Result<(Image, Image), String>,
}

/// What happened in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameRecord {
    /// Frame index.
    pub index: usize,
    /// Tracking state; `None` for an unreadable frame.
    pub state: Option<TrackState>,
    /// The frame became a keyframe.
    pub keyframe: bool,
    /// Map points tracked in the frame (0 when no pose was measured or the frame was unreadable).
    pub tracked_map_points: usize,
    /// RMS reprojection error of the tracked map points, pixels (NaN when none).
    pub reprojection_rms_px: f64,
    /// Detections used.
    pub detections: Vec<Detection>,
    /// Object of each detection.
    pub tracks: Vec<Option<TrackId>>,
    /// Stage times, milliseconds.
    pub times: FrameTimes,
}

/// Per-frame stage times, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameTimes {
    /// Wall time from the end of the previous frame's tracking to the end of this one's: the
    /// system's throughput, all threads included (the first frame: from the start of the run).
    pub interval: f64,
    /// Detection (its own thread).
    pub detection: f64,
    /// Feature extraction.
    pub extraction: f64,
    /// Stereo matching.
    pub stereo: f64,
    /// Frame tracking.
    pub tracking: f64,
    /// Optical flow for the association.
    pub flow: f64,
    /// Object association.
    pub association: f64,
    /// Local bundle adjustment (keyframes; mapping thread).
    pub bundle_adjustment: f64,
    /// Object initialisation and optimisation (keyframes; mapping thread).
    pub objects: f64,
}

/// Counts of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RunCounts {
    /// Frames.
    pub frames: usize,
    /// Keyframes.
    pub keyframes: usize,
    /// Frames whose images could not be read (pose held).
    pub unreadable: usize,
    /// Frames tracked with full support.
    pub tracked: usize,
    /// Frames tracked with less support (pose used, marked weak).
    pub weak: usize,
    /// Frames where tracking failed (the first frame of a failure; pose predicted).
    pub lost: usize,
    /// Frames after a lost one that were not recovered either (pose predicted).
    pub predicted: usize,
    /// Frames recovered by relocalisation.
    pub relocalised: usize,
    /// Map segments started after a failure (the first one not counted).
    pub new_segments: usize,
    /// Detection failures (counted and logged, the frame goes on without boxes).
    pub detector_errors: usize,
    /// Observations culled by local mapping.
    pub culled_observations: usize,
    /// Detector boxes suppressed as duplicates or parts of another box of the same class group.
    pub suppressed_boxes: usize,
}

/// Everything a run produced.
pub struct RunOutput {
    /// The map: keyframes, points, objects, per-frame trajectory.
    pub map: Map,
    /// Pose of every input frame (left camera, world from camera), following the refined keyframes.
    pub poses: Vec<Isometry3<f64>>,
    /// The objects with their observations.
    pub objects: Vec<MappedObject>,
    /// Per-frame records.
    pub frames: Vec<FrameRecord>,
    /// Counts.
    pub counts: RunCounts,
}

/// Requests to the local-mapping thread.
pub enum MapperRequest {
    /// A new keyframe and the object fits due at it.
    Keyframe(Box<KeyframeData>, Vec<FitJob>),
    /// Stop and hand the map over.
    Finish,
}

struct MapperReply {
    correction: KeyframeCorrection,
    fits: Vec<FitResult>,
    ba_ms: f64,
    fit_ms: f64,
    culled: usize,
}

/// Failures of the system itself (not of the data: bad frames are counted and logged).
#[derive(Debug, thiserror::Error)]
pub enum SystemError {
    /// The tracker failed in a way it could not turn into a lost frame.
    #[error("frame {frame}: {message}")]
    Tracker {
        /// Frame index.
        frame: usize,
        /// The tracker's message.
        message: String,
    },
    /// A thread stopped unexpectedly.
    #[error("the {0} thread stopped unexpectedly")]
    Thread(&'static str),
}

fn mapping_thread(
    mut mapper: LocalMapper,
    texture: TextureConfig,
    requests: Receiver<MapperRequest>,
    replies: Sender<MapperReply>,
) -> Map {
    for req in requests {
        match req {
            MapperRequest::Keyframe(kf, mut jobs) => {
                let report = mapper.insert_keyframe(&kf);
                for job in &mut jobs {
                    job.repose(|k| mapper.keyframe_pose(k));
                }
                let t = Instant::now();
                let fits = jobs
                    .iter()
                    .map(|job| {
                        // texture planes from the map points as seen by the latest view
                        let planes = match job.views.last() {
                            Some(v) if job.uses_planes() => {
                                let points: Vec<Vector3<f64>> =
                                    job.points.iter().filter_map(|p| mapper.map().point(*p)).collect();
                                texture_planes(&points, &v.camera, &texture)
                            }
                            _ => Vec::new(),
                        };
                        job.run(&planes)
                    })
                    .collect();
                let reply = MapperReply {
                    correction: report.correction,
                    fits,
                    ba_ms: report.ba_ms,
                    fit_ms: t.elapsed().as_secs_f64() * 1e3,
                    culled: report.culled_observations,
                };
                if replies.send(reply).is_err() {
                    break;
                }
            }
            MapperRequest::Finish => break,
        }
    }
    mapper.into_map()
}

/// Fewest map points in a box for its centroid to count.
const MIN_OBJECT_POINTS: usize = 5;

/// Heights an object of a class group can have, metres: vehicles from a low car to a lorry (1.2–4.5),
/// people and riders 0.9–2.1, anything else 0.3–5.
fn height_range(class: ClassId) -> (f64, f64) {
    match class.0 {
        2 | 5 | 7 => (1.2, 4.5),
        0 | 1 | 3 => (0.9, 2.1),
        _ => (0.3, 5.0),
    }
}

/// The stereo points of a keyframe that lie on the object of a box, and where they put it.
///
/// Candidates: points inside the central part of the box (`core` of its width and height) whose depth
/// fits the box height for some height the class can have (no near limit for a box cut by the image
/// border: its height understates the object's). Among them the object is the densest depth cluster:
/// windows `[z, z + 2w]` with `w = max(a, 2 σ_z(z))`, `a` the class's half-length (a car seen obliquely
/// spans its length in depth) and `σ_z = z² σ_d / (f b)` the stereo depth noise; the object is the
/// nearest window holding at least half as many points as the densest one (it hides what lies behind
/// it). The centroid is
/// the points' median world position (`None` below [`MIN_OBJECT_POINTS`] points).
#[allow(clippy::too_many_arguments)]
fn object_points(
    kf: &KeyframeData,
    b: &BBox,
    core: f64,
    class: ClassId,
    k: &Intrinsics,
    baseline: f64,
    disparity_sigma: f64,
    image: &slam_core::geometry::ImageSize,
) -> (Vec<u64>, Option<PointsCentroid>) {
    let (cx, cy) = (0.5 * (b.xmin + b.xmax), 0.5 * (b.ymin + b.ymax));
    let (hw, hh) = (0.5 * core * (b.xmax - b.xmin), 0.5 * core * (b.ymax - b.ymin));
    let (hmin, hmax) = height_range(class);
    let bh = b.height().max(1.0);
    let cut = b.touches_border(image, 2.0);
    let (near, far) = (if cut { 0.0 } else { k.fy * hmin / bh }, k.fy * hmax / bh);
    let mut cand: Vec<&slam_core::KeyframePoint> = kf
        .points
        .iter()
        .filter(|p| (p.observation[0] - cx).abs() <= hw && (p.observation[1] - cy).abs() <= hh)
        .filter(|p| p.camera_point.z > 0.0 && (near..=far).contains(&p.camera_point.z))
        .collect();
    cand.sort_by(|a, b| a.camera_point.z.total_cmp(&b.camera_point.z).then(a.id.cmp(&b.id)));
    let sigma_z = |z: f64| z * z * disparity_sigma / (k.fx * baseline);
    let half_length = class_prior(class).axes.x;
    let windows: Vec<usize> = (0..cand.len())
        .map(|i| {
            let z0 = cand[i].camera_point.z;
            let top = z0 + 2.0 * half_length.max(2.0 * sigma_z(z0));
            cand[i..].iter().take_while(|p| p.camera_point.z <= top).count()
        })
        .collect();
    // the nearest window holding at least half as many points as the densest one: the object hides
    // what lies behind it, and a textured facade behind a plain car can outnumber the car's points
    let densest = windows.iter().copied().max().unwrap_or(0);
    let best = windows
        .iter()
        .position(|&n| n >= MIN_OBJECT_POINTS && 2 * n >= densest)
        .map_or((0, 0), |i| (windows[i], i));
    let kept: Vec<(u64, Vector3<f64>, f64)> = cand[best.1..best.1 + best.0]
        .iter()
        .map(|p| (p.id, (kf.world_from_camera * Point3::from(p.camera_point)).coords, p.camera_point.z))
        .collect();
    let median = |mut v: Vec<f64>| {
        v.sort_by(|a, b| a.total_cmp(b));
        v[v.len() / 2]
    };
    // a centroid needs a few points: one stray point of the background would fake a motion
    let centroid = (kept.len() >= MIN_OBJECT_POINTS).then(|| {
        let m = |k: usize| median(kept.iter().map(|p| p.1[k]).collect());
        PointsCentroid {
            position: Vector3::new(m(0), m(1), m(2)),
            depth_sigma: sigma_z(median(kept.iter().map(|p| p.2).collect())),
        }
    });
    (kept.iter().map(|p| p.0).collect(), centroid)
}

/// Run the whole system over `frames`.
///
/// `detector` is `None` for a run without objects. `optimizer` solves the local bundle adjustments and
/// the object fits. `on_frame` sees each frame's record as soon as it is tracked (progress output).
pub fn run(
    frames: Box<dyn Iterator<Item = FrameInput> + Send>,
    mut tracker: Box<dyn StereoTracker>,
    detector: Option<Box<dyn DetectionSource>>,
    intrinsics: Intrinsics,
    baseline: f64,
    config: &SystemConfig,
    optimizer: SharedOptimizer,
    on_frame: &mut dyn FnMut(&FrameRecord),
) -> Result<RunOutput, SystemError> {
    let config = *config;
    std::thread::scope(|scope| {
        // reader → detection
        let (frame_tx, frame_rx) = bounded::<FrameInput>(4);
        scope.spawn(move || {
            for f in frames {
                if frame_tx.send(f).is_err() {
                    break;
                }
            }
        });
        // detection → tracking
        type Detected = (FrameInput, Result<Vec<Detection>, String>, f64);
        let (det_tx, det_rx) = bounded::<Detected>(4);
        let detect_every = config.detect_every.max(1);
        scope.spawn(move || {
            let mut detector = detector;
            for f in frame_rx {
                let t = Instant::now();
                // an unreadable frame is not tracked, so its boxes would go unused
                let dets = match (&mut detector, &f.images) {
                    (Some(d), Ok((left, _))) if f.index % detect_every == 0 => {
                        let img = d.needs_image().then_some(left);
                        d.detect(f.index, img).map_err(|e| e.to_string())
                    }
                    _ => Ok(Vec::new()),
                };
                let ms = t.elapsed().as_secs_f64() * 1e3;
                if det_tx.send((f, dets, ms)).is_err() {
                    break;
                }
            }
        });
        // local mapping
        let (req_tx, req_rx) = unbounded::<MapperRequest>();
        let (reply_tx, reply_rx) = unbounded::<MapperReply>();
        let mapper = LocalMapper::new(intrinsics, baseline, config.mapping, optimizer.clone());
        let texture = config.texture;
        let mapping = scope.spawn(move || mapping_thread(mapper, texture, req_rx, reply_tx));

        // tracking, on this thread
        let oda = slam_assoc::Oda::new(slam_assoc::OdaConfig {
            min_projected_iou: config.projected_gate,
            ..slam_assoc::OdaConfig::default()
        });
        // with stereo points, an ellipsoid must agree with them
        let mut objects =
            ObjectMapper::new(Box::new(oda), MapperConfig { stereo_evidence: true, ..config.objects }, optimizer);
        let mut records: Vec<FrameRecord> = Vec::new();
        let mut trajectory: Vec<FramePose> = Vec::new();
        let mut counts = RunCounts::default();
        let mut pending: VecDeque<(usize, usize)> = VecDeque::new(); // (keyframe frame, record index)
        let mut last_reference: Option<(u64, Isometry3<f64>)> = None;
        let mut prev_boxes: Vec<BBox> = Vec::new();
        let mut moving_boxes: Vec<BBox> = Vec::new();
        let apply = |reply: MapperReply,
                     tracker: &mut Box<dyn StereoTracker>,
                     objects: &mut ObjectMapper,
                     record: Option<&mut FrameRecord>,
                     counts: &mut RunCounts| {
            tracker.correct(&reply.correction);
            for fit in reply.fits {
                objects.apply(fit);
            }
            counts.culled_observations += reply.culled;
            if let Some(r) = record {
                r.times.bundle_adjustment = reply.ba_ms;
                r.times.objects = reply.fit_ms;
            }
        };
        let mut last_done = Instant::now();
        for (input, dets, det_ms) in det_rx {
            let i = input.index;
            while let Some(&(_, rec)) = pending.front() {
                // counted in played frames (records), not frame ids: with a stride or gaps in the ids the
                // lag stays the same number of tracked frames
                if rec + config.correction_lag > records.len() {
                    break;
                }
                let reply = reply_rx.recv().map_err(|_| SystemError::Thread("local mapping"))?;
                apply(reply, &mut tracker, &mut objects, records.get_mut(rec), &mut counts);
                pending.pop_front();
            }
            counts.frames += 1;
            let detections = match dets {
                Ok(d) if config.suppress_duplicates => {
                    let (kept, dropped) = suppress_duplicate_boxes(d);
                    counts.suppressed_boxes += dropped;
                    kept
                }
                Ok(d) => d,
                Err(e) => {
                    counts.detector_errors += 1;
                    tracing::warn!(frame = i, "detector failed: {e}; frame has no boxes");
                    Vec::new()
                }
            };
            let mut times = FrameTimes { detection: det_ms, ..FrameTimes::default() };
            let (left, right) = match input.images {
                Ok(pair) => pair,
                Err(why) => {
                    counts.unreadable += 1;
                    tracing::warn!(frame = i, "unreadable: {why}; pose held");
                    let (kf, rel) = last_reference.unwrap_or((0, Isometry3::identity()));
                    trajectory.push(FramePose {
                        frame: i,
                        keyframe: kf,
                        relative: pose_to_array(&rel),
                        state: "unreadable".into(),
                    });
                    let record = FrameRecord {
                        index: i,
                        state: None,
                        keyframe: false,
                        tracked_map_points: 0,
                        reprojection_rms_px: f64::NAN,
                        detections: Vec::new(),
                        tracks: Vec::new(),
                        times,
                    };
                    on_frame(&record);
                    records.push(record);
                    prev_boxes.clear();
                    continue;
                }
            };
            let exclude: &[BBox] = if config.exclude_moving { &moving_boxes } else { &[] };
            let tf = tracker
                .track(i, &left, &right, exclude)
                .map_err(|e| SystemError::Tracker { frame: i, message: e.to_string() })?;
            times.extraction = tf.times.extraction;
            times.stereo = tf.times.stereo;
            times.tracking = tf.times.tracking;
            match tf.state {
                TrackState::Initialised => {}
                TrackState::Tracked { .. } => counts.tracked += 1,
                TrackState::Weak { .. } => counts.weak += 1,
                TrackState::Lost => {
                    counts.lost += 1;
                    tracing::warn!(frame = i, stereo_points = tf.stereo_points, "tracking lost");
                }
                TrackState::Predicted => counts.predicted += 1,
                TrackState::Relocalised { .. } => counts.relocalised += 1,
            }
            let t = Instant::now();
            let flow = if prev_boxes.is_empty() {
                Vec::new()
            } else {
                tracker.flow(&prev_boxes).unwrap_or_else(|e| {
                    tracing::debug!(frame = i, "optical flow failed: {e}");
                    Vec::new()
                })
            };
            times.flow = t.elapsed().as_secs_f64() * 1e3;
            let t = Instant::now();
            let camera = Camera::new(intrinsics, tf.world_from_camera);
            let tracks = objects.associate(i, &camera, Some(tf.reference), &detections, &flow);
            if let Some(kf) = &tf.keyframe {
                if kf.parent.is_none() && kf.id > 0 {
                    counts.new_segments += 1;
                }
                for (d, t) in detections.iter().zip(&tracks) {
                    if let Some(id) = t {
                        let (pts, centroid) = object_points(
                            kf,
                            &d.bbox,
                            config.object_core,
                            d.class,
                            &intrinsics,
                            baseline,
                            config.disparity_sigma_px,
                            &config.objects.image,
                        );
                        objects.add_points(*id, &pts, centroid);
                    }
                }
            }
            moving_boxes = detections
                .iter()
                .zip(&tracks)
                .filter(|(_, t)| t.and_then(|id| objects.object(id)).is_some_and(|o| o.moving))
                .map(|(d, _)| {
                    let b = d.bbox;
                    let (mx, my) = (0.1 * (b.xmax - b.xmin), 0.1 * (b.ymax - b.ymin));
                    BBox::new(b.xmin - mx, b.ymin - my, b.xmax + mx, b.ymax + my)
                })
                .collect();
            prev_boxes = detections.iter().map(|d| d.bbox).collect();
            times.association = t.elapsed().as_secs_f64() * 1e3;
            last_reference = Some(tf.reference);
            trajectory.push(FramePose {
                frame: i,
                keyframe: tf.reference.0,
                relative: pose_to_array(&tf.reference.1),
                state: tf.state.name().into(),
            });
            let is_kf = tf.keyframe.is_some();
            if let Some(kf) = tf.keyframe {
                counts.keyframes += 1;
                let jobs = objects.fit_jobs();
                req_tx
                    .send(MapperRequest::Keyframe(Box::new(kf), jobs))
                    .map_err(|_| SystemError::Thread("local mapping"))?;
                pending.push_back((i, records.len()));
            }
            times.interval = last_done.elapsed().as_secs_f64() * 1e3;
            last_done = Instant::now();
            let record = FrameRecord {
                index: i,
                state: Some(tf.state),
                keyframe: is_kf,
                tracked_map_points: tf.tracked_map_points,
                reprojection_rms_px: tf.reprojection_rms_px,
                detections,
                tracks,
                times,
            };
            on_frame(&record);
            records.push(record);
        }
        while let Some((_, rec)) = pending.pop_front() {
            let reply = reply_rx.recv().map_err(|_| SystemError::Thread("local mapping"))?;
            apply(reply, &mut tracker, &mut objects, records.get_mut(rec), &mut counts);
        }
        let _ = req_tx.send(MapperRequest::Finish);
        let mut map = mapping.join().map_err(|_| SystemError::Thread("local mapping"))?;
        map.trajectory = trajectory;
        map.objects = objects.objects().filter_map(MappedObject::to_map_object).collect();
        let poses = map.frame_poses().into_iter().map(|p| p.unwrap_or_else(Isometry3::identity)).collect();
        Ok(RunOutput { map, poses, objects: objects.objects().cloned().collect(), frames: records, counts })
    })
}
