//! Pose-only refinement: Gauss–Newton on one camera pose whose observed points are held fixed, with
//! Huber weights (iteratively reweighted). The tracker's outlier-sorting rounds solve this small
//! problem (six unknowns, hundreds of observations) many times per frame; a dedicated solver needs
//! no graph, no boxed factors and no allocation per observation.

use nalgebra::{Isometry3, Matrix3, Matrix3x6, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};
use slam_quadric::Intrinsics;

/// A fixed point (in the frame the pose maps from) and its observation `[u_l, v, u_r]` (`u_r` NaN:
/// left image only), with the σ of each component, pixels.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PoseObservation {
    pub point: Vector3<f64>,
    pub observed: [f64; 3],
    pub sigma: [f64; 3],
}

/// A rectified stereo rig's projection: intrinsics and baseline (right camera at +x).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Rig {
    pub k: Intrinsics,
    pub baseline: f64,
}

impl Rig {
    /// Whitened residual `(π(T x) − observed) / σ` (third component 0 for a left-only observation)
    /// and its Jacobian with respect to `δ = [ρ, φ]` of the update `T ← (Rot(φ), ρ) · T`; `None`
    /// when the point is not in front of the camera.
    pub(crate) fn residual(
        &self,
        pose: &Isometry3<f64>,
        o: &PoseObservation,
    ) -> Option<(Vector3<f64>, Matrix3x6<f64>)> {
        let k = &self.k;
        let p = pose * nalgebra::Point3::from(o.point);
        let (x, y, z) = (p.x, p.y, p.z);
        if z <= 1e-6 {
            return None;
        }
        let stereo = o.observed[2].is_finite();
        let u = k.fx * x / z + k.skew * y / z + k.cx;
        let v = k.fy * y / z + k.cy;
        let ur = k.fx * (x - self.baseline) / z + k.skew * y / z + k.cx;
        let mut r = Vector3::new((u - o.observed[0]) / o.sigma[0], (v - o.observed[1]) / o.sigma[1], 0.0);
        // ∂(u, v, u_r)/∂p
        let mut jp = Matrix3::new(
            k.fx / z,
            k.skew / z,
            -(k.fx * x + k.skew * y) / (z * z),
            0.0,
            k.fy / z,
            -k.fy * y / (z * z),
            k.fx / z,
            k.skew / z,
            -(k.fx * (x - self.baseline) + k.skew * y) / (z * z),
        );
        if stereo {
            r.z = (ur - o.observed[2]) / o.sigma[2];
        } else {
            jp.row_mut(2).fill(0.0);
        }
        for (i, s) in o.sigma.iter().enumerate() {
            jp.row_mut(i).scale_mut(1.0 / s);
        }
        // ∂p/∂ρ = I, ∂p/∂φ = −[p]×
        let mut j = Matrix3x6::zeros();
        j.fixed_view_mut::<3, 3>(0, 0).copy_from(&jp);
        j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-jp * p.coords.cross_matrix()));
        Some((r, j))
    }
}

