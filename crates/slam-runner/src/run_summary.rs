//! Summaries of a finished run for reports: frames per second, per-stage medians, the frame period of
//! a sequence's timestamps, and the per-frame `tracking.csv`.

use slam_pipeline::system::{FrameRecord, FrameTimes, RunOutput};

/// Frames per second from the median interval between consecutive tracked frames (start-up and the
/// first frame excluded; unreadable frames are not timed, their interval 0, and would make it infinite);
/// `None` with fewer than two such frames.
pub fn median_fps(out: &RunOutput) -> Option<f64> {
    let mut v: Vec<f64> = out.frames.iter().filter(|f| f.state.is_some()).skip(1).map(|f| f.times.interval).collect();
    slam_core::figure::median(&mut v).filter(|&m| m > 0.0).map(|m| 1000.0 / m)
}

/// What a stage needs to run at all.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Needs {
    /// Every run (tracking).
    Nothing,
    /// A detection source (the object stages idle, and are timed near 0, without boxes).
    Objects,
    /// A detection source that runs a network (one that times forward passes: the run's frames show it).
    Network,
    /// Local bundle adjustment switched on.
    BundleAdjustment,
}

/// One stage timed per frame: its name, its time, whether it runs on keyframes only, what it needs.
type Stage = (&'static str, fn(&FrameTimes) -> f64, bool, Needs);

/// The stages timed per frame, in table order.
const STAGES: [Stage; 9] = [
    ("detection (own thread)", |t| t.detection, false, Needs::Objects),
    ("of which the network's forward pass", |t| t.detector_forward, false, Needs::Network),
    ("ORB extraction", |t| t.extraction, false, Needs::Nothing),
    ("stereo matching", |t| t.stereo, false, Needs::Nothing),
    ("tracking (local map + PnP + refinement)", |t| t.tracking, false, Needs::Nothing),
    ("optical flow", |t| t.flow, false, Needs::Objects),
    ("association", |t| t.association, false, Needs::Objects),
    ("local BA (keyframes, mapping thread)", |t| t.bundle_adjustment, true, Needs::BundleAdjustment),
    ("object init + optimisation (keyframes)", |t| t.objects, true, Needs::Objects),
];

/// Which of a run's optional stages were switched on ([`stages_run`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StagesOn {
    /// A detection source: detection, optical flow, association and object fits.
    pub objects: bool,
    /// Local bundle adjustment.
    pub bundle_adjustment: bool,
}

impl StagesOn {
    fn has(&self, needs: Needs, out: &RunOutput) -> bool {
        match needs {
            Needs::Nothing => true,
            Needs::Objects => self.objects,
            Needs::Network => self.objects && out.frames.iter().any(|r| r.times.detector_forward > 0.0),
            Needs::BundleAdjustment => self.bundle_adjustment,
        }
    }
}

/// Median per stage, over the frames where the stage ran (tracked frames, not unreadable ones; only
/// keyframes for the stages that run on keyframes: local BA, objects): `(stage, median ms, frames)`,
/// every stage in a fixed order; `on` leaves out the stages a run switched off.
fn stage_rows(out: &RunOutput, on: Option<StagesOn>) -> Vec<(&'static str, Option<f64>, usize)> {
    STAGES
        .iter()
        .filter(|(_, _, _, needs)| on.is_none_or(|on| on.has(*needs, out)))
        .map(|&(name, time, keyframes_only, _)| {
            let mut v: Vec<f64> = out
                .frames
                .iter()
                .filter(|r| r.state.is_some() && (!keyframes_only || r.keyframe))
                .map(|r| time(&r.times))
                .collect();
            let n = v.len();
            (name, slam_core::figure::median(&mut v), n)
        })
        .collect()
}

/// Median per stage, over the frames where the stage ran: `(stage, median ms, frames)`; the stages that
/// run on keyframes only (local BA, objects) over keyframes. Every stage has a row, in a fixed order.
pub fn stage_table(out: &RunOutput) -> Vec<(&'static str, Option<f64>, usize)> {
    stage_rows(out, None)
}

