//! Sparse Levenberg–Marquardt factor-graph optimisation for quadric SLAM.
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
//! * [`Graph`] holds factors with a [`NoiseModel`] and a [`RobustKernel`] each; [`LevenbergMarquardt`]
//!   solves it with Marquardt diagonal scaling and a Ceres-style trust-region update, eliminating chosen
//!   variables (points) by the Schur complement, and factorising the reduced system densely or with
//!   faer's sparse Cholesky.
//! * [`io`] reads BAL and g2o problems; [`window`] selects a local-BA window.

#![warn(missing_docs)]

pub mod factor;
pub mod factors;
pub mod io;
pub mod lie;
pub mod noise;
pub mod object;
pub mod robust;
pub mod solver;
pub mod values;
pub mod window;

pub use factor::{Factor, FactorError};
pub use noise::NoiseModel;
pub use robust::{Cauchy, Huber, RobustKernel, Tukey, L2};
pub use solver::{Graph, IterationInfo, LevenbergMarquardt, LmParams, Observer, OptimError, Summary, Termination};
pub use values::{BalCamera, Key, Values, Var};
