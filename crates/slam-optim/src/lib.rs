//! Factor-graph optimisation seam for quadric SLAM: variables, factors, robust kernels, the `Optimizer` trait.
//!
//! Minimises `½ Σ_i ρ_i(‖W_i r_i(x)‖²)` over variables `x` on their manifolds, where `r_i` is a factor's
//! residual, `W_i` its noise model's whitening (`W = Σ^{-1/2}`, so `‖W r‖²` is a squared Mahalanobis
//! distance) and `ρ_i` a robust kernel with the convention `ρ(s) = s` for plain least squares (as
//! Ceres; gtsam's and factrs' "½x²" is our `½ρ`). The cost therefore equals Ceres' `final_cost` and
//! gtsam's `graph.error()`.
//!
//! * [`Values`] holds variables: SE(3) poses (right perturbation, full SE(3) exponential, tangent
//!   `[ω, v]`), 3-D points, ellipsoids (9-dof tangent of `slam_quadric`), BAL cameras (additive 9-vector).
//! * [`Factor`] is the extension point: keys, residual dimension, residual and Jacobians. Built-in
//!   factors are in [`factors`]; each has an analytic Jacobian checked against central differences.
//! * [`Graph`] holds factors with a [`NoiseModel`] and a [`RobustKernel`] each, the fixed variables and
//!   the variables to eliminate first (BA points).
//! * [`Optimizer`] is the seam: one object-safe trait with [`Options`] and a [`Summary`] report. The
//!   backends live in their own crates (`slam-lm`: Levenberg–Marquardt; `slam-dogleg`: Powell's
//!   dog-leg); callers hold a [`SharedOptimizer`] chosen at run time. [`conformance`] is the suite
//!   every backend passes.
//! * [`linear`] is the linear algebra the trust-region backends share: Schur complement of the
//!   eliminated variables, reduced system factorised densely or with faer's sparse Cholesky.
//! * [`io`] reads BAL and g2o problems; [`object`] fits one ellipsoid from its boxes with any backend.

#![warn(missing_docs)]

pub mod conformance;
mod error;
pub mod factor;
pub mod factors;
pub mod graph;
pub mod io;
mod key;
pub mod lie;
pub mod linear;
pub mod noise;
pub mod object;
pub mod optimizer;
pub mod robust;
pub mod values;

pub use factor::{Factor, FactorError};
pub use graph::{Entry, Graph};
pub use noise::NoiseModel;
pub use optimizer::{IterationInfo, Observer, OptimError, Optimizer, Options, SharedOptimizer, Summary, Termination};
pub use robust::{Cauchy, Huber, RobustKernel, Tukey, L2};
pub use values::{BalCamera, Key, Values, Var};
