//! The factor graph: factors with their noise models and robust kernels, plus which variables are held
//! constant and which a backend may eliminate first (the problem handed to an [`crate::Optimizer`]).

use std::collections::BTreeSet;

use nalgebra::DVector;

use crate::{
    error::{FactorError, OptimError},
    factor::Factor,
    noise::NoiseModel,
    robust::{RobustKernel, L2},
    values::{Key, Values},
};

/// One factor with its noise model and robust kernel.
pub struct Entry {
    /// The measurement model.
    pub factor: Box<dyn Factor>,
    /// Whitening of its residual.
    pub noise: NoiseModel,
    /// Robust kernel of the squared whitened residual.
    pub kernel: Box<dyn RobustKernel>,
}

/// A factor graph: factors with their noise models and robust kernels, the variables held constant
/// ([`Graph::fix`]) and the variables a backend may eliminate first ([`Graph::eliminate`]).
#[derive(Default)]
pub struct Graph {
    entries: Vec<Entry>,
    fixed: BTreeSet<Key>,
    eliminate: BTreeSet<Key>,
}

impl Graph {
    /// An empty graph.
    pub fn new() -> Self {
        Self::default()
    }

    /// Add a factor; returns its index.
    pub fn add(
        &mut self,
        factor: impl Factor + 'static,
        noise: NoiseModel,
        kernel: impl RobustKernel + 'static,
    ) -> Result<usize, OptimError> {
        self.add_boxed(Box::new(factor), noise, Box::new(kernel))
    }

    /// Add a boxed factor and kernel.
    pub fn add_boxed(
        &mut self,
        factor: Box<dyn Factor>,
        noise: NoiseModel,
        kernel: Box<dyn RobustKernel>,
    ) -> Result<usize, OptimError> {
        if !noise.fits(factor.dim()) {
            return Err(OptimError::BadNoise { factor: self.entries.len(), dim: factor.dim() });
        }
        self.entries.push(Entry { factor, noise, kernel });
        Ok(self.entries.len() - 1)
    }

    /// Add a plain least-squares factor with unit noise.
    pub fn add_l2(&mut self, factor: impl Factor + 'static) -> usize {
        let n = self.entries.len();
        self.entries.push(Entry { factor: Box::new(factor), noise: NoiseModel::Unit, kernel: Box::new(L2) });
        n
    }

    /// Hold a variable constant (gauge fixing, old keyframes, known cameras).
    pub fn fix(&mut self, k: Key) -> &mut Self {
        self.fixed.insert(k);
        self
    }

    /// Mark a variable for elimination before the rest (BA points: the Schur complement). A factor may
    /// touch at most one such variable. This is an ordering hint: it never changes the minimum.
    pub fn eliminate(&mut self, k: Key) -> &mut Self {
        self.eliminate.insert(k);
        self
    }

    /// Whether a variable is held constant.
    pub fn is_fixed(&self, k: Key) -> bool {
        self.fixed.contains(&k)
    }

    /// Whether a variable is marked for elimination.
    pub fn is_eliminated(&self, k: Key) -> bool {
        self.eliminate.contains(&k)
    }

    /// The factors, in insertion order.
    pub fn entries(&self) -> &[Entry] {
        &self.entries
    }

    /// Number of factors.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when the graph has no factor.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The cost `½ Σ ρ(‖W r‖²)` at `values`.
    pub fn cost(&self, values: &Values) -> Result<f64, OptimError> {
        let mut c = 0.0;
        for (i, e) in self.entries.iter().enumerate() {
            let mut r = e
                .factor
                .evaluate(values, None)
                .map_err(|source| OptimError::InitialEvaluation { factor: i, source })?;
            e.noise.whiten(&mut r);
            c += 0.5 * e.kernel.evaluate(r.norm_squared())[0];
        }
        Ok(c)
    }

    /// The whitened residual of one factor (before the kernel), for inspection.
    pub fn whitened_residual(&self, factor: usize, values: &Values) -> Option<Result<DVector<f64>, FactorError>> {
        let e = self.entries.get(factor)?;
        Some(e.factor.evaluate(values, None).map(|mut r| {
            e.noise.whiten(&mut r);
            r
        }))
    }
}
