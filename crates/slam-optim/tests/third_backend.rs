//! The example of docs/architecture.md: a third backend in under 100 lines, written against the seam
//! only (Gauss–Newton with a small Marquardt regularisation and step halving), passing conformance
//! checks.

use std::time::Instant;

use slam_optim::{
    conformance, linear::LinearSystem, Graph, Observer, OptimError, Optimizer, Options, Summary, Termination, Values,
};

/// Gauss–Newton with backtracking: solve `(JᵀJ + 1e-9·diag) δ = −g`, halve δ until the cost drops.
#[derive(Debug, Default)]
struct GaussNewton;

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

#[test]
fn a_third_backend_passes_the_conformance_checks() {
    let gn = GaussNewton;
    let fixtures = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/optim");
    conformance::check_pose_graphs(&gn, &fixtures).expect("pose graphs");
    conformance::check_local_ba(&gn).expect("local BA");
    conformance::check_object_fit(&gn).expect("object fit");
    conformance::check_bad_start(&gn).expect("bad start");
}
