//! A third optimiser in under 100 lines (docs/architecture.md, docs/optimisation.md): plain Gauss–Newton
//! with step halving, written against the `slam_optim` seam only. `tests/third_backend.rs` runs the
//! conformance checks on it; this program solves a g2o pose graph with it:
//!
//! `cargo run --release -p slam-optim --example gauss_newton -- [fixtures/optim/parking-garage.g2o]`

use std::time::Instant;

use slam_optim::{linear::LinearSystem, Graph, Observer, OptimError, Optimizer, Options, Summary, Termination, Values};

/// Gauss–Newton with backtracking: solve `(JᵀJ + 1e-9·diag) δ = −g`, halve δ until the cost drops.
#[derive(Debug, Default)]
pub struct GaussNewton;

impl Optimizer for GaussNewton {
    fn name(&self) -> &str {
        "gauss-newton"
    }

    fn optimize(
        &self,
        graph: &Graph,
        values: &mut Values,
        options: &Options,
        _observer: Option<&mut dyn Observer>,
    ) -> Result<Summary, OptimError> {
        let start = Instant::now();
        let sys = LinearSystem::new(graph, values, options.dense_limit)?;
        let init = |(factor, source)| OptimError::InitialEvaluation { factor, source };
        let mut lin = sys.linearize(graph, values).map_err(init)?;
        let mut s = Summary {
            initial_cost: lin.cost,
            final_cost: lin.cost,
            iterations: 0,
            accepted: 0,
            termination: Termination::MaxIterations,
            elapsed: start.elapsed(),
            reduced_dim: sys.reduced_dim(),
            sparse: sys.is_sparse(),
        };
        while s.iterations < options.max_iterations {
            s.iterations += 1;
            if sys.gradient_max(&lin) <= options.gradient_tolerance {
                s.termination = Termination::GradientTolerance;
                break;
            }
            let Some(mut step) = sys.solve(&lin, |d| 1e-9 * d.max(1e-6)) else {
                s.termination = Termination::NoProgress;
                break;
            };
            // backtrack: at most 20 halvings
            let mut next = None;
            for _ in 0..20 {
                let trial = sys.retract(values, &step);
                match sys.cost(graph, &trial) {
                    Ok(c) if c < lin.cost => {
                        next = Some((trial, c));
                        break;
                    }
                    _ => step = step.scaled(0.5),
                }
            }
            let Some((trial, cost)) = next else {
                s.termination = Termination::NoProgress;
                break;
            };
            let rel = (lin.cost - cost) / lin.cost.max(f64::MIN_POSITIVE);
            *values = trial;
            s.accepted += 1;
            lin = sys.linearize(graph, values).map_err(init)?;
            if rel < options.function_tolerance {
                s.termination = Termination::FunctionTolerance;
                break;
            }
        }
        s.final_cost = lin.cost;
        s.elapsed = start.elapsed();
        Ok(s)
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let default = concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/optim/parking-garage.g2o");
    let path = std::env::args().nth(1).unwrap_or_else(|| default.to_string());
    let mut p = slam_optim::io::read_g2o(&path)?;
    if let Some(&first) = p.cameras.first() {
        p.graph.fix(first); // the gauge
    }
    let s = GaussNewton.optimize(&p.graph, &mut p.values, &Options::pose_graph(), None)?;
    println!(
        "{path}: cost {:.6e} -> {:.6e} in {} iterations ({:?}), {:.3} s",
        s.initial_cost,
        s.final_cost,
        s.iterations,
        s.termination,
        s.elapsed.as_secs_f64()
    );
    Ok(())
}
