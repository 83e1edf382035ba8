//! SE(3) helpers beyond `slam_quadric::se3`: adjoint and the right Jacobian and its inverse, in the
//! `[ω, v]` (rotation-first) tangent ordering.

use nalgebra::{Isometry3, Matrix3, Matrix6, Vector3, Vector6};
pub use slam_quadric::se3::{hat, local, retract, se3_exp, se3_log, so3_left_jacobian, so3_left_jacobian_inv};

/// Adjoint of a pose in `[ω, v]` ordering: `Ad(T) = [[R, 0], [t^ R, R]]`, so that
/// `T Exp(ξ) T⁻¹ = Exp(Ad(T) ξ)`.
pub fn adjoint(t: &Isometry3<f64>) -> Matrix6<f64> {
    let r = t.rotation.to_rotation_matrix().into_inner();
    let p = t.translation.vector;
    let mut a = Matrix6::zeros();
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    a.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    a.fixed_view_mut::<3, 3>(3, 0).copy_from(&(hat(&p) * r));
    a
}

/// The `Q(v, ω)` block of the SE(3) left Jacobian (Barfoot, "State Estimation for Robotics", eq. 7.86).
fn q_block(w: &Vector3<f64>, v: &Vector3<f64>) -> Matrix3<f64> {
    let th2 = w.norm_squared();
    let (wx, vx) = (hat(w), hat(v));
    if th2 < 1e-10 {
        return 0.5 * vx + (wx * vx + vx * wx + wx * vx * wx) / 6.0;
    }
    let th = th2.sqrt();
    let (s, c) = (th.sin(), th.cos());
    let a = (th - s) / (th2 * th);
    let b = (th2 + 2.0 * c - 2.0) / (2.0 * th2 * th2);
    let d = (2.0 * th - 3.0 * s + th * c) / (2.0 * th2 * th2 * th);
    0.5 * vx
        + a * (wx * vx + vx * wx + wx * vx * wx)
        + b * (wx * wx * vx + vx * wx * wx - 3.0 * wx * vx * wx)
        + d * (wx * vx * wx * wx + wx * wx * vx * wx)
}

/// SE(3) left Jacobian `J_l(ξ)` in `[ω, v]` ordering: `Exp(ξ + δ) ≈ Exp(J_l δ) Exp(ξ)`.
pub fn se3_left_jacobian(xi: &Vector6<f64>) -> Matrix6<f64> {
    let w = Vector3::new(xi[0], xi[1], xi[2]);
    let v = Vector3::new(xi[3], xi[4], xi[5]);
    let jl = so3_left_jacobian(&w);
    let mut j = Matrix6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&jl);
    j.fixed_view_mut::<3, 3>(3, 3).copy_from(&jl);
    j.fixed_view_mut::<3, 3>(3, 0).copy_from(&q_block(&w, &v));
    j
}

/// SE(3) right Jacobian `J_r(ξ) = J_l(−ξ)`: `Exp(ξ + δ) ≈ Exp(ξ) Exp(J_r δ)`.
pub fn se3_right_jacobian(xi: &Vector6<f64>) -> Matrix6<f64> {
    se3_left_jacobian(&-xi)
}

/// Inverse of [`se3_right_jacobian`]: `Log(Exp(ξ) Exp(δ)) ≈ ξ + J_r⁻¹ δ`.
pub fn se3_right_jacobian_inv(xi: &Vector6<f64>) -> Matrix6<f64> {
    let w = -Vector3::new(xi[0], xi[1], xi[2]);
    let v = -Vector3::new(xi[3], xi[4], xi[5]);
    let jinv = so3_left_jacobian_inv(&w);
    let q = q_block(&w, &v);
    let mut j = Matrix6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&jinv);
    j.fixed_view_mut::<3, 3>(3, 3).copy_from(&jinv);
    j.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-jinv * q * jinv));
    j
}

/// SO(3) right Jacobian of the angle-axis map: `R(r + δ) ≈ R(r) Exp(J_r(r) δ)`.
pub fn so3_right_jacobian(r: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian(&-r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn right_jacobian_matches_numeric() {
        let xi = Vector6::new(0.3, -0.5, 0.8, 1.0, -2.0, 0.7);
        let h = 1e-6;
        let base = se3_exp(&xi);
        let jr_inv = se3_right_jacobian_inv(&xi);
        let jr = se3_right_jacobian(&xi);
        assert!((jr * jr_inv - Matrix6::identity()).norm() < 1e-10);
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = h;
            let plus = se3_log(&(base * se3_exp(&d)));
            let minus = se3_log(&(base * se3_exp(&-d)));
            let num = (plus - minus) / (2.0 * h);
            assert!((num - jr_inv.column(k)).norm() < 1e-6, "col {k}: {num} vs {}", jr_inv.column(k));
        }
    }

    #[test]
    fn adjoint_identity() {
        let t = se3_exp(&Vector6::new(0.2, 0.1, -0.3, 1.0, 2.0, 3.0));
        let xi = Vector6::new(0.01, -0.02, 0.03, 0.1, 0.2, -0.1);
        let lhs = t * se3_exp(&xi) * t.inverse();
        let rhs = se3_exp(&(adjoint(&t) * xi));
        assert!((lhs.to_homogeneous() - rhs.to_homogeneous()).norm() < 1e-12);
    }
}
