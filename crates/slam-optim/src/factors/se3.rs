//! Pose-graph factors and priors.

use nalgebra::{DMatrix, DVector, Isometry3, Vector3};

use crate::{
    factor::{Factor, FactorError},
    lie::{adjoint, se3_log, se3_right_jacobian_inv},
    values::{Key, Values},
};

/// Relative-pose measurement `Z ≈ X_i⁻¹ X_j`: residual `Log(Z⁻¹ X_i⁻¹ X_j)` in `[ω, v]` (the g2o
/// `EDGE_SE3:QUAT` convention used by gtsam's `BetweenFactor<Pose3>`).
#[derive(Debug, Clone)]
pub struct Between {
    keys: [Key; 2],
    z_inv: Isometry3<f64>,
}

impl Between {
    /// `X_i⁻¹ X_j ≈ measured`.
    pub fn new(i: Key, j: Key, measured: Isometry3<f64>) -> Self {
        Self { keys: [i, j], z_inv: measured.inverse() }
    }
}

impl Factor for Between {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        6
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let xi = values.require_pose(self.keys[0])?;
        let xj = values.require_pose(self.keys[1])?;
        let e = se3_log(&(self.z_inv * xi.inverse() * xj));
        if let Some(jac) = jacobians {
            let jr_inv = se3_right_jacobian_inv(&e);
            // X_i Exp(ξ): E ← E Exp(−Ad(X_j⁻¹ X_i) ξ);  X_j Exp(ξ): E ← E Exp(ξ)
            let ji = -jr_inv * adjoint(&(xj.inverse() * xi));
            jac.clear();
            jac.push(DMatrix::from_column_slice(6, 6, ji.as_slice()));
            jac.push(DMatrix::from_column_slice(6, 6, jr_inv.as_slice()));
        }
        Ok(DVector::from_column_slice(e.as_slice()))
    }
}

/// Absolute pose prior: residual `Log(Z⁻¹ X)`.
#[derive(Debug, Clone)]
pub struct PosePrior {
    keys: [Key; 1],
    z_inv: Isometry3<f64>,
}

impl PosePrior {
    /// `X ≈ prior`.
    pub fn new(k: Key, prior: Isometry3<f64>) -> Self {
        Self { keys: [k], z_inv: prior.inverse() }
    }
}

impl Factor for PosePrior {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        6
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let x = values.require_pose(self.keys[0])?;
        let e = se3_log(&(self.z_inv * x));
        if let Some(jac) = jacobians {
            jac.clear();
            jac.push(DMatrix::from_column_slice(6, 6, se3_right_jacobian_inv(&e).as_slice()));
        }
        Ok(DVector::from_column_slice(e.as_slice()))
    }
}

/// Point prior: residual `X − Z`.
#[derive(Debug, Clone)]
pub struct PointPrior {
    keys: [Key; 1],
    prior: Vector3<f64>,
}

impl PointPrior {
    /// `X ≈ prior`.
    pub fn new(k: Key, prior: Vector3<f64>) -> Self {
        Self { keys: [k], prior }
    }
}

impl Factor for PointPrior {
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
        let x = values.require_point(self.keys[0])?;
        if let Some(jac) = jacobians {
            jac.clear();
            jac.push(DMatrix::identity(3, 3));
        }
        Ok(DVector::from_column_slice((x - self.prior).as_slice()))
    }
}
