//! Powell's dog-leg passes the optimiser conformance suite.

use std::path::PathBuf;

use slam_dogleg::DogLeg;
use slam_optim::conformance;

#[test]
fn dogleg_passes_the_conformance_suite() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/optim");
    conformance::check_all(&DogLeg::default(), &dir).expect("dog-leg conformance");
}
