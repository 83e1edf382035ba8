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

use slam_optim::{linear::Progress, Graph, Observer, OptimError, Optimizer, Options, Summary, Termination, Values};

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

/// What Levenberg–Marquardt carries from one iteration to the next besides the [`Progress`].
struct Region {
    /// The trust-region radius `μ`.
    radius: f64,
    /// The factor `v` the radius is divided by after the next rejected step.
    decrease: f64,
}

impl LevenbergMarquardt {
    /// A solver with the given settings.
    pub fn new(params: LmParams) -> Self {
        Self { params }
    }

    /// One iteration: the damped step for the current radius (none when the factorisation fails), tried
    /// and accepted when its gain ratio is high enough; the radius grows with a good step and shrinks
    /// after a rejected one. `Err` ends the solve.
    fn iteration(&self, values: &mut Values, at: &mut Progress, region: &mut Region) -> Result<(), Termination> {
        let p = &self.params;
        let radius = region.radius;
        let step = at.sys.solve(&at.lin, |x| x.clamp(p.min_diagonal, p.max_diagonal) / radius);
        let mut info = at.info(radius, 0.0);
        let mut accepted = false;
        if let Some(step) = step {
            info.step_norm = step.norm();
            at.check_step(values, &info)?;
            if let Some(trial) = at.trial(values, &step) {
                info.cost_change = trial.change;
                if trial.acceptable(p.min_relative_decrease) {
                    accepted = true;
                    let rho = trial.rho;
                    region.radius = (radius / (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3))).min(p.max_radius);
                    region.decrease = 2.0;
                    at.accept(values, trial, &mut info)?;
                }
            }
        }
        info.accepted = accepted;
        tracing::trace!(iteration = info.iteration, cost = info.cost, radius = region.radius, accepted, "lm iteration");
        at.notify(&info);
        if !accepted {
            region.radius /= region.decrease;
            region.decrease *= 2.0;
            if region.radius < p.min_radius {
                return Err(Termination::NoProgress);
            }
        }
        Ok(())
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
        observer: Option<&mut dyn Observer>,
    ) -> Result<Summary, OptimError> {
        let start = Instant::now();
        let o = options;
        let (sys, lin, summary) = match slam_optim::linear::start(graph, values, o, start)? {
            Ok(ready) => ready,
            Err(done) => return Ok(done),
        };
        let mut at = Progress { sys, graph, options: o, cost: lin.cost, lin, summary, observer };
        let mut region = Region { radius: o.initial_radius, decrease: 2.0 };
        at.iterate(|at| self.iteration(values, at, &mut region));
        let mut summary = at.summary;
        summary.final_cost = at.cost;
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
