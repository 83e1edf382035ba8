//! The factor trait: the extension point for new measurement models.

use nalgebra::{DMatrix, DVector};

use crate::values::{Key, Values};

pub use crate::error::FactorError;

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

    /// [`Factor::evaluate`] into the caller's buffers, which the solvers use: `residual` has
    /// [`Factor::dim`] entries; `jacobians`, when given, holds the blocks of all keys one after the
    /// other, each `dim × tangent_dim(key)` column-major. The provided implementation calls `evaluate`
    /// and copies; a factor on a hot path (BA reprojection) overrides it to avoid allocating. A
    /// residual or Jacobian of the wrong size is an error, not a panic.
    fn evaluate_into(
        &self,
        values: &Values,
        residual: &mut [f64],
        jacobians: Option<&mut [f64]>,
    ) -> Result<(), FactorError> {
        let mut blocks = Vec::new();
        let want = jacobians.is_some();
        let r = self.evaluate(values, if want { Some(&mut blocks) } else { None })?;
        if r.len() != residual.len() {
            return Err(FactorError::Undefined(format!(
                "residual has {} components, the factor's dim() is {}",
                r.len(),
                residual.len()
            )));
        }
        residual.copy_from_slice(r.as_slice());
        if let Some(out) = jacobians {
            let mut off = 0;
            for b in &blocks {
                let end = off + b.len();
                let Some(dst) = out.get_mut(off..end) else { break };
                dst.copy_from_slice(b.as_slice());
                off = end;
            }
            let expected: usize = out.len();
            let got: usize = blocks.iter().map(|b| b.len()).sum();
            if got != expected || blocks.len() != self.keys().len() {
                return Err(FactorError::Undefined(format!(
                    "{} Jacobian blocks with {got} entries, expected {} blocks with {expected}",
                    blocks.len(),
                    self.keys().len()
                )));
            }
        }
        Ok(())
    }
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
