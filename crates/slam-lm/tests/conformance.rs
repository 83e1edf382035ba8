//! Levenberg–Marquardt passes the optimiser conformance suite, and keeps its anchor iteration counts.

use std::path::PathBuf;

use slam_lm::LevenbergMarquardt;
use slam_optim::{conformance, io::read_g2o, Optimizer, Options};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/optim")
}

#[test]
fn lm_passes_the_conformance_suite() {
    conformance::check_all(&LevenbergMarquardt::default(), &fixtures()).expect("LM conformance");
}

#[test]
fn problem_16_l2_in_ten_iterations() {
    let s = conformance::check_bal(&LevenbergMarquardt::default(), &fixtures()).expect("BAL");
    assert!(s.iterations <= 10, "{s:?}");
}

/// The pose-graph preset reaches both minima in ≤ 8 iterations; the BA defaults (strong Marquardt
/// damping) get there too, in more.
#[test]
fn pose_graph_iterations() {
    for (file, minimum) in [("sphere2500.g2o", 6.757010e+02), ("parking-garage.g2o", 6.341924e-01)] {
        for (options, cap) in [(Options::pose_graph(), 8), (Options::default(), 100)] {
            let mut p = read_g2o(fixtures().join(file)).expect("reads");
            p.graph.fix(p.cameras[0]);
            let s = LevenbergMarquardt::default().optimize(&p.graph, &mut p.values, &options, None).expect("solves");
            assert!((s.final_cost - minimum).abs() < 1e-3 * minimum, "{file}: {s:?}");
            assert!(s.iterations <= cap, "{file}: {s:?}");
        }
    }
}
