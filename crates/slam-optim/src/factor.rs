//! The factor trait: the extension point for new measurement models.

use nalgebra::{DMatrix, DVector};

use crate::values::{Key, Values};

/// Why a factor could not be evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FactorError {
    /// A key is missing or holds a variable of the wrong kind.
    #[error("variable {0:?} missing or of the wrong kind")]
    WrongVariable(Key),
    /// The measurement model is undefined here (e.g. point behind the camera, ellipsoid not visible).
    #[error("measurement model undefined: {0}")]
    Undefined(String),
}

/// A measurement: keys, residual dimension, residual and Jacobians.
///
/// Contract: `evaluate` returns the **unwhitened** residual `r(x)` (length [`Factor::dim`]); when
/// `jacobians` is given it is filled with one `dim × tangent_dim(key)` matrix per key, in key order,
/// the derivative of `r(x ⊕ δ)` at `δ = 0` with each variable's retraction. Noise and robust kernel are
/// applied by the graph, not here. Implementations must not panic on any finite input.
pub trait Factor: Send + Sync {
    /// The variables this factor touches.
    fn keys(&self) -> &[Key];
    /// Residual dimension.
    fn dim(&self) -> usize;
    /// Residual and, on request, Jacobians.
    fn evaluate(&self, values: &Values, jacobians: Option<&mut Vec<DMatrix<f64>>>)
        -> Result<DVector<f64>, FactorError>;
}

/// Numeric Jacobians by central differences in the tangent spaces (step `h`), for tests of analytic
/// Jacobians and for prototyping factors.
pub fn numeric_jacobians(factor: &dyn Factor, values: &Values, h: f64) -> Result<Vec<DMatrix<f64>>, FactorError> {
    let mut out = Vec::new();
    for &k in factor.keys() {
        let var = values.get(k).ok_or(FactorError::WrongVariable(k))?.clone();
        let n = var.dim();
        let mut j = DMatrix::zeros(factor.dim(), n);
        for c in 0..n {
            let mut d = vec![0.0; n];
            d[c] = h;
            let mut vp = values.clone();
            vp.set(k, var.retract(&d));
            d[c] = -h;
            let mut vm = values.clone();
            vm.set(k, var.retract(&d));
            let rp = factor.evaluate(&vp, None)?;
            let rm = factor.evaluate(&vm, None)?;
            j.set_column(c, &((rp - rm) / (2.0 * h)));
        }
        out.push(j);
    }
    Ok(out)
}
