//! The system's worker threads: detection (ahead of tracking) and local mapping, with the messages
//! they exchange with the tracking thread. Local mapping never holds the live map (the tracking
//! thread owns it): it works on the snapshot of a keyframe's window it is sent and replies with the
//! snapshot's edits, which the tracking thread applies.

use std::time::Instant;

use crossbeam_channel::{Receiver, Sender};
use nalgebra::Vector3;
use slam_core::{DetectError, Detection, DetectionSource, Map};

use super::FrameInput;
use crate::{
    mapping::{LocalMapper, MappingJob, MappingReport},
    objects::{FitJob, FitResult},
    texture::{texture_planes, TextureConfig},
    yaw_cue::{point_yaw, PointYawConfig},
};

/// A frame after the detection thread: its input, its detections (or why there are none) and the
/// detector's times.
pub(crate) type Detected = (FrameInput, Result<Vec<Detection>, DetectError>, DetectTimes);

/// The detector's times on one frame, milliseconds.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct DetectTimes {
    /// The whole detection call.
    pub(crate) whole: f64,
    /// The network's forward passes within it (0 for a source that runs none).
    pub(crate) forward: f64,
}

/// Requests to the local-mapping thread.
pub enum MapperRequest {
    /// The work around a new keyframe and the object fits due at it.
    Keyframe(Box<MappingJob>, Vec<FitJob>),
    /// Stop.
    Finish,
}

/// The local-mapping thread's answer to a keyframe.
pub(crate) struct MapperReply {
    pub(crate) report: MappingReport,
    pub(crate) fits: Vec<FitResult>,
    pub(crate) fit_ms: f64,
}

/// The detection thread: runs `detector` on every `detect_every`-th frame of `frames` as they come
/// (the first, then every n-th: a count of frames, not of frame ids, so that a played subset with a
/// stride still gets boxes; an unreadable frame is not tracked, so it gets no boxes) and passes each
/// frame on with its boxes.
pub(crate) fn detection_thread(
    mut detector: Option<Box<dyn DetectionSource>>,
    detect_every: usize,
    frames: Receiver<FrameInput>,
    detected: Sender<Detected>,
) {
    let detect_every = detect_every.max(1);
    for (played, f) in frames.into_iter().enumerate() {
        let t = Instant::now();
        let mut forward = 0.0;
        let dets = match (&mut detector, &f.images) {
            (Some(d), Ok((left, _))) if played % detect_every == 0 => {
                let img = d.needs_image().then_some(left);
                let dets = d.detect(f.index, img);
                forward = d.forward_ms().unwrap_or(0.0);
                dets
            }
            _ => Ok(Vec::new()),
        };
        let times = DetectTimes { whole: t.elapsed().as_secs_f64() * 1e3, forward };
        if detected.send((f, dets, times)).is_err() {
            break;
        }
    }
}

/// The local-mapping thread: does the work around each keyframe on its snapshot ([`LocalMapper::process`]),
/// then runs the object fits due at it on the refined poses and points, and replies.
pub(crate) fn mapping_thread(
    mapper: LocalMapper,
    texture: TextureConfig,
    requests: Receiver<MapperRequest>,
    replies: Sender<MapperReply>,
) {
    for req in requests {
        match req {
            MapperRequest::Keyframe(job, mut jobs) => {
                let (report, snapshot) = mapper.process(*job);
                for job in &mut jobs {
                    job.repose(|k| snapshot.keyframe(k).map(|kf| kf.pose));
                }
                let t = Instant::now();
                let fits = jobs.iter().map(|job| run_fit(&snapshot, &texture, job)).collect();
                let reply = MapperReply { report, fits, fit_ms: t.elapsed().as_secs_f64() * 1e3 };
                if replies.send(reply).is_err() {
                    break;
                }
            }
            MapperRequest::Finish => break,
        }
    }
}

/// One object fit, with texture planes from the object's map points as seen by its latest view, and
/// the points' yaw cue ([`crate::yaw_cue`]) when it is confident.
fn run_fit(snapshot: &Map, texture: &TextureConfig, job: &FitJob) -> FitResult {
    // the snapshot's (adjusted) position where it holds the point, else the live map's when the job was made
    let points: Vec<Vector3<f64>> = job.positions.iter().map(|&(p, x)| snapshot.position(p).unwrap_or(x)).collect();
    let planes = match job.views.last() {
        Some(v) if job.uses_planes() => texture_planes(&points, &v.camera, texture),
        _ => Vec::new(),
    };
    let cue = match (job.views.first(), job.views.last()) {
        (Some(first), Some(last)) if job.uses_point_yaw() => {
            let (k, baseline) = (snapshot.camera().k, snapshot.camera().baseline);
            let up = first.camera.world_from_camera.rotation * Vector3::y();
            let camera = last.camera.world_from_camera.translation.vector;
            let prior = crate::objects::class_prior(job.class);
            let found = point_yaw(&points, &up, &camera, &prior, k.fx, baseline, &PointYawConfig::default());
            tracing::debug!(object = %job.id, ?found, "stereo-point yaw cue");
            found.cue()
        }
        _ => None,
    };
    job.run_with_cue(&planes, cue)
}
