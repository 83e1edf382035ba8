# Task runner recipes (install `just` with `pip install rust-just`, or tools/setup.sh does it).
# CI does not depend on just: .ci/run calls tools/test.sh directly.

# The main job (README).
run *ARGS:
    bash tools/run.sh {{ARGS}}

# All tests (README), including setup and the layering check.
test:
    bash tools/test.sh

# Tests of one crate, release mode: `just test-pkg slam-quadric`.
test-pkg PKG:
    cargo test --release -p {{PKG}}

# Formatting, clippy with warnings as errors.
lint:
    cargo fmt --all -- --check
    cargo clippy --release --workspace --all-targets -- -D warnings

# Layering check: slam-quadric depends on nalgebra only.
deps-check:
    bash tools/check-deps.sh
    python3 tools/module-cycles.py crates/*/src

# Micro-benchmarks of the geometry crate (criterion).
bench:
    cargo bench -p slam-quadric --bench quadric

# Fuzz every parser for 20 s each (cargo-fuzz on the stable toolchain via RUSTC_BOOTSTRAP).
fuzz:
    cd crates/slam-dataset && for t in tracking_labels calib kitti_poses tum tracklets oxts timestamps detections bal g2o; do RUSTC_BOOTSTRAP=1 cargo fuzz run $t -- -max_total_time=20; done
