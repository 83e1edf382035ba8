//! Levenberg–Marquardt behind [`slam_optim::Optimizer`]: the project's own solver.
//!
//! Each iteration solves
//!
//! ```text
//! (JᵀJ + diag(JᵀJ)_clamped / μ) δ = −Jᵀr
//! ```
//!
//! ([`slam_optim::linear`]: Schur complement of the marked variables, dense or sparse Cholesky) with
//! Marquardt's diagonal scaling clamped to `[min_diagonal, max_diagonal]` and a trust-region radius `μ`
//! updated as in Ceres: after a step with gain ratio `ρ > min_relative_decrease`,
//! `μ ← μ / max(1/3, 1 − (2ρ − 1)³)`; after a rejected step `μ ← μ / v`, `v ← 2v`. A failed
//! factorisation, or a trial point where a factor cannot be evaluated, is a rejected step.

use std::time::Instant;

use slam_optim::{Graph, IterationInfo, Observer, OptimError, Optimizer, Options, Summary, Termination, Values};

/// Settings particular to Levenberg–Marquardt (the common ones are [`Options`]); defaults follow Ceres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmParams {
    /// Largest radius.
    pub max_radius: f64,
    /// Smallest radius before giving up.
    pub min_radius: f64,
    /// Clamp of the Marquardt diagonal, lower.
    pub min_diagonal: f64,
    /// Clamp of the Marquardt diagonal, upper.
    pub max_diagonal: f64,
    /// Smallest gain ratio of an accepted step.
    pub min_relative_decrease: f64,
}

impl Default for LmParams {
    fn default() -> Self {
        Self {
            max_radius: 1e16,
            min_radius: 1e-32,
            min_diagonal: 1e-6,
            max_diagonal: 1e32,
            min_relative_decrease: 1e-3,
        }
    }
}

/// The Levenberg–Marquardt backend (name `"lm"`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LevenbergMarquardt {
    /// Settings.
    pub params: LmParams,
}

impl LevenbergMarquardt {
    /// A solver with the given settings.
    pub fn new(params: LmParams) -> Self {
        Self { params }
    }
}

impl Optimizer for LevenbergMarquardt {
    fn name(&self) -> &str {
        "lm"
    }

    fn optimize(
        &self,
        graph: &Graph,
        values: &mut Values,
        options: &Options,
        mut observer: Option<&mut dyn Observer>,
    ) -> Result<Summary, OptimError> {
        let start = Instant::now();
        let (p, o) = (self.params, options);
        let (sys, mut lin, mut summary) = match slam_optim::linear::start(graph, values, o, start)? {
            Ok(ready) => ready,
            Err(done) => return Ok(done),
        };
        let mut cost = lin.cost;
        let mut radius = o.initial_radius;
        let mut decrease = 2.0;
        loop {
            if summary.iterations >= o.max_iterations {
                summary.termination = Termination::MaxIterations;
                break;
            }
            if sys.gradient_max(&lin) <= o.gradient_tolerance {
                summary.termination = Termination::GradientTolerance;
                break;
            }
            summary.iterations += 1;
            let step = sys.solve(&lin, |x| x.clamp(p.min_diagonal, p.max_diagonal) / radius);
            let mut info = IterationInfo {
                iteration: summary.iterations,
                cost,
                cost_change: f64::NAN,
                radius,
                step_norm: 0.0,
                accepted: false,
            };
            let mut accepted = false;
            if let Some(step) = step {
                let step_norm = step.norm();
                info.step_norm = step_norm;
                let x_norm = values.iter().map(|(_, v)| v.norm_squared()).sum::<f64>().sqrt();
                if step_norm <= o.parameter_tolerance * (x_norm + o.parameter_tolerance) {
                    summary.termination = Termination::ParameterTolerance;
                    if let Some(obs) = observer.as_deref_mut() {
                        obs.on_iteration(&info);
                    }
                    break;
                }
                let model = sys.model_decrease(graph, &lin, &step);
                let trial = sys.retract(values, &step);
                if let Ok(new_cost) = sys.cost(graph, &trial) {
                    let change = cost - new_cost;
                    info.cost_change = change;
                    let rho = if model > 0.0 { change / model } else { f64::NEG_INFINITY };
                    if new_cost.is_finite() && rho > p.min_relative_decrease {
                        accepted = true;
                        *values = trial;
                        let rel = change.abs() / cost.max(f64::MIN_POSITIVE);
                        cost = new_cost;
                        radius = (radius / (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3))).min(p.max_radius);
                        decrease = 2.0;
                        summary.accepted += 1;
                        info.cost = cost;
                        if rel < o.function_tolerance {
                            summary.termination = Termination::FunctionTolerance;
                            if let Some(obs) = observer.as_deref_mut() {
                                obs.on_iteration(&IterationInfo { accepted: true, ..info });
                            }
                            break;
                        }
                        match sys.linearize(graph, values) {
                            Ok(l) => {
                                cost = l.cost;
                                lin = l;
                            }
                            Err(_) => {
                                summary.termination = Termination::NoProgress;
                                break;
                            }
                        }
                    }
                }
            }
            info.accepted = accepted;
            tracing::trace!(iteration = info.iteration, cost = info.cost, radius, accepted, "lm iteration");
            if let Some(obs) = observer.as_deref_mut() {
                obs.on_iteration(&info);
            }
            if !accepted {
                radius /= decrease;
                decrease *= 2.0;
                if radius < p.min_radius {
                    summary.termination = Termination::NoProgress;
                    break;
                }
            }
        }
        summary.final_cost = cost;
        summary.elapsed = start.elapsed();
        tracing::debug!(
            initial = summary.initial_cost,
            final_cost = summary.final_cost,
            iterations = summary.iterations,
            termination = ?summary.termination,
            "lm finished"
        );
        Ok(summary)
    }
}
