//! Minimal SE(3) / SO(3) helpers: hat, exponential and logarithm maps.
//!
//! Tangent vectors are ordered `[ω (3), v (3)]` (rotation first), as in GTSAM's `Pose3`.
//! The exponential is the full SE(3) one:
//!
//! ```text
//! Exp([ω, v]) = ( exp([ω]×),  J_l(ω) v ),   J_l(ω) = I + (1 - cos θ)/θ² [ω]× + (θ - sin θ)/θ³ [ω]×²
//! ```
//!
//! and poses are perturbed on the right: `T ⊕ ξ = T · Exp(ξ)`, `T₂ ⊖ T₁ = Log(T₁⁻¹ T₂)`.
//! This matches gtsam built with `GTSAM_POSE3_EXPMAP=ON`, which the oracle vectors use.

use nalgebra::{Isometry3, Matrix3, Matrix4, Rotation3, Translation3, UnitQuaternion, Vector3, Vector6};

/// Skew-symmetric matrix `[w]×` with `[w]× x = w × x`.
pub fn hat(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

/// Left Jacobian of SO(3), `J_l(ω)`; the translation part of the SE(3) exponential is `J_l(ω) v`.
pub fn so3_left_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = w.norm_squared();
    let wx = hat(w);
    if theta2 < 1e-10 {
        // Taylor expansion to second order.
        return Matrix3::identity() + 0.5 * wx + wx * wx / 6.0;
    }
    let theta = theta2.sqrt();
    Matrix3::identity() + (1.0 - theta.cos()) / theta2 * wx + (theta - theta.sin()) / (theta2 * theta) * wx * wx
}

/// Inverse of [`so3_left_jacobian`].
pub fn so3_left_jacobian_inv(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = w.norm_squared();
    let wx = hat(w);
    if theta2 < 1e-10 {
        return Matrix3::identity() - 0.5 * wx + wx * wx / 12.0;
    }
    let theta = theta2.sqrt();
    let coeff = 1.0 / theta2 - (1.0 + theta.cos()) / (2.0 * theta * theta.sin());
    Matrix3::identity() - 0.5 * wx + coeff * wx * wx
}

/// SE(3) exponential of `xi = [ω, v]`.
pub fn se3_exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    let w = Vector3::new(xi[0], xi[1], xi[2]);
    let v = Vector3::new(xi[3], xi[4], xi[5]);
    let rot = UnitQuaternion::from_scaled_axis(w);
    let t = so3_left_jacobian(&w) * v;
    Isometry3::from_parts(Translation3::from(t), rot)
}

/// SE(3) logarithm, returning `[ω, v]`; inverse of [`se3_exp`] for rotation angles below π.
pub fn se3_log(pose: &Isometry3<f64>) -> Vector6<f64> {
    let w = pose.rotation.scaled_axis();
    let v = so3_left_jacobian_inv(&w) * pose.translation.vector;
    Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
}

/// Right retraction `pose · Exp(xi)`.
pub fn retract(pose: &Isometry3<f64>, xi: &Vector6<f64>) -> Isometry3<f64> {
    pose * se3_exp(xi)
}

/// Right local coordinates `Log(from⁻¹ · to)`, so that `retract(from, local(from, to)) == to`.
pub fn local(from: &Isometry3<f64>, to: &Isometry3<f64>) -> Vector6<f64> {
    se3_log(&(from.inverse() * to))
}

/// The 4×4 generator `G_k` of the SE(3) Lie algebra for tangent index `k` (0..6, `[ω, v]` order):
/// `ξ^ = Σ ξ_k G_k`.
pub fn generator(k: usize) -> Matrix4<f64> {
    let mut g = Matrix4::zeros();
    match k {
        0..=2 => {
            let mut e = Vector3::zeros();
            e[k] = 1.0;
            g.fixed_view_mut::<3, 3>(0, 0).copy_from(&hat(&e));
        }
        3..=5 => g[(k - 3, 3)] = 1.0,
        _ => panic!("SE(3) generator index {k} out of range 0..6"),
    }
    g
}

/// Build an isometry from a rotation matrix (assumed orthonormal, det +1) and a translation.
pub fn isometry_from_parts(r: &Matrix3<f64>, t: &Vector3<f64>) -> Isometry3<f64> {
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    Isometry3::from_parts(Translation3::from(*t), rot)
}

/// Build an isometry from a 4×4 homogeneous matrix (top-left block re-orthonormalised).
pub fn isometry_from_matrix(m: &Matrix4<f64>) -> Isometry3<f64> {
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let t: Vector3<f64> = m.fixed_view::<3, 1>(0, 3).into_owned();
    isometry_from_parts(&r, &t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_log_round_trip() {
        let xi = Vector6::new(0.3, -0.2, 0.5, 1.0, -2.0, 0.5);
        let back = se3_log(&se3_exp(&xi));
        assert!((back - xi).norm() < 1e-12, "{back:?}");
        let tiny = Vector6::new(1e-7, 0.0, -2e-7, 0.1, 0.2, 0.3);
        assert!((se3_log(&se3_exp(&tiny)) - tiny).norm() < 1e-12);
    }

    #[test]
    fn jacobian_inverse_is_inverse() {
        for w in [Vector3::new(0.1, 0.2, -0.3), Vector3::new(1e-6, 0.0, 0.0), Vector3::new(2.0, -1.0, 0.5)] {
            let p = so3_left_jacobian(&w) * so3_left_jacobian_inv(&w);
            assert!((p - Matrix3::identity()).norm() < 1e-10);
        }
    }

    #[test]
    fn generators_match_first_order_exp() {
        let h = 1e-6;
        for k in 0..6 {
            let mut xi = Vector6::zeros();
            xi[k] = h;
            let m = se3_exp(&xi).to_homogeneous();
            let approx = (m - Matrix4::identity()) / h;
            assert!((approx - generator(k)).norm() < 1e-5, "k={k}");
        }
    }
}
