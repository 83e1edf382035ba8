//! Trajectory error against ground truth: ATE (RMS of position errors, in the shared first-frame world
//! and after a rigid alignment), RPE over distance segments (KITTI's odometry metric: translation % and
//! degrees per 100 m), and end-point drift.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Errors of an estimated trajectory.
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryErrors {
    /// Poses compared.
    pub frames: usize,
    /// Ground-truth path length, metres.
    pub path_m: f64,
    /// Estimated path length over the same frames, metres (sum of the frame-to-frame steps).
    pub est_path_m: f64,
    /// RMS position error with both trajectories starting at the identity (no alignment), metres.
    pub ate_m: f64,
    /// RMS position error after the best rigid alignment (Horn / Umeyama without scale), metres.
    pub ate_aligned_m: f64,
    /// Distance between the last estimated and true positions over the path length, %.
    pub end_drift_pct: f64,
    /// Scale of the best similarity alignment (estimate to truth is `1 / scale`): above 1 the estimate
    /// is too long.
    pub scale: f64,
    /// `(segment length m, translation %, rotation deg/100 m, segments)` for each length with segments.
    pub rpe: Vec<(f64, f64, f64, usize)>,
}

impl TrajectoryErrors {
    /// How much longer the estimated path is than the true one, % (negative: shorter): a scale error
    /// shows here whatever the path's shape (the peer comparison's "path error").
    pub fn path_error_pct(&self) -> f64 {
        100.0 * (self.est_path_m / self.path_m - 1.0)
    }
}