/// [`stage_table`] without the stages the run switched off (`on`): without a detection source the
/// object stages, without bundle adjustment local BA (they still pass through the threads, in
/// microseconds, so their times alone do not say so), and the network's forward pass when the source
/// runs none (detections from a file, labels).
pub fn stages_run(out: &RunOutput, on: StagesOn) -> Vec<(&'static str, Option<f64>, usize)> {
    stage_rows(out, Some(on))
}

/// Seconds per step of the frame index (the tracker counts frame intervals by index differences): the
/// median of Δtime / Δindex over consecutive `(index, time)` pairs; 0.1 s, KITTI's rate, when there
/// are fewer than two or they are not increasing.
pub fn frame_period(stamped: &[(usize, f64)]) -> f64 {
    let mut d: Vec<f64> =
        stamped.windows(2).filter(|w| w[1].0 > w[0].0).map(|w| (w[1].1 - w[0].1) / (w[1].0 - w[0].0) as f64).collect();
    slam_core::figure::median(&mut d).filter(|m| m.is_finite() && *m > 0.0).unwrap_or(0.1)
}

/// `tracking.csv`: one row per input frame (frame, state, inliers, tracked map points, RMS
/// reprojection error in pixels, tracking time in ms: extraction + stereo + tracking).
/// Written with the `csv` crate (a field holding a comma or quote would be quoted).
pub fn tracking_csv(out: &RunOutput) -> Result<String, csv::Error> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(["frame", "state", "inliers", "tracked_map_points", "reprojection_rms_px", "time_ms"])?;
    for r in &out.frames {
        let (state, inliers) = (state_name(r), r.state.map_or(0, |s| s.inliers()));
        let rms =
            if r.reprojection_rms_px.is_finite() { format!("{:.3}", r.reprojection_rms_px) } else { String::new() };
        let ms = r.times.extraction + r.times.stereo + r.times.tracking;
        w.write_record([
            r.index.to_string(),
            state.to_string(),
            inliers.to_string(),
            r.tracked_map_points.to_string(),
            rms,
            format!("{ms:.2}"),
        ])?;
    }
    let bytes = w.into_inner().map_err(|e| e.into_error())?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

pub use slam_pipeline::tracking_states::STATE_NAMES;

/// The state of a frame as `tracking.csv` names it ("unreadable": the images could not be read).
pub fn state_name(r: &FrameRecord) -> &'static str {
    r.state.map_or("unreadable", |s| s.name())
}

