//! BAL reprojection (Agarwal et al., "Bundle Adjustment in the Large", ECCV 2010).

use nalgebra::{DMatrix, DVector, Matrix2x3, Matrix3, Rotation3, SMatrix, Vector2, Vector3};

use crate::{
    factor::{Factor, FactorError},
    lie::{hat, so3_right_jacobian},
    values::{Key, Values},
};

/// Residual `f·d(p)·p − u_obs`, with `P = R(r) X + t`, `p = −(P_x, P_y)/P_z`,
/// `d = 1 + k1‖p‖² + k2‖p‖⁴`. A point at `P_z = 0` is an evaluation error; points behind the camera
/// keep their (large) residual, never zeroed.
#[derive(Debug, Clone)]
pub struct BalReprojection {
    keys: [Key; 2],
    observed: Vector2<f64>,
}

impl BalReprojection {
    /// Observation of point `point` by camera `camera` at pixel `observed`.
    pub fn new(camera: Key, point: Key, observed: [f64; 2]) -> Self {
        Self { keys: [camera, point], observed: Vector2::new(observed[0], observed[1]) }
    }

    /// Residual and, on request, the camera (2×9) and point (2×3) Jacobians, in fixed-size matrices.
    #[allow(clippy::type_complexity)]
    fn compute(
        &self,
        values: &Values,
        jac: bool,
    ) -> Result<(Vector2<f64>, Option<(SMatrix<f64, 2, 9>, Matrix2x3<f64>)>), FactorError> {
        let c = values.require_bal(self.keys[0])?.0;
        let x = values.require_point(self.keys[1])?;
        let r = Vector3::new(c[0], c[1], c[2]);
        let rot = Rotation3::from_scaled_axis(r).into_inner();
        let p_cam = rot * x + Vector3::new(c[3], c[4], c[5]);
        if p_cam.z == 0.0 || !p_cam.z.is_finite() {
            return Err(FactorError::Undefined("point on the camera plane".into()));
        }
        let p = Vector2::new(-p_cam.x / p_cam.z, -p_cam.y / p_cam.z);
        let (f, k1, k2) = (c[6], c[7], c[8]);
        let n = p.norm_squared();
        let d = 1.0 + k1 * n + k2 * n * n;
        let res = f * d * p - self.observed;
        if !jac {
            return Ok((res, None));
        }
        // ∂p/∂P
        let z = p_cam.z;
        let dp_dpc = Matrix2x3::new(-1.0 / z, 0.0, p_cam.x / (z * z), 0.0, -1.0 / z, p_cam.y / (z * z));
        // ∂u/∂p = f (d I + p (∂d/∂p)ᵀ), ∂d/∂p = 2 (k1 + 2 k2 n) p
        let dd_dp = 2.0 * (k1 + 2.0 * k2 * n) * p;
        let du_dp = f * (d * nalgebra::Matrix2::identity() + p * dd_dp.transpose());
        let du_dpc = du_dp * dp_dpc;
        let dpc_dr: Matrix3<f64> = -rot * hat(x) * so3_right_jacobian(&r);
        let mut jc = SMatrix::<f64, 2, 9>::zeros();
        jc.fixed_view_mut::<2, 3>(0, 0).copy_from(&(du_dpc * dpc_dr));
        jc.fixed_view_mut::<2, 3>(0, 3).copy_from(&du_dpc);
        jc.fixed_view_mut::<2, 1>(0, 6).copy_from(&(d * p));
        jc.fixed_view_mut::<2, 1>(0, 7).copy_from(&(f * n * p));
        jc.fixed_view_mut::<2, 1>(0, 8).copy_from(&(f * n * n * p));
        let jp = du_dpc * rot;
        Ok((res, Some((jc, jp))))
    }
}

impl Factor for BalReprojection {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        2
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let want = jacobians.is_some();
        let (res, j) = self.compute(values, want)?;
        if let (Some(jac), Some((jc, jp))) = (jacobians, j) {
            jac.clear();
            jac.push(DMatrix::from_column_slice(2, 9, jc.as_slice()));
            jac.push(DMatrix::from_column_slice(2, 3, jp.as_slice()));
        }
        Ok(DVector::from_column_slice(res.as_slice()))
    }

    fn evaluate_into(
        &self,
        values: &Values,
        residual: &mut [f64],
        jacobians: Option<&mut [f64]>,
    ) -> Result<(), FactorError> {
        let (res, j) = self.compute(values, jacobians.is_some())?;
        let size = |n: usize, want: usize| {
            if n == want {
                Ok(())
            } else {
                Err(FactorError::Undefined(format!("BAL reprojection: buffer of {n} entries, expected {want}")))
            }
        };
        size(residual.len(), 2)?;
        residual.copy_from_slice(res.as_slice());
        if let (Some(out), Some((jc, jp))) = (jacobians, j) {
            size(out.len(), 24)?;
            out[..18].copy_from_slice(jc.as_slice());
            out[18..].copy_from_slice(jp.as_slice());
        }
        Ok(())
    }
}
