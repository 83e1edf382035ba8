//! The optimiser seam: one object-safe trait that every call site uses, its options and its report.
//!
//! A backend receives a [`Graph`] (factors with analytic Jacobians, noise models, robust kernels, fixed
//! variables and elimination hints) and the starting [`Values`], and minimises the graph's cost
//! `½ Σ ρ(‖W r‖²)` in place. Callers hold an `Arc<dyn Optimizer>` chosen at run time
//! (`slam-app run --optimizer lm|dogleg`); implementations live in their own crates (`slam-lm`,
//! `slam-dogleg`) and pass [`crate::conformance`].

use std::{sync::Arc, time::Duration};

use crate::{graph::Graph, values::Values};

pub use crate::error::OptimError;

/// Options every backend honours (backend-specific settings belong to the backend's constructor).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Iteration cap (accepted plus rejected steps).
    pub max_iterations: usize,
    /// Stop when `|Δcost| / cost < function_tolerance` after an accepted step.
    pub function_tolerance: f64,
    /// Stop when the largest gradient component is below this.
    pub gradient_tolerance: f64,
    /// Stop when `‖δ‖ ≤ parameter_tolerance (‖x‖ + parameter_tolerance)`.
    pub parameter_tolerance: f64,
    /// Initial trust-region radius (Ceres' meaning: for LM the inverse of the relative damping, for
    /// dog-leg the largest step norm).
    pub initial_radius: f64,
    /// Reduced systems (after eliminating the marked variables) up to this size are factorised densely,
    /// larger ones with the sparse Cholesky.
    pub dense_limit: usize,
}

impl Default for Options {
    /// Ceres' defaults (function 1e-6, gradient 1e-10, parameter 1e-8, radius 1e4, 100 iterations).
    fn default() -> Self {
        Self {
            max_iterations: 100,
            function_tolerance: 1e-6,
            gradient_tolerance: 1e-10,
            parameter_tolerance: 1e-8,
            initial_radius: 1e4,
            dense_limit: 2000,
        }
    }
}

impl Options {
    /// The defaults with an iteration cap.
    pub fn with_max_iterations(max_iterations: usize) -> Self {
        Self { max_iterations, ..Self::default() }
    }

    /// Settings for pose graphs: start near Gauss–Newton (initial radius 1e12, so the Marquardt term is
    /// ~1e-12 of the diagonal). A long chain of poses has low-frequency modes whose curvature is far
    /// below the diagonal of the information matrix; Ceres' BA default radius (1e4) damps exactly those
    /// and costs 10–14 iterations instead of 4–6 on sphere2500 and parking-garage. A bad step is still
    /// rejected and the radius shrinks as usual.
    pub fn pose_graph() -> Self {
        Self { initial_radius: 1e12, ..Self::default() }
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Termination {
    /// Relative cost change below the function tolerance.
    FunctionTolerance,
    /// Gradient below the gradient tolerance.
    GradientTolerance,
    /// Step below the parameter tolerance.
    ParameterTolerance,
    /// Iteration cap reached.
    MaxIterations,
    /// The trust region shrank below its minimum without an acceptable step.
    NoProgress,
    /// Nothing to optimise.
    NoFreeVariables,
}

/// What happened in one iteration (for observers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IterationInfo {
    /// Iteration number, from 1.
    pub iteration: usize,
    /// Cost after the iteration.
    pub cost: f64,
    /// Cost decrease of the trial step (negative when it got worse; NaN when it could not be evaluated).
    pub cost_change: f64,
    /// Trust-region radius used.
    pub radius: f64,
    /// Norm of the trial step.
    pub step_norm: f64,
    /// Whether the step was accepted.
    pub accepted: bool,
}

/// Watches iterations (logging, visualisation) without touching the solver.
pub trait Observer {
    /// Called after every iteration.
    fn on_iteration(&mut self, info: &IterationInfo);
}

/// The report of a solve.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Cost at the start.
    pub initial_cost: f64,
    /// Cost at the end.
    pub final_cost: f64,
    /// Iterations (accepted plus rejected).
    pub iterations: usize,
    /// Accepted steps.
    pub accepted: usize,
    /// Why it stopped.
    pub termination: Termination,
    /// Wall time of the solve.
    pub elapsed: Duration,
    /// Size of the system factorised (after eliminating the marked variables).
    pub reduced_dim: usize,
    /// Whether the sparse Cholesky was used.
    pub sparse: bool,
}

/// A nonlinear least-squares backend. Object-safe: callers hold `Arc<dyn Optimizer>`.
///
/// Contract (checked by [`crate::conformance`]): minimise the graph's cost from `values`, which on
/// return hold the best point found (never a point with a higher cost than the start); variables
/// marked [`Graph::fix`] are unchanged; [`Graph::eliminate`] is a hint the backend may ignore; a
/// factor that cannot be evaluated at a trial point rejects that step; an error only when the start
/// itself cannot be evaluated or the graph is malformed.
pub trait Optimizer: Send + Sync + std::fmt::Debug {
    /// Short name (`"lm"`, `"dogleg"`), as accepted by `--optimizer`.
    fn name(&self) -> &str;

    /// Optimise `values` in place.
    fn optimize(
        &self,
        graph: &Graph,
        values: &mut Values,
        options: &Options,
        observer: Option<&mut dyn Observer>,
    ) -> Result<Summary, OptimError>;
}

/// A shared optimiser, as held by the components that solve problems (tracker, mapper, object fits).
pub type SharedOptimizer = Arc<dyn Optimizer>;
