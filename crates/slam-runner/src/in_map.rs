//! What a run in a map loaded from an earlier run (`run --map`) reports: where its frames were placed
//! in the map, the errors of their poses in the map's frame against the ground truth, and the time it
//! took to place a frame against the time of a tracked one.

use nalgebra::Isometry3;
use slam_core::figure::median;
use slam_core::TrackState;
use slam_dataset::kitti::stereo::StereoSequence;
use slam_pipeline::{saved_map::pose_from_array, system::RunOutput};

use crate::run::{MapLoad, Outcome};

/// A loaded-map run's figures ([`in_map`]).
#[derive(Debug, Clone, PartialEq)]
pub struct InMap {
    /// Frames played and frames placed in the map.
    pub frames: usize,
    /// See `frames`.
    pub placed: usize,
    /// The id of the first frame placed, if any.
    pub first_placed: Option<usize>,
    /// Unaligned errors of the placed frames' positions against the ground truth expressed in the
    /// map's world ([`truth_in_map`]), metres: RMS and largest; `None` without such a ground truth or
    /// placed frames.
    pub errors: Option<(f64, f64)>,
    /// How the ground truth was expressed in the map's world, or why there is no figure.
    pub truth: Result<String, String>,
    /// Median tracker time (extraction, stereo matching, tracking) of the frames that tried to place
    /// themselves in the map (those not placed and the first placed one), and of frames tracked, ms.
    pub placing_ms: Option<f64>,
    /// See `placing_ms`.
    pub tracked_ms: Option<f64>,
    /// The frames that tried to place themselves.
    pub trying: usize,
}

/// The ground truth of a run's sequence expressed in a loaded map's world, one pose per played frame,
/// and how it was had; or why it cannot be. The map's world is the camera of its first frame: where
/// that camera lies in a ground truth is what the map records of the run that made it
/// (`ground_truth_world`); a map that records none is taken through this sequence's frame of the same
/// id (right when the sequence numbers its frames as the run that made the map did: the same drive,
/// not a layout renumbered). Its unaligned errors are meaningful only when the two ground truths share
/// a world (one drive's poses file).
pub fn truth_in_map(seq: &StereoSequence, load: &MapLoad) -> Result<(Vec<Isometry3<f64>>, String), String> {
    let gt = seq.ground_truth.as_ref().ok_or_else(|| "this sequence has no ground truth".to_string())?;
    let (origin, how) = match (&load.ground_truth_world, load.first_frame) {
        (Some(w), _) => (
            pose_from_array(&w.pose),
            format!("the ground truth expressed in the map's world, the camera of frame {} whose ground-truth pose the map records", w.frame),
        ),
        (None, Some(f)) => {
            let at = seq.ids.iter().position(|&id| id == f).and_then(|k| gt.get(k));
            let Some(pose) = at else {
                return Err(format!(
                    "the map does not record where its world (the camera of frame {f}) lies in a ground truth, and this \
                     sequence has no ground truth of a frame {f} to take it from"
                ));
            };
            (
                *pose,
                format!(
                    "the ground truth expressed in the map's world through this sequence's frame {f} (the map's first \
                     frame; the map records no ground truth, so this holds when the sequence numbers its frames as the \
                     run that made the map did)"
                ),
            )
        }
        (None, None) => return Err("the map has no keyframe".into()),
    };
    let to_map = origin.inverse();
    Ok((gt.iter().map(|g| to_map * g).collect(), how))
}

