//! The errors of factors ([`FactorError`]) and of building and solving a graph ([`OptimError`]),
//! re-exported where they are met (`factor`, `optimizer`); a file of their own so that the values,
//! the factors, the graph and the optimiser need not import each other for them.

use crate::key::Key;

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

/// Errors of graph building and solving.
#[derive(Debug, thiserror::Error)]
pub enum OptimError {
    /// A factor failed at the starting point.
    #[error("factor {factor} cannot be evaluated at the initial values: {source}")]
    InitialEvaluation {
        /// Index of the factor in the graph.
        factor: usize,
        /// Why.
        source: FactorError,
    },
    /// The noise model does not fit the factor.
    #[error("factor {factor}: noise model does not fit a residual of dimension {dim}")]
    BadNoise {
        /// Index of the factor.
        factor: usize,
        /// Residual dimension.
        dim: usize,
    },
    /// A factor joins two variables marked for elimination.
    #[error("factor {factor} joins two eliminated variables; Schur elimination needs at most one per factor")]
    Elimination {
        /// Index of the factor.
        factor: usize,
    },
    /// The cost is not finite at the starting point.
    #[error("the initial cost is not finite")]
    NonFiniteCost,
    /// The sparse symbolic analysis of the reduced system failed.
    #[error("symbolic analysis of the reduced system failed")]
    Symbolic,
    /// No optimiser of that name.
    #[error("unknown optimiser {0:?}")]
    UnknownOptimizer(String),
}
