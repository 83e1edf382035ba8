//! What a run in a map loaded from an earlier run (`run --map`) reports: where its frames were placed
//! in the map, the errors of their poses in the map's frame against the ground truth, and the time it
//! took to place a frame against the time of a tracked one.

use slam_core::TrackState;
use slam_dataset::kitti::stereo::StereoSequence;
use slam_pipeline::{report::median, system::RunOutput};

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
    /// Unaligned errors of the placed frames' positions against the ground truth as given (its world
    /// is the camera of the sequence's frame 0: the map's world when the map was made from that frame
    /// of the same drive), metres: RMS and largest; `None` without ground truth or placed frames.
    pub errors: Option<(f64, f64)>,
    /// Median tracker time (extraction, stereo matching, tracking) of the frames that tried to place
    /// themselves in the map (those not placed and the first placed one), and of frames tracked, ms.
    pub placing_ms: Option<f64>,
    /// See `placing_ms`.
    pub tracked_ms: Option<f64>,
    /// The frames that tried to place themselves.
    pub trying: usize,
}

/// Unaligned position errors of a run's frames placed in the map whose ids pass `keep`, against the
/// ground truth as given (its world is the camera of the sequence's frame 0): RMS and largest,
/// metres; `None` without ground truth or such frames.
pub fn unaligned_errors(out: &RunOutput, seq: &StereoSequence, keep: impl Fn(usize) -> bool) -> Option<(f64, f64)> {
    let gt = seq.ground_truth.as_ref()?;
    let n = out.poses.len().min(gt.len()).min(seq.ids.len());
    let e: Vec<f64> = (0..n)
        .filter(|&k| out.placed.get(k).copied().unwrap_or(true) && keep(seq.ids[k]))
        .map(|k| (out.poses[k].translation.vector - gt[k].translation.vector).norm())
        .collect();
    (!e.is_empty()).then(|| {
        let rms = (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt();
        (rms, e.iter().copied().fold(0.0, f64::max))
    })
}

/// The figures of a run in a loaded map.
pub fn in_map(out: &RunOutput, seq: &StereoSequence) -> InMap {
    let n = out.frames.len().min(out.placed.len()).min(out.poses.len());
    let placed: Vec<usize> = (0..n).filter(|&k| out.placed[k]).collect();
    let first = placed.first().copied();
    let errors = unaligned_errors(out, seq, |_| true);
    let frame_ms = |k: usize| {
        let t = &out.frames[k].times;
        t.extraction + t.stereo + t.tracking
    };
    let trying: Vec<usize> = (0..n).filter(|&k| !out.placed[k] || Some(k) == first).collect();
    let tracked: Vec<usize> =
        (0..n).filter(|&k| matches!(out.frames[k].state, Some(TrackState::Tracked { .. }))).collect();
    let med = |ks: &[usize]| (!ks.is_empty()).then(|| median(&mut ks.iter().map(|&k| frame_ms(k)).collect::<Vec<_>>()));
    InMap {
        frames: n,
        placed: placed.len(),
        first_placed: first.map(|k| seq.ids.get(k).copied().unwrap_or(k)),
        errors,
        placing_ms: med(&trying),
        tracked_ms: med(&tracked),
        trying: trying.len(),
    }
}

impl Outcome {
    /// The lines a run in a loaded map prints (none for a run that started an empty map).
    pub(crate) fn map_lines(&self) -> Vec<String> {
        let Some(MapLoad { path, counts, seconds, reexpressed, localise_only }) = &self.loaded else {
            return Vec::new();
        };
        let m = in_map(&self.out, &self.seq);
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
        match m.errors {
            Some((rms, max)) => lines.push(format!(
                "in the map's frame against the ground truth (unaligned; the ground truth's world is the camera of the sequence's frame 0, the map's when it was made from that frame): ATE {rms:.3} m RMS, largest {max:.3} m over {} placed frames",
                m.placed
            )),
            None if self.seq.ground_truth.is_none() => lines.push("ground truth: none for this sequence".into()),
            None => {}
        }
        lines
    }
}
