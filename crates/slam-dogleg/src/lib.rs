//! Powell's dog-leg behind [`slam_optim::Optimizer`]: a second backend with a different step rule,
//! sharing the Schur-complement linear algebra of [`slam_optim::linear`].
//!
//! Each iteration computes the Gauss–Newton step `δ_gn` from `(JᵀJ + μ D) δ = −g` (`g = Jᵀr`, `D` the
//! clamped diagonal of `JᵀJ`, `μ` a small regularisation that grows ×10 whenever the factorisation
//! fails, as in Ceres' dog-leg, so rank-deficient gauges stay solvable) and the Cauchy point
//! `δ_sd = −(‖g‖² / ‖J g‖²) g`, then takes, with the trust-region radius `Δ`:
//!
//! * `δ_gn` if `‖δ_gn‖ ≤ Δ`;
//! * `Δ · δ_sd / ‖δ_sd‖` if the Cauchy point is already outside (`‖δ_sd‖ ≥ Δ`);
//! * otherwise the point of the segment `δ_sd → δ_gn` at distance `Δ`.
//!
//! The step is accepted when the gain ratio `ρ` (actual / model decrease) exceeds 1e-3. The radius
//! follows the classical rule: `Δ ← max(Δ, 3‖δ‖)` when `ρ > 0.75`, `Δ ← ‖δ‖ / 4` when `ρ < 0.25`
//! (and after a rejected step). A trial point where a factor cannot be evaluated is a rejected step.

use std::time::Instant;

use slam_optim::{
    linear::{LinearSystem, Linearization, Progress, Step},
    Graph, Observer, OptimError, Optimizer, Options, Summary, Termination, Values,
};

/// Settings particular to dog-leg (the common ones are [`Options`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DogLegParams {
    /// Initial regularisation `μ` of the Gauss–Newton system, relative to its clamped diagonal.
    pub min_mu: f64,
    /// Largest regularisation before the step counts as failed.
    pub max_mu: f64,
    /// Clamp of the diagonal used for the regularisation, lower.
    pub min_diagonal: f64,
    /// Clamp of the diagonal, upper.
    pub max_diagonal: f64,
    /// Smallest trust-region radius before giving up.
    pub min_radius: f64,
    /// Largest trust-region radius.
    pub max_radius: f64,
    /// Smallest gain ratio of an accepted step.
    pub min_relative_decrease: f64,
}

impl Default for DogLegParams {
    /// Ceres' dog-leg defaults (μ from 1e-8 to 1, diagonal clamp [1e-6, 1e32]).
    fn default() -> Self {
        Self {
            min_mu: 1e-8,
            max_mu: 1.0,
            min_diagonal: 1e-6,
            max_diagonal: 1e32,
            min_radius: 1e-32,
            max_radius: 1e16,
            min_relative_decrease: 1e-3,
        }
    }
}

/// The dog-leg backend (name `"dogleg"`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DogLeg {
    /// Settings.
    pub params: DogLegParams,
}

/// What dog-leg carries from one iteration to the next besides the [`Progress`].
struct Region {
    /// The trust-region radius.
    radius: f64,
    /// The regularisation of the Gauss–Newton system.
    mu: f64,
    /// The steps at the current linearisation, kept after a rejected step (recomputed after every
    /// accepted one).
    cached: Option<(Option<Step>, Step)>,
}

impl DogLeg {
    /// A solver with the given settings.
    pub fn new(params: DogLegParams) -> Self {
        Self { params }
    }

    /// The two steps at a linearisation: Gauss-Newton (damped by `mu` where the system needs it) and
    /// steepest descent scaled to the minimum of the model along the gradient (Cauchy's point).
    fn steps(&self, sys: &LinearSystem, graph: &Graph, lin: &Linearization, mu: &mut f64) -> (Option<Step>, Step) {
        let g = sys.gradient(lin);
        let jg = sys.jacobian_norm_squared(graph, lin, &g);
        let alpha = if jg > 0.0 { g.norm_squared() / jg } else { 0.0 };
        (self.gauss_newton(sys, lin, mu), g.scaled(-alpha))
    }

    /// The Gauss–Newton step (regularised), raising `mu` until the factorisation succeeds.
    fn gauss_newton(&self, sys: &LinearSystem, lin: &Linearization, mu: &mut f64) -> Option<Step> {
        let p = &self.params;
        while *mu <= p.max_mu {
            let m = *mu;
            if let Some(s) = sys.solve(lin, |x| x.clamp(p.min_diagonal, p.max_diagonal) * m) {
                return Some(s);
            }
            *mu *= 10.0;
        }
        None
    }

