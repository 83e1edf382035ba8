//! The motion model: the constant-velocity prediction of the next pose from the last measured step,
//! and the bookkeeping of frame gaps it needs (frames the pipeline could not read, every n-th frame
//! played, frames lost since the last measured pose).

use nalgebra::Isometry3;

use super::config::VoConfig;

/// The motion state of the tracker; poses are in the reference keyframe's frame and move with it
/// ([`MotionModel::rebase`] when a keyframe is taken).
#[derive(Debug, Clone)]
pub(crate) struct MotionModel {
    /// Pose of the last processed frame in the reference keyframe (measured or predicted).
    pub(crate) kf_from_last: Isometry3<f64>,
    /// Pose of the last frame with a measured pose, in the reference keyframe.
    pub(crate) kf_from_measured: Isometry3<f64>,
    /// Frames since the last measured pose (1: the previous frame was measured).
    pub(crate) since_measured: usize,
    /// Frame-id steps the velocity was measured over (2 when every 2nd frame is played).
    pub(crate) velocity_gap: usize,
    /// Frame intervals between the last processed frame and the current one (frames the pipeline
    /// could not read count).
    pub(crate) gap: usize,
    /// Index of the last processed frame and of the last frame with a measured pose.
    pub(crate) last_index: usize,
    pub(crate) measured_index: usize,
    /// Whether a frame failed (lost or predicted) since the last measured pose.
    pub(crate) failed: bool,
    /// Whether `velocity` was measured (two consecutive measured frames in this segment).
    pub(crate) velocity_known: bool,
    /// `T_last←curr` of the last step (constant-velocity model).
    pub(crate) velocity: Isometry3<f64>,
}

impl Default for MotionModel {
    fn default() -> Self {
        Self {
            kf_from_last: Isometry3::identity(),
            kf_from_measured: Isometry3::identity(),
            since_measured: 1,
            velocity_gap: 1,
            gap: 1,
            last_index: 0,
            measured_index: 0,
            failed: false,
            velocity_known: false,
            velocity: Isometry3::identity(),
        }
    }
}

impl MotionModel {
    /// The first frame of the run (or of a restart): measured at `frame_index`, velocity unknown.
    pub(crate) fn start(&mut self, frame_index: usize) {
        self.since_measured = 1;
        (self.last_index, self.measured_index, self.failed) = (frame_index, frame_index, false);
        self.velocity_known = false;
        self.velocity = Isometry3::identity();
        self.velocity_gap = 1;
    }

    /// A new frame `frame_index` arrives: the frame intervals since the last processed and the last
    /// measured frame (unreadable frames between them count).
    pub(crate) fn advance(&mut self, frame_index: usize) {
        self.gap = frame_index.saturating_sub(self.last_index).max(1);
        self.since_measured = frame_index.saturating_sub(self.measured_index).max(1);
        self.last_index = frame_index;
    }

    /// The constant-velocity prediction of the current frame, `curr_from_ref`.
    pub(crate) fn predicted(&self) -> Isometry3<f64> {
        (self.kf_from_last * scaled(&self.velocity, self.steps(self.gap))).inverse()
    }

    /// A keyframe was taken: poses are now relative to it, where the frame that became it is.
    pub(crate) fn rebase(&mut self) {
        self.kf_from_last = Isometry3::identity();
        self.kf_from_measured = Isometry3::identity();
    }

    /// The reference keyframe changed to one at `new_from_old` of the old one: the poses kept relative
    /// to the reference follow.
    pub(crate) fn rebase_to(&mut self, new_from_old: &Isometry3<f64>) {
        self.kf_from_last = new_from_old * self.kf_from_last;
        self.kf_from_measured = new_from_old * self.kf_from_measured;
    }

    /// A frame at `kf_from_curr` was measured (`steady`: tracked or weak, not relocalised): the
    /// velocity from the step when the previous frame was measured too.
    pub(crate) fn measured(&mut self, frame_index: usize, kf_from_curr: Isometry3<f64>, steady: bool) {
        if steady && self.since_measured == self.gap {
            self.velocity = self.kf_from_last.inverse() * kf_from_curr;
            self.velocity_known = true;
            self.velocity_gap = self.gap;
        }
        self.kf_from_measured = kf_from_curr;
        (self.measured_index, self.failed) = (frame_index, false);
    }

