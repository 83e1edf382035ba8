//! Levenberg–Marquardt passes the optimiser conformance suite, and keeps its anchor iteration counts.

use std::path::PathBuf;

use slam_lm::LevenbergMarquardt;
use slam_optim::{conformance, io::read_g2o, Optimizer, Options};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/optim")
}

/// `conformance::check_all`, split in two tests so they run in parallel; problem-16 L2 also in ≤ 10
/// iterations (the anchors' pass criterion).
#[test]
fn lm_passes_the_conformance_bal_checks_and_problem_16_in_ten_iterations() {
    let s = conformance::check_bal(&LevenbergMarquardt::default(), &fixtures()).expect("BAL");
    assert!(s.iterations <= 10, "{s:?}");
}

#[test]
fn lm_passes_the_other_conformance_checks() {
    let lm = LevenbergMarquardt::default();
    conformance::check_pose_graphs(&lm, &fixtures()).expect("pose graphs");
    conformance::check_object_fit(&lm).expect("object fit");
    conformance::check_local_ba(&lm).expect("local BA");
    conformance::check_sparse_matches_dense(&lm).expect("sparse vs dense");
    conformance::check_bad_start(&lm).expect("bad start");
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

/// `optim-bench --generated`'s solve: both forced paths lower the cost to the same minimum, and say
/// which path they took.
#[test]
fn the_benchmarks_generated_solve_agrees_on_both_paths() {
    let lm = LevenbergMarquardt::default();
    let dense = slam_studies::optim_bench::generated_solve(&lm, 6, 2, true).expect("dense");
    let sparse = slam_studies::optim_bench::generated_solve(&lm, 6, 2, false).expect("sparse");
    assert!(!dense.sparse && sparse.sparse, "{dense:?} {sparse:?}");
    assert!(dense.final_cost < dense.initial && sparse.final_cost < sparse.initial);
    assert!((dense.final_cost - sparse.final_cost).abs() <= 1e-6 * dense.final_cost.max(1.0));
}