    /// One iteration: the dog-leg step for the current radius, tried and accepted when its gain ratio
    /// is high enough, then the radius updated. `Err` ends the solve.
    fn iteration(&self, values: &mut Values, at: &mut Progress, region: &mut Region) -> Result<(), Termination> {
        let p = &self.params;
        let (gn, sd) = match region.cached.take() {
            Some(c) => c,
            None => self.steps(&at.sys, at.graph, &at.lin, &mut region.mu),
        };
        let step = dogleg_step(gn.as_ref(), &sd, region.radius);
        let step_norm = step.norm();
        let mut info = at.info(region.radius, step_norm);
        at.check_step(values, &info)?;
        let mut accepted = false;
        let mut rho = f64::NEG_INFINITY;
        if let Some(trial) = at.trial(values, &step) {
            info.cost_change = trial.change;
            rho = trial.rho;
            if trial.acceptable(p.min_relative_decrease) {
                accepted = true;
                at.accept(values, trial, &mut info)?;
                region.mu = (region.mu / 10.0).max(p.min_mu);
            }
        }
        if !accepted {
            region.cached = Some((gn, sd));
        }
        region.radius = next_radius(region.radius, rho, step_norm, p);
        info.accepted = accepted;
        tracing::trace!(
            iteration = info.iteration,
            cost = info.cost,
            radius = region.radius,
            accepted,
            "dog-leg iteration"
        );
        at.notify(&info);
        if region.radius < p.min_radius {
            return Err(Termination::NoProgress);
        }
        Ok(())
    }
}

/// The trust region after a step of length `step_norm` whose cost fell by `rho` times the model's
/// prediction: grown (to three steps, at most `max_radius`) after a good step, shrunk to a quarter of
/// it after a poor one, kept otherwise.
fn next_radius(radius: f64, rho: f64, step_norm: f64, p: &DogLegParams) -> f64 {
    if rho > 0.75 {
        radius.max(3.0 * step_norm).min(p.max_radius)
    } else if rho < 0.25 {
        0.25 * step_norm.min(radius)
    } else {
        radius
    }
}

/// The dog-leg step for radius `radius` from the Gauss–Newton step (if any) and the Cauchy point.
fn dogleg_step(gn: Option<&Step>, sd: &Step, radius: f64) -> Step {
    if let Some(gn) = gn {
        if gn.norm() <= radius {
            return gn.clone();
        }
    }
    let sd_norm = sd.norm();
    let Some(gn) = gn.filter(|_| sd_norm < radius) else {
        return sd.scaled(radius / sd_norm.max(f64::MIN_POSITIVE));
    };
    // ‖sd + β (gn − sd)‖ = radius, β ∈ [0, 1]
    let d = gn.add_scaled(-1.0, sd);
    let (a, b, c) = (d.norm_squared(), 2.0 * sd.dot(&d), sd.norm_squared() - radius * radius);
    let disc = (b * b - 4.0 * a * c).max(0.0);
    let beta = if a > 0.0 { ((-b + disc.sqrt()) / (2.0 * a)).clamp(0.0, 1.0) } else { 0.0 };
    sd.add_scaled(beta, &d)
}

impl Optimizer for DogLeg {
    fn name(&self) -> &str {
        "dogleg"
    }

    fn optimize(
        &self,
        graph: &Graph,
        values: &mut Values,
        options: &Options,
        observer: Option<&mut dyn Observer>,
    ) -> Result<Summary, OptimError> {
        let start = Instant::now();
        let (p, o) = (self.params, options);
        let (sys, lin, summary) = match slam_optim::linear::start(graph, values, o, start)? {
            Ok(ready) => ready,
            Err(done) => return Ok(done),
        };
        let mut at = Progress { sys, graph, options: o, cost: lin.cost, lin, summary, observer };
        let mut region = Region { radius: o.initial_radius, mu: p.min_mu, cached: None };
        at.iterate(|at| self.iteration(values, at, &mut region));
        let mut summary = at.summary;
        summary.final_cost = at.cost;
        summary.elapsed = start.elapsed();
        tracing::debug!(
            initial = summary.initial_cost,
            final_cost = summary.final_cost,
            iterations = summary.iterations,
            termination = ?summary.termination,
            "dog-leg finished"
        );
        Ok(summary)
    }
}