    /// The pose of the current frame was found without the motion model (keyframe retrieval: a revisit
    /// or a long gap breaks it legitimately): the velocity is unknown until two measured frames give it
    /// again, so the next frame is checked against the speed limit only.
    pub(crate) fn forget_velocity(&mut self) {
        self.velocity_known = false;
    }

    /// A new map segment starts at `frame_index`: measured there, the velocity no longer known.
    pub(crate) fn restart(&mut self, frame_index: usize) {
        (self.measured_index, self.failed) = (frame_index, false);
        self.velocity_known = false;
    }

    /// Frame-id steps as velocity steps (the velocity was measured over `velocity_gap` ids), at least 1.
    pub(crate) fn steps(&self, ids: usize) -> f64 {
        ids.max(1) as f64 / self.velocity_gap.max(1) as f64
    }

    /// The settings with the frame period of one velocity step.
    pub(crate) fn step_config(&self, config: &VoConfig) -> VoConfig {
        VoConfig { frame_period_s: config.period() * self.velocity_gap.max(1) as f64, ..*config }
    }
}

/// `step` applied `r` times (a fraction of it for the fractional part).
pub(crate) fn scaled(step: &Isometry3<f64>, r: f64) -> Isometry3<f64> {
    let whole = r.max(0.0).floor();
    repeat(step, whole as usize) * Isometry3::identity().lerp_slerp(step, r.max(0.0) - whole)
}

/// `step` applied `k` times: one product after another up to [`REPEAT_FOLD`] steps, by repeated
/// squaring beyond (a gap of 10⁸ frame ids costs 27 products, not 10⁸).
fn repeat(step: &Isometry3<f64>, k: usize) -> Isometry3<f64> {
    if k <= REPEAT_FOLD {
        return (0..k).fold(Isometry3::identity(), |acc, _| acc * step);
    }
    let (mut out, mut base, mut k) = (Isometry3::identity(), *step, k);
    while k > 0 {
        if k & 1 == 1 {
            out *= base;
        }
        base *= base;
        k >>= 1;
    }
    out
}

/// Steps up to which [`repeat`] multiplies one step after another (every gap a drive's recording
/// drops, so the tracker's predictions stay as they were); longer gaps are squared.
const REPEAT_FOLD: usize = 64;

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn a_step_repeated_over_a_long_gap_is_squared_and_agrees_with_the_product() {
        let step = Isometry3::new(Vector3::new(0.01, 0.0, 0.9), Vector3::new(0.0, 0.001, 0.0));
        let fold = |k: usize| (0..k).fold(Isometry3::identity(), |acc, _| acc * step);
        for k in [0, 1, 2, 16, REPEAT_FOLD] {
            assert_eq!(repeat(&step, k), fold(k), "k = {k}: the product itself");
        }
        for k in [REPEAT_FOLD + 1, 100, 1000] {
            let d = repeat(&step, k).inverse() * fold(k);
            assert!(d.translation.vector.norm() < 1e-9 && d.rotation.angle() < 1e-12, "k = {k}: {d:?}");
        }
        // 10¹² steps: squared (a fold would not finish); a pure rotation stays one
        let turn = Isometry3::rotation(Vector3::new(0.0, 1e-6, 0.0));
        assert!(repeat(&turn, 1_000_000_000_000).translation.vector.norm() < 1e-9);
    }

    #[test]
    fn a_pose_found_without_the_motion_model_leaves_the_velocity_unknown() {
        let mut m = MotionModel::default();
        m.start(0);
        m.advance(1);
        m.measured(1, Isometry3::translation(0.0, 0.0, 1.0), true);
        assert!(m.velocity_known);
        m.advance(2);
        m.measured(2, Isometry3::translation(0.0, 0.0, 0.0), false);
        m.forget_velocity();
        assert!(!m.velocity_known, "a retrieved pose says nothing of the velocity");
        m.advance(3);
        m.measured(3, Isometry3::translation(0.0, 0.0, -1.0), true);
        assert!(m.velocity_known, "the next measured step gives it again");
    }
}
