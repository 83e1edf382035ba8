//! Pinhole reprojection factors for a camera pose `T_wc` (x right, y down, z forward) and a world point.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use slam_quadric::Intrinsics;

use crate::{
    factor::{Factor, FactorError},
    lie::hat,
    values::{Key, Values},
};

/// A camera-frame point `p_c` and its Jacobians with respect to the pose tangent (right perturbation
/// of `T_wc`: rotation part `d_w`, translation part `d_v`) and the world point (`d_x`).
struct CameraPoint {
    pc: Vector3<f64>,
    d_w: Matrix3<f64>,
    d_v: Matrix3<f64>,
    d_x: Matrix3<f64>,
}

fn camera_point(values: &Values, keys: &[Key; 2]) -> Result<CameraPoint, FactorError> {
    let t_wc = values.require_pose(keys[0])?;
    let x = values.require_point(keys[1])?;
    let pc = t_wc.inverse_transform_point(&nalgebra::Point3::from(*x)).coords;
    if pc.z <= 0.0 {
        return Err(FactorError::Undefined("point behind the camera".into()));
    }
    let r_cw = t_wc.rotation.to_rotation_matrix().into_inner().transpose();
    // T_wc Exp([ω, v]) ⇒ p_c ← Exp(−[ω, v]) p_c ≈ p_c + p_c × ω − v
    Ok(CameraPoint { pc, d_w: hat(&pc), d_v: -Matrix3::identity(), d_x: r_cw })
}

/// Monocular reprojection: residual `π(K, p_c) − u_obs` (2).
#[derive(Debug, Clone)]
pub struct MonoReprojection {
    keys: [Key; 2],
    k: Intrinsics,
    observed: [f64; 2],
}

impl MonoReprojection {
    /// Pixel `observed` of point `point` in camera `pose`.
    pub fn new(pose: Key, point: Key, k: Intrinsics, observed: [f64; 2]) -> Self {
        Self { keys: [pose, point], k, observed }
    }
}

fn project_rows(k: &Intrinsics, pc: &Vector3<f64>) -> ([f64; 2], nalgebra::Matrix2x3<f64>) {
    let (x, y, z) = (pc.x, pc.y, pc.z);
    let u = k.fx * x / z + k.skew * y / z + k.cx;
    let v = k.fy * y / z + k.cy;
    let j = nalgebra::Matrix2x3::new(
        k.fx / z,
        k.skew / z,
        -(k.fx * x + k.skew * y) / (z * z),
        0.0,
        k.fy / z,
        -k.fy * y / (z * z),
    );
    ([u, v], j)
}

impl Factor for MonoReprojection {
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
        let CameraPoint { pc, d_w: dpc_dw, d_v: dpc_dv, d_x: dpc_dx } = camera_point(values, &self.keys)?;
        let (uv, j) = project_rows(&self.k, &pc);
        if let Some(jac) = jacobians {
            let mut jp = DMatrix::zeros(2, 6);
            jp.view_mut((0, 0), (2, 3)).copy_from(&(j * dpc_dw));
            jp.view_mut((0, 3), (2, 3)).copy_from(&(j * dpc_dv));
            jac.clear();
            jac.push(jp);
            jac.push(DMatrix::from_column_slice(2, 3, (j * dpc_dx).as_slice()));
        }
        Ok(DVector::from_column_slice(&[uv[0] - self.observed[0], uv[1] - self.observed[1]]))
    }
}

/// Rectified-stereo reprojection: residual `[u_l, v, u_r] − observed` (3), where the right camera is
/// the left one moved by `baseline` metres along its x axis (`u_r = fx (x − b)/z + cx`).
#[derive(Debug, Clone)]
pub struct StereoReprojection {
    keys: [Key; 2],
    k: Intrinsics,
    baseline: f64,
    observed: [f64; 3],
}

impl StereoReprojection {
    /// Left pixel and right column `observed = [u_l, v, u_r]` of `point` seen by the rig at `pose` (left camera).
    pub fn new(pose: Key, point: Key, k: Intrinsics, baseline: f64, observed: [f64; 3]) -> Self {
        Self { keys: [pose, point], k, baseline, observed }
    }
}

impl Factor for StereoReprojection {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        3
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let CameraPoint { pc, d_w: dpc_dw, d_v: dpc_dv, d_x: dpc_dx } = camera_point(values, &self.keys)?;
        let (uv, j2) = project_rows(&self.k, &pc);
        let z = pc.z;
        let ur = self.k.fx * (pc.x - self.baseline) / z + self.k.skew * pc.y / z + self.k.cx;
        if let Some(jac) = jacobians {
            let mut j = nalgebra::Matrix3::zeros();
            j.fixed_view_mut::<2, 3>(0, 0).copy_from(&j2);
            j[(2, 0)] = self.k.fx / z;
            j[(2, 1)] = self.k.skew / z;
            j[(2, 2)] = -(self.k.fx * (pc.x - self.baseline) + self.k.skew * pc.y) / (z * z);
            let mut jp = DMatrix::zeros(3, 6);
            jp.view_mut((0, 0), (3, 3)).copy_from(&(j * dpc_dw));
            jp.view_mut((0, 3), (3, 3)).copy_from(&(j * dpc_dv));
            jac.clear();
            jac.push(jp);
            jac.push(DMatrix::from_column_slice(3, 3, (j * dpc_dx).as_slice()));
        }
        Ok(DVector::from_column_slice(&[uv[0] - self.observed[0], uv[1] - self.observed[1], ur - self.observed[2]]))
    }
}