/// Unaligned position errors of a run's frames placed in the map whose ids pass `keep`, against
/// `truth` (one pose per played frame, in the frame of the run's poses; the frames named by `ids`): RMS
/// and largest, metres; `None` without such frames.
pub fn unaligned_errors(
    out: &RunOutput,
    truth: &[Isometry3<f64>],
    ids: &[usize],
    keep: impl Fn(usize) -> bool,
) -> Option<(f64, f64)> {
    let n = out.poses.len().min(truth.len()).min(ids.len());
    let e: Vec<f64> = (0..n)
        .filter(|&k| out.placed.get(k).copied().unwrap_or(true) && keep(ids[k]))
        .map(|k| (out.poses[k].translation.vector - truth[k].translation.vector).norm())
        .collect();
    (!e.is_empty()).then(|| {
        let rms = (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt();
        (rms, e.iter().copied().fold(0.0, f64::max))
    })
}

/// The figures of a run in a map loaded as `load`.
pub fn in_map(out: &RunOutput, seq: &StereoSequence, load: &MapLoad) -> InMap {
    let n = out.frames.len().min(out.placed.len()).min(out.poses.len());
    let placed: Vec<usize> = (0..n).filter(|&k| out.placed[k]).collect();
    let first = placed.first().copied();
    let truth = truth_in_map(seq, load);
    let errors = truth.as_ref().ok().and_then(|(t, _)| unaligned_errors(out, t, &seq.ids, |_| true));
    let frame_ms = |k: usize| {
        let t = &out.frames[k].times;
        t.extraction + t.stereo + t.tracking
    };
    let trying: Vec<usize> = (0..n).filter(|&k| !out.placed[k] || Some(k) == first).collect();
    let tracked: Vec<usize> =
        (0..n).filter(|&k| matches!(out.frames[k].state, Some(TrackState::Tracked { .. }))).collect();
    let med = |ks: &[usize]| median(&mut ks.iter().map(|&k| frame_ms(k)).collect::<Vec<_>>());
    InMap {
        frames: n,
        placed: placed.len(),
        first_placed: first.map(|k| seq.ids.get(k).copied().unwrap_or(k)),
        errors,
        truth: truth.map(|(_, how)| how),
        placing_ms: med(&trying),
        tracked_ms: med(&tracked),
        trying: trying.len(),
    }
}

impl Outcome {
    /// The lines a run in a loaded map prints (none for a run that started an empty map).
    pub(crate) fn map_lines(&self) -> Vec<String> {
        let Some(load) = &self.loaded else {
            return Vec::new();
        };
        let MapLoad { path, counts, seconds, reexpressed, localise_only, .. } = load;
        let m = in_map(&self.out, &self.seq, load);
        let mut lines = vec![format!(
            "\nloaded map {}: {} keyframes, {} points, {} objects in {seconds:.2} s{}{}",
            path.display(),
            counts.0,
            counts.1,
            counts.2,
            if *localise_only {
                "; localising only (nothing added, no detector run)"
            } else {
                "; extended by this run"
            },
            if *reexpressed { "; its keyframes re-expressed in this run's camera" } else { "" }
        )];
        lines.push(match m.first_placed {
            Some(f) => format!(
                "placed in the map: {} of {} frames, from frame {f}; {} frame(s) before it without a pose (left out of the trajectory files)",
                m.placed,
                m.frames,
                m.frames - m.placed
            ),
            None => format!("placed in the map: none of {} frames (no pose written: the trajectory files are empty)", m.frames),
        });
        if let (Some(p), Some(t)) = (m.placing_ms, m.tracked_ms) {
            lines.push(format!(
                "time to place a frame: {p:.1} ms median over the {} frame(s) that tried, {:.2}x a tracked frame's {t:.1} ms (a run's first frame also waits for its threads to start; track-bench times 51 placements)",
                m.trying,
                p / t
            ));
        }
        if self.out.counts.joined_segments > 0 {
            lines.push(format!(
                "a segment tracked beside the map from frame {} joined it where a frame of it was placed: its keyframes, points and frames moved into the map's frame",
                m.first_placed.map_or("?".into(), |f| f.to_string())
            ));
        }
        match (&m.truth, m.errors) {
            (Ok(how), Some((rms, max))) => lines.push(format!(
                "in the map's frame against {how} (unaligned): ATE {rms:.3} m RMS, largest {max:.3} m over {} placed frames",
                m.placed
            )),
            (Err(why), _) if m.placed > 0 => lines.push(format!("no error figure in the map's frame: {why}")),
            _ => {}
        }
        lines
    }
}