/// Frames in each state of [`STATE_NAMES`], counted from the records `tracking.csv` is written from.
pub fn state_counts(frames: &[FrameRecord]) -> [usize; STATE_NAMES.len()] {
    let mut counts = [0; STATE_NAMES.len()];
    for r in frames {
        if let Some(k) = STATE_NAMES.iter().position(|n| *n == state_name(r)) {
            counts[k] += 1;
        }
    }
    counts
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::TrackState;
    use slam_pipeline::system::FrameRecord;

    fn record(index: usize, interval: f64, keyframe: bool, state: Option<TrackState>) -> FrameRecord {
        FrameRecord {
            index,
            state,
            keyframe,
            tracked_map_points: 7,
            reprojection_rms_px: if state.is_some() { 0.5 } else { f64::NAN },
            detections: Vec::new(),
            tracks: Vec::new(),
            times: FrameTimes {
                interval,
                extraction: 2.0,
                bundle_adjustment: 10.0 * index as f64,
                ..FrameTimes::default()
            },
        }
    }

    #[test]
    fn frame_period_is_the_median_step_and_falls_back_to_kitti_rate() {
        // ids 0, 1, 3 (one skipped), 4 at 10 Hz, plus a decreasing pair that is ignored
        let stamped = [(0, 0.0), (1, 0.1), (3, 0.3), (4, 0.4), (2, 0.2)];
        assert!((frame_period(&stamped) - 0.1).abs() < 1e-12);
        assert_eq!(frame_period(&[(0, 0.0)]), 0.1);
        assert_eq!(frame_period(&[(0, 1.0), (1, 1.0)]), 0.1, "no time passes: not a period");
    }

    #[test]
    fn stage_medians_skip_unreadable_frames_and_keyframe_stages_use_keyframes() {
        let tracked = Some(TrackState::Lost);
        let frames = vec![
            record(0, 500.0, true, tracked),
            record(1, 50.0, false, tracked),
            record(2, 100.0, true, tracked),
            record(3, 100.0, false, None),
        ];
        let out = RunOutput {
            map: slam_pipeline::saved_map::SavedMap::default(),
            poses: Vec::new(),
            placed: Vec::new(),
            objects: Vec::new(),
            frames,
            counts: Default::default(),
        };
        // the first frame's interval (start-up) is left out: median of 50, 100, 100
        assert!((median_fps(&out).expect("three intervals") - 10.0).abs() < 1e-12);
        let table = stage_table(&out);
        let row = |name: &str| table.iter().find(|r| r.0.starts_with(name)).copied().expect("stage");
        assert_eq!(row("ORB extraction"), ("ORB extraction", Some(2.0), 3));
        // local BA: keyframes 0 and 2 only (0 and 20 ms): the upper median
        assert_eq!(row("local BA"), ("local BA (keyframes, mapping thread)", Some(20.0), 2));
        // a run without a detection source leaves out the object stages; without BA, local BA too
        let names = |on| stages_run(&out, on).iter().map(|r| r.0).collect::<Vec<_>>();
        let tracking = ["ORB extraction", "stereo matching", "tracking (local map + PnP + refinement)"];
        let ba = "local BA (keyframes, mapping thread)";
        assert_eq!(names(StagesOn { objects: false, bundle_adjustment: true }), [&tracking[..], &[ba]].concat());
        assert_eq!(names(StagesOn { objects: false, bundle_adjustment: false }), tracking);
        let all = StagesOn { objects: true, bundle_adjustment: true };
        assert_eq!(names(all).len(), 8, "no forward pass timed: a source without a network");
        let mut frames = out.frames.clone();
        frames[1].times.detector_forward = 3.0;
        let network = RunOutput {
            map: slam_pipeline::saved_map::SavedMap::default(),
            poses: Vec::new(),
            placed: Vec::new(),
            objects: Vec::new(),
            frames,
            counts: Default::default(),
        };
        assert_eq!(names(all).len() + 1, stages_run(&network, all).len());
        assert_eq!(
            stage_table(&network)[1],
            ("of which the network's forward pass", Some(0.0), 3),
            "median of 0, 3, 0"
        );
        // every other frame unreadable (interval 0): the median is over the frames tracked
        let alternating = RunOutput {
            map: slam_pipeline::saved_map::SavedMap::default(),
            poses: Vec::new(),
            placed: Vec::new(),
            objects: Vec::new(),
            frames: (0..30)
                .map(|i| if i % 2 == 0 { record(i, 80.0, false, tracked) } else { record(i, 0.0, false, None) })
                .collect(),
            counts: Default::default(),
        };
        assert!((median_fps(&alternating).expect("tracked frames") - 12.5).abs() < 1e-12);
        // one frame: no interval, no figure (a dash in the tables, not NaN)
        let one = RunOutput { frames: out.frames[..1].to_vec(), ..alternating };
        assert_eq!(median_fps(&one), None);
        assert!(stage_table(&RunOutput { frames: Vec::new(), ..one }).iter().all(|r| r.1.is_none()));
        let csv = tracking_csv(&out).expect("csv");
        assert_eq!(csv.lines().count(), 5);
        assert!(csv.lines().nth(4).expect("row").starts_with("3,unreadable,0,7,,"), "{csv}");
    }
}