/// Rigid transform `T` minimising `Σ |T·a_i − b_i|²` (Horn / Umeyama, no scale); `None` for fewer than
/// three points.
pub fn align_rigid(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Option<Isometry3<f64>> {
    let n = a.len().min(b.len());
    if n < 3 {
        return None;
    }
    let ca = a[..n].iter().sum::<Vector3<f64>>() / n as f64;
    let cb = b[..n].iter().sum::<Vector3<f64>>() / n as f64;
    let mut h = Matrix3::zeros();
    for (p, q) in a[..n].iter().zip(&b[..n]) {
        h += (p - ca) * (q - cb).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let v = vt.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = cb - rot * ca;
    Some(Isometry3::from_parts(Translation3::from(t), rot))
}

/// KITTI's relative-pose error over all segments of `length` metres (by ground-truth distance):
/// mean `|t_err| / length` (%) and `angle_err / length` (deg/100 m), and the number of segments.
pub fn rpe(est: &[Isometry3<f64>], gt: &[Isometry3<f64>], length: f64) -> Option<(f64, f64, usize)> {
    let n = est.len().min(gt.len());
    let mut dist = vec![0.0; n];
    for i in 1..n {
        dist[i] = dist[i - 1] + (gt[i].translation.vector - gt[i - 1].translation.vector).norm();
    }
    let (mut t_sum, mut r_sum, mut count) = (0.0, 0.0, 0usize);
    for i in 0..n {
        let Some(j) = (i..n).find(|&j| dist[j] - dist[i] >= length) else { break };
        let err = (gt[i].inverse() * gt[j]).inverse() * (est[i].inverse() * est[j]);
        t_sum += err.translation.vector.norm() / length;
        r_sum += err.rotation.angle().to_degrees() / length;
        count += 1;
    }
    (count > 0).then(|| (100.0 * t_sum / count as f64, 100.0 * r_sum / count as f64, count))
}

/// All errors of `est` against `gt` (first `min(len)` poses), RPE at the given segment lengths.
pub fn trajectory_errors(est: &[Isometry3<f64>], gt: &[Isometry3<f64>], lengths: &[f64]) -> Option<TrajectoryErrors> {
    let n = est.len().min(gt.len());
    if n < 2 {
        return None;
    }
    let pe: Vec<Vector3<f64>> = est[..n].iter().map(|p| p.translation.vector).collect();
    let pg: Vec<Vector3<f64>> = gt[..n].iter().map(|p| p.translation.vector).collect();
    let rms = |pairs: &mut dyn Iterator<Item = f64>| (pairs.map(|d| d * d).sum::<f64>() / n as f64).sqrt();
    let ate_m = rms(&mut pe.iter().zip(&pg).map(|(a, b)| (a - b).norm()));
    let aligned = align_rigid(&pe, &pg);
    let scale = aligned
        .map(|t| {
            let ca = pe.iter().sum::<Vector3<f64>>() / n as f64;
            let cb = pg.iter().sum::<Vector3<f64>>() / n as f64;
            let num: f64 = pe.iter().map(|a| (a - ca).norm_squared()).sum();
            let den: f64 = pe.iter().zip(&pg).map(|(a, b)| (t.rotation * (a - ca)).dot(&(b - cb))).sum();
            if den > 0.0 {
                num / den
            } else {
                f64::NAN
            }
        })
        .unwrap_or(f64::NAN);
    let ate_aligned_m = match aligned {
        Some(t) => rms(&mut pe
            .iter()
            .zip(&pg)
            .map(|(a, b)| (t * nalgebra::Point3::from(*a) - nalgebra::Point3::from(*b)).norm())),
        None => ate_m,
    };
    let path_m: f64 = pg.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    let est_path_m: f64 = pe.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    let end = (pe[n - 1] - pg[n - 1]).norm();
    Some(TrajectoryErrors {
        frames: n,
        path_m,
        est_path_m,
        ate_m,
        ate_aligned_m,
        end_drift_pct: if path_m > 0.0 { 100.0 * end / path_m } else { f64::NAN },
        scale,
        rpe: lengths.iter().filter_map(|&l| rpe(&est[..n], &gt[..n], l).map(|(t, r, c)| (l, t, r, c))).collect(),
    })
}

/// The largest translation error of one frame-to-frame step, `|t(est[k−1]⁻¹·est[k]) − t(gt[k−1]⁻¹·gt[k])|`,
/// over the steps `k ≥ 1` whose end frame is `counted[k]` (e.g. frames the tracker marked tracked), with
/// that `k`; `None` when no step counts.
pub fn largest_step_error(est: &[Isometry3<f64>], gt: &[Isometry3<f64>], counted: &[bool]) -> Option<(f64, usize)> {
    let n = est.len().min(gt.len()).min(counted.len());
    (1..n)
        .filter(|&k| counted[k])
        .map(|k| {
            let e = (est[k - 1].inverse() * est[k]).translation.vector;
            let g = (gt[k - 1].inverse() * gt[k]).translation.vector;
            ((e - g).norm(), k)
        })
        .max_by(|a, b| a.0.total_cmp(&b.0))
}

/// Largest change of the step rotation between two consecutive steps (degrees) that a stretch of
/// ground truth may show and still be taken as interpolated rather than measured. A car on a road
/// changes its attitude from one 0.1 s step to the next by road roughness and steering: the measured
/// stretches of the dev data change by at least 0.015° (odometry 06 from frame 12) and 0.037° (the OXTS
/// attitude of raw drive 0005), with medians of 0.07° and 0.18°. An interpolated or smoothed stretch
/// turns by the same rotation every step to within rounding (below 0.001° at the start of odometry
/// 06). 0.005° lies between the two on a log scale, three times below the smallest measured change.
pub const INTERPOLATED_TURN_DEG: f64 = 0.005;

/// Fewest consecutive steps with the same rotation for a stretch to count as interpolated: three
/// changes below [`INTERPOLATED_TURN_DEG`] in a row, which one quiet moment of a measured drive does
/// not produce.
pub const INTERPOLATED_MIN_STEPS: usize = 4;

/// A step shorter than this (metres) is standing still, where a measured attitude may hold steady: it
/// never counts towards an interpolated stretch.
pub const STANDING_STEP_M: f64 = 0.1;

/// Stretches of ground truth over which every step turns by the same rotation (to within
/// [`INTERPOLATED_TURN_DEG`]) while the camera moves: smoothed or interpolated poses, not measured
/// ones. Returns `(first frame, last frame)` index pairs, each spanning at least
/// [`INTERPOLATED_MIN_STEPS`] steps.
pub fn interpolated_stretches(gt: &[Isometry3<f64>]) -> Vec<(usize, usize)> {
    let steps: Vec<Isometry3<f64>> = gt.windows(2).map(|w| w[0].inverse() * w[1]).collect();
    // same[k]: step k (frame k → k+1) turns as step k−1 did, both moving
    let moving = |s: &Isometry3<f64>| s.translation.vector.norm() >= STANDING_STEP_M;
    let same: Vec<bool> = (0..steps.len())
        .map(|k| {
            k > 0
                && moving(&steps[k])
                && moving(&steps[k - 1])
                && (steps[k].rotation.scaled_axis() - steps[k - 1].rotation.scaled_axis()).norm().to_degrees()
                    < INTERPOLATED_TURN_DEG
        })
        .collect();
    let mut out = Vec::new();
    let mut k = 0;
    while k < same.len() {
        if !same[k] {
            k += 1;
            continue;
        }
        let start = k;
        while k < same.len() && same[k] {
            k += 1;
        }
        // steps start−1 ..= k−1 turn alike: frames start−1 ..= k
        if k - start + 1 >= INTERPOLATED_MIN_STEPS {
            out.push((start - 1, k));
        }
    }
    out
}

/// [`trajectory_errors`] of the poses from index `from` on, both trajectories re-anchored there (each
/// expressed in the frame of its pose at `from`).
pub fn errors_from(
    est: &[Isometry3<f64>],
    gt: &[Isometry3<f64>],
    from: usize,
    lengths: &[f64],
) -> Option<TrajectoryErrors> {
    let n = est.len().min(gt.len());
    if from + 2 > n {
        return None;
    }
    let anchor = |p: &[Isometry3<f64>]| -> Vec<Isometry3<f64>> {
        let origin = p[from].inverse();
        p[from..n].iter().map(|q| origin * q).collect()
    };
    trajectory_errors(&anchor(est), &anchor(gt), lengths)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A drive along z at `step` m per frame that turns by `turn(k)` radians about y at step k.
    fn turning(n: usize, step: f64, turn: impl Fn(usize) -> f64) -> Vec<Isometry3<f64>> {
        let mut p = Isometry3::identity();
        let mut out = vec![p];
        for k in 0..n - 1 {
            let s = Isometry3::from_parts(
                Translation3::new(0.0, 0.0, step),
                UnitQuaternion::from_axis_angle(&Vector3::y_axis(), turn(k)),
            );
            p *= s;
            out.push(p);
        }
        out
    }

    #[test]
    fn an_interpolated_stretch_is_found_and_measured_driving_is_not() {
        // measured-like: the step rotation changes by 0.06° from one step to the next
        let wobble = |k: usize| if k % 2 == 0 { 0.08f64.to_radians() } else { 0.02f64.to_radians() };
        let measured = turning(30, 1.2, wobble);
        assert!(interpolated_stretches(&measured).is_empty());
        // frames 0..=10 turn by exactly 0.04° per step, then measured-like driving
        let drive = turning(30, 1.2, |k| if k < 10 { 0.04f64.to_radians() } else { wobble(k) });
        assert_eq!(interpolated_stretches(&drive), vec![(0, 10)]);
        // a short constant run (3 steps) is not enough
        let short = turning(30, 1.2, |k| if (5..8).contains(&k) { 0.04f64.to_radians() } else { wobble(k) });
        assert!(interpolated_stretches(&short).is_empty(), "{:?}", interpolated_stretches(&short));
        // standing still with a steady attitude is not interpolation
        let standing = turning(30, 0.0, |_| 0.0);
        assert!(interpolated_stretches(&standing).is_empty());
    }

    #[test]
    fn errors_from_a_frame_ignore_what_went_wrong_before_it() {
        let gt = straight(20, 1.0);
        // 0.3 m too far at frame 5 and every frame after (one bad step), exact from there on
        let est: Vec<Isometry3<f64>> = gt
            .iter()
            .enumerate()
            .map(|(k, g)| if k >= 5 { Isometry3::translation(0.0, 0.0, 0.3) * g } else { *g })
            .collect();
        let all = trajectory_errors(&est, &gt, &[]).expect("errors");
        assert!(all.ate_m > 0.2, "{}", all.ate_m);
        let later = errors_from(&est, &gt, 5, &[]).expect("errors");
        assert!(later.ate_m < 1e-9 && later.frames == 15, "{later:?}");
        assert!(errors_from(&est, &gt, 19, &[]).is_none(), "one pose is too few");
    }

    #[test]
    fn the_largest_step_error_counts_only_the_marked_frames() {
        let gt = straight(6, 1.0);
        // a 0.5 m jump into frame 3 that persists: only the step into frame 3 is wrong (ATE would
        // blame every frame after it)
        let est: Vec<Isometry3<f64>> = gt
            .iter()
            .enumerate()
            .map(|(k, g)| if k >= 3 { Isometry3::translation(0.0, 0.0, 0.5) * g } else { *g })
            .collect();
        let (e, k) = largest_step_error(&est, &gt, &[true; 6]).expect("steps");
        assert!((e - 0.5).abs() < 1e-12 && k == 3, "{e} {k}");
        // frame 3 not counted: the other steps are right
        let (e, k) = largest_step_error(&est, &gt, &[true, true, true, false, true, true]).expect("steps");
        assert!(e < 1e-12 && k != 3, "{e} {k}");
        assert!(largest_step_error(&est, &gt, &[true, false, false, false, false, false]).is_none());
    }

    fn straight(n: usize, step: f64) -> Vec<Isometry3<f64>> {
        (0..n).map(|i| Isometry3::translation(0.0, 0.0, step * i as f64)).collect()
    }

    #[test]
    fn a_perfect_trajectory_has_no_error() {
        let gt = straight(50, 1.0);
        let e = trajectory_errors(&gt, &gt, &[10.0]).expect("errors");
        assert!(e.ate_m < 1e-12 && e.ate_aligned_m < 1e-12 && e.end_drift_pct < 1e-12);
        assert_eq!(e.rpe.len(), 1);
        assert!(e.rpe[0].1 < 1e-12 && e.rpe[0].3 == 40);
    }

    #[test]
    fn a_scale_error_shows_as_drift_and_rpe() {
        let gt = straight(51, 1.0);
        let est = straight(51, 1.01); // 1 % too long
        let e = trajectory_errors(&est, &gt, &[10.0, 20.0]).expect("errors");
        assert!((e.end_drift_pct - 1.0).abs() < 1e-9, "{e:?}");
        assert!((e.scale - 1.01).abs() < 1e-9, "{e:?}");
        for (_, t, r, _) in &e.rpe {
            assert!((t - 1.0).abs() < 1e-9 && r.abs() < 1e-9, "{e:?}");
        }
        // positions 0.01·i off: RMS over i = 0..50
        let expected = ((0..51).map(|i| (0.01 * i as f64).powi(2)).sum::<f64>() / 51.0).sqrt();
        assert!((e.ate_m - expected).abs() < 1e-9);
        assert!(e.ate_aligned_m < e.ate_m, "alignment can only help");
    }

    #[test]
    fn alignment_undoes_a_rigid_motion() {
        let gt: Vec<Isometry3<f64>> =
            (0..30).map(|i| Isometry3::translation((0.2 * i as f64).sin() * 3.0, 0.1 * i as f64, i as f64)).collect();
        let t =
            Isometry3::from_parts(Translation3::new(1.0, -2.0, 0.5), UnitQuaternion::from_euler_angles(0.1, 0.3, -0.2));
        let est: Vec<Isometry3<f64>> = gt.iter().map(|p| t * p).collect();
        let e = trajectory_errors(&est, &gt, &[]).expect("errors");
        assert!(e.ate_m > 1.0 && e.ate_aligned_m < 1e-9, "{e:?}");
        assert!(align_rigid(&[Vector3::zeros(); 2], &[Vector3::zeros(); 2]).is_none());
    }
}
