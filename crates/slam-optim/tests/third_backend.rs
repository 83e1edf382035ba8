//! The third backend of docs/architecture.md (`examples/gauss_newton.rs`, under 100 lines, written
//! against the seam only) passes the conformance checks.

#[path = "../examples/gauss_newton.rs"]
#[allow(dead_code)] // the example's `main`
mod gauss_newton;

use gauss_newton::GaussNewton;
use slam_optim::conformance;

#[test]
fn a_third_backend_passes_the_conformance_suite() {
    let fixtures = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/optim");
    conformance::check_all(&GaussNewton, &fixtures).expect("conformance");
}
