//! Pose checks: every pose, whichever route found it, is accepted only with enough support (inliers,
//! their spread over the image, their error) and, unless it was retrieved from the keyframe index,
//! when it is consistent with what a vehicle can do since the last measured pose.

use nalgebra::Isometry3;

use super::config::VoConfig;
use super::frame::Frame;
use super::motion::{scaled, MotionModel};
use super::pose_search::Route;
use super::refine::Refined;

/// Support of a pose: what [`support`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Support {
    /// Enough inliers, spread over the image, small reprojection error.
    Full,
    /// Accepted, but weaker.
    Weak,
    /// Not enough to accept the pose.
    Rejected,
}

/// The motion-model limits of a frame's pose: how far (metres, radians) it may lie from the
/// constant-velocity prediction after `frames` frame periods of `period_s`, for a vehicle whose
/// acceleration is at most `max_acceleration` and angular acceleration `max_angular_acceleration`,
/// with the velocity estimate off by up to `step_tolerance_m` / `rotation_tolerance_rad` per frame.
pub fn motion_limits(config: &VoConfig, frames: f64) -> (f64, f64) {
    let n = frames.max(1.0);
    let t = n * config.period();
    (
        0.5 * config.max_acceleration * t * t + n * config.step_tolerance_m,
        0.5 * config.max_angular_acceleration * t * t + n * config.rotation_tolerance_rad,
    )
}

/// Whether `pose` (any frame's pose in a common frame) is consistent with `predicted` after `frames`
/// frame periods ([`motion_limits`]); with `velocity_known` false only the speed limit applies to the
/// step from `last` (the last measured pose).
pub fn motion_consistent(
    config: &VoConfig,
    pose: &Isometry3<f64>,
    predicted: &Isometry3<f64>,
    last: &Isometry3<f64>,
    frames: f64,
    velocity_known: bool,
) -> bool {
    if velocity_known {
        let (t_lim, r_lim) = motion_limits(config, frames);
        let d = predicted.inverse() * pose;
        d.translation.vector.norm() <= t_lim && d.rotation.angle() <= r_lim
    } else {
        let t = frames.max(1.0) * config.period();
        let d = last.inverse() * pose;
        d.translation.vector.norm() <= config.max_speed * t
    }
}

/// Support of a refined pose: [`Support::Full`] with at least `min_inliers` inliers over at least
/// `min_spread_cells` cells of a 4 × 4 grid; [`Support::Weak`] with at least `weak_inliers` over at
/// least 3 cells; else rejected, as is any pose whose inliers' RMS error exceeds `max_rms_px`.
pub fn support(config: &VoConfig, inliers: usize, cells: usize, rms_px: f64) -> Support {
    if rms_px.is_nan() || rms_px > config.max_rms_px || inliers < config.weak_inliers || cells < 3 {
        Support::Rejected
    } else if inliers >= config.min_inliers && cells >= config.min_spread_cells {
        Support::Full
    } else {
        Support::Weak
    }
}

/// Occupied cells of a 4 × 4 grid over a `width` × `height` image.
pub(crate) fn spread_cells(points: impl Iterator<Item = (f64, f64)>, (width, height): (f64, f64)) -> usize {
    let mut cells = [false; 16];
    for (u, v) in points {
        let i = ((u / width * 4.0).floor().clamp(0.0, 3.0)) as usize;
        let j = ((v / height * 4.0).floor().clamp(0.0, 3.0)) as usize;
        cells[4 * j + i] = true;
    }
    cells.iter().filter(|c| **c).count()
}