/// `(Rot(φ), ρ) · pose` for `δ = [ρ, φ]`.
pub(crate) fn update(pose: &Isometry3<f64>, d: &Vector6<f64>) -> Isometry3<f64> {
    let step = Isometry3::from_parts(
        Translation3::new(d[0], d[1], d[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(d[3], d[4], d[5])),
    );
    step * pose
}

/// Robust cost of a whitened squared residual `s`: Huber with threshold `huber` (σ units), or plain
/// least squares when `None`; and the IRLS weight.
fn kernel(s: f64, huber: Option<f64>) -> (f64, f64) {
    match huber {
        Some(d) if s > d * d => {
            let r = s.sqrt();
            (2.0 * d * r - d * d, d / r)
        }
        _ => (s, 1.0),
    }
}

fn cost(rig: &Rig, pose: &Isometry3<f64>, obs: &[PoseObservation], huber: Option<f64>) -> f64 {
    obs.iter().filter_map(|o| rig.residual(pose, o)).map(|(r, _)| kernel(r.norm_squared(), huber).0).sum()
}

/// Gauss–Newton from `guess` on the observations (Huber with threshold `huber` when given): at most
/// `max_iterations` steps, each halved up to four times until the robust cost does not rise; stops
/// when a step changes the cost by less than 1e-6 of it (the optimiser's function tolerance).
/// `None` when the normal equations are singular.
pub(crate) fn solve(
    rig: &Rig,
    obs: &[PoseObservation],
    guess: &Isometry3<f64>,
    huber: Option<f64>,
    max_iterations: usize,
) -> Option<Isometry3<f64>> {
    let mut pose = *guess;
    let mut current = cost(rig, &pose, obs, huber);
    for _ in 0..max_iterations {
        let mut h = Matrix6::zeros();
        let mut g = Vector6::zeros();
        for o in obs {
            if let Some((r, j)) = rig.residual(&pose, o) {
                let (_, w) = kernel(r.norm_squared(), huber);
                h += w * j.transpose() * j;
                g += w * j.transpose() * r;
            }
        }
        let step = -h.cholesky()?.solve(&g);
        let mut scale = 1.0;
        let mut accepted = None;
        for _ in 0..5 {
            let candidate = update(&pose, &(scale * step));
            let c = cost(rig, &candidate, obs, huber);
            if c <= current {
                accepted = Some((candidate, c));
                break;
            }
            scale *= 0.5;
        }
        let Some((next, c)) = accepted else { break };
        let change = current - c;
        pose = next;
        current = c;
        if change <= 1e-6 * current.max(1e-12) {
            break;
        }
    }
    Some(pose)
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::rng::SimRng;

    fn rig() -> Rig {
        Rig { k: Intrinsics::new(707.0, 707.0, 601.9, 183.1), baseline: 0.54 }
    }

    /// The analytic Jacobian matches central differences of the residual along each update
    /// direction, for stereo and left-only observations and a far point with a larger σ.
    #[test]
    fn jacobian_matches_numeric_derivatives() {
        let rig = rig();
        let pose = Isometry3::from_parts(
            Translation3::new(0.3, -0.1, -1.2),
            UnitQuaternion::from_euler_angles(0.02, -0.05, 0.01),
        );
        for (point, ur, sigma) in [
            (Vector3::new(2.0, -1.0, 12.0), 500.0, [1.0, 1.0, 1.0]),
            (Vector3::new(-4.0, 0.5, 30.0), f64::NAN, [1.0, 1.0, 1.0]),
            (Vector3::new(1.0, 0.2, 45.0), 600.0, [1.0, 1.0, 2.1]),
        ] {
            let o = PoseObservation { point, observed: [610.0, 190.0, ur], sigma };
            let (_, j) = rig.residual(&pose, &o).expect("in front");
            let h = 1e-6;
            for c in 0..6 {
                let mut d = Vector6::zeros();
                d[c] = h;
                let (rp, _) = rig.residual(&update(&pose, &d), &o).expect("in front");
                d[c] = -h;
                let (rm, _) = rig.residual(&update(&pose, &d), &o).expect("in front");
                let numeric = (rp - rm) / (2.0 * h);
                let analytic = j.column(c);
                assert!(
                    (numeric - analytic).norm() < 1e-5 * (1.0 + analytic.norm()),
                    "column {c}: {numeric} vs {analytic}"
                );
            }
        }
        let behind = PoseObservation { point: Vector3::new(0.0, 0.0, -5.0), observed: [0.0; 3], sigma: [1.0; 3] };
        assert!(rig.residual(&Isometry3::identity(), &behind).is_none());
    }

    /// From a guess 0.3 m and 2° off, the solver recovers the pose from exact observations, and with
    /// Huber weights also when a fifth of them are gross outliers.
    #[test]
    fn solve_recovers_the_pose_with_and_without_outliers() {
        let rig = rig();
        let k = rig.k;
        let truth =
            Isometry3::from_parts(Translation3::new(0.1, 0.0, -1.3), UnitQuaternion::from_euler_angles(0.0, 0.03, 0.0));
        let mut rng = SimRng::new(21);
        let obs: Vec<PoseObservation> = (0..300)
            .map(|i| {
                let z = rng.uniform(5.0, 40.0);
                let x = Vector3::new(rng.uniform(-0.5, 0.5) * z, rng.uniform(-0.2, 0.2) * z, z);
                let p = truth * nalgebra::Point3::from(x);
                let (u, v) = (k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
                let ur = if i % 3 == 0 { f64::NAN } else { u - k.fx * rig.baseline / p.z };
                PoseObservation { point: x, observed: [u, v, ur], sigma: [1.0; 3] }
            })
            .collect();
        let guess = update(&truth, &Vector6::new(0.2, -0.1, 0.2, 0.01, -0.03, 0.005));
        let check = |pose: Isometry3<f64>, tol_m: f64| {
            let e = pose * truth.inverse();
            assert!(e.translation.vector.norm() < tol_m && e.rotation.angle() < tol_m / 10.0, "{e:?}");
        };
        check(solve(&rig, &obs, &guess, None, 10).expect("solved"), 1e-6);
        let mut bad = obs.clone();
        for o in bad.iter_mut().step_by(5) {
            o.observed[0] += rng.uniform(30.0, 80.0);
            o.observed[1] -= rng.uniform(30.0, 80.0);
        }
        let robust = solve(&rig, &bad, &guess, Some(7.815f64.sqrt()), 10).expect("solved");
        check(robust, 0.05);
        // the tracker's next round: observations within the χ² bound at the robust pose, least squares
        let kept: Vec<PoseObservation> = bad
            .iter()
            .copied()
            .filter(|o| rig.residual(&robust, o).is_some_and(|(r, _)| r.norm_squared() <= 7.815))
            .collect();
        assert_eq!(kept.len(), 240, "every outlier and no inlier dropped");
        check(solve(&rig, &kept, &robust, None, 10).expect("solved"), 1e-6);
        assert!(solve(&rig, &[], &guess, None, 10).is_none(), "no observations: singular");
    }
}