/// Whether a refined pose (`curr_from_ref`) found by `route` is accepted: its support (`config`, over
/// an image of `image_size`), and its consistency with the motion model over the frames since the last
/// measured pose. A pose found without the motion model (by descriptors against the local map, or
/// against a keyframe retrieved from the index) needs full support and no motion check: it is found
/// exactly where the motion model broke (a reversal, a start after a standstill, a revisit). A pose of
/// weak support needs the motion model's prediction with a known velocity: where only the speed limit
/// applies it needs full support, as a relocalisation does.
pub(crate) fn judge(
    config: &VoConfig,
    image_size: (f64, f64),
    motion: &MotionModel,
    r: &Refined,
    route: Route,
    frame: &Frame,
) -> Support {
    let cells = spread_cells(r.inliers.iter().map(|&(_, c)| frame.keypoints[c]), image_size);
    let support = support(config, r.inliers.len(), cells, r.rms);
    if matches!(route, Route::Retrieved(_) | Route::Descriptors) {
        return if support == Support::Full { support } else { Support::Rejected };
    }
    if support == Support::Rejected {
        tracing::debug!(inliers = r.inliers.len(), cells, rms = r.rms, "pose rejected: support");
        return support;
    }
    // a weak pose is taken only where the motion model vouches for it: with the velocity unknown (the
    // step after a relocalisation or a segment's first frame) the speed limit alone lets a pose lie
    // anywhere within 5 m a frame, and 15 inliers on repeated structure can be found there
    if support == Support::Weak && !motion.velocity_known {
        tracing::debug!(inliers = r.inliers.len(), cells, "weak pose rejected: the velocity is not known");
        return Support::Rejected;
    }
    let (steps, frames) = match route {
        Route::Along(k) => {
            (motion.steps(motion.gap) - 1.0 + k as f64, motion.steps(motion.since_measured) - 1.0 + k as f64)
        }
        _ => (motion.steps(motion.gap), motion.steps(motion.since_measured)),
    };
    let predicted = motion.kf_from_last * scaled(&motion.velocity, steps);
    let pose = r.pose.inverse();
    if motion_consistent(
        &motion.step_config(config),
        &pose,
        &predicted,
        &motion.kf_from_measured,
        frames,
        motion.velocity_known,
    ) {
        support
    } else {
        let d = predicted.inverse() * pose;
        tracing::debug!(
            metres = d.translation.vector.norm(),
            degrees = d.rotation.angle().to_degrees(),
            frames,
            "pose rejected: inconsistent with the motion model"
        );
        Support::Rejected
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn motion_limits_follow_the_frame_period_and_vehicle_physics() {
        for period in [0.1, 0.2, 0.3, 0.4] {
            let config = VoConfig { frame_period_s: period, ..VoConfig::default() };
            let last = Isometry3::translation(0.0, 0.0, 100.0);
            let predicted = last * Isometry3::translation(0.0, 0.0, 15.0 * period);
            // hard braking (0.9 g) during the frame: accepted
            let braking = predicted * Isometry3::translation(0.0, 0.0, -0.5 * 9.0 * period * period);
            assert!(motion_consistent(&config, &braking, &predicted, &last, 1.0, true), "{period}");
            // a 5 m jump in any direction: rejected
            for d in [Vector3::new(0.0, 0.0, 5.0), Vector3::new(5.0, 0.0, 0.0), Vector3::new(3.0, 0.0, -4.0)] {
                let jump = Isometry3::translation(d.x, d.y, d.z) * predicted;
                assert!(!motion_consistent(&config, &jump, &predicted, &last, 1.0, true), "{period} {d}");
            }
            // a 20° turn within one frame: rejected
            let turn = predicted * Isometry3::rotation(Vector3::new(0.0, 20f64.to_radians(), 0.0));
            assert!(!motion_consistent(&config, &turn, &predicted, &last, 1.0, true), "{period}");
            // while the velocity is unknown only the speed limit (50 m/s) applies
            let fast = last * Isometry3::translation(0.0, 0.0, 40.0 * period);
            let too_fast = last * Isometry3::translation(0.0, 0.0, 60.0 * period);
            assert!(motion_consistent(&config, &fast, &last, &last, 1.0, false));
            assert!(!motion_consistent(&config, &too_fast, &last, &last, 1.0, false));
        }
        // the limits grow with the frames since the last measured pose
        let c = VoConfig::default();
        assert!(
            motion_limits(&c, 3.0).0 > motion_limits(&c, 1.0).0 && motion_limits(&c, 3.0).1 > motion_limits(&c, 1.0).1
        );
    }

    #[test]
    fn support_needs_inliers_spread_and_small_error() {
        let c = VoConfig::default();
        assert_eq!(support(&c, 200, 10, 0.8), Support::Full);
        assert_eq!(support(&c, 20, 10, 0.8), Support::Weak);
        assert_eq!(support(&c, 200, 4, 0.8), Support::Weak);
        assert_eq!(support(&c, 200, 2, 0.8), Support::Rejected);
        assert_eq!(support(&c, 10, 10, 0.8), Support::Rejected);
        assert_eq!(support(&c, 200, 10, 2.5), Support::Rejected);
        assert_eq!(support(&c, 200, 10, f64::NAN), Support::Rejected);
        assert_eq!(spread_cells([(1.0, 1.0), (1240.0, 375.0), (620.0, 10.0)].into_iter(), (1241.0, 376.0)), 3);
    }
}
