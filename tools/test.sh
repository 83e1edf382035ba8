#!/usr/bin/env bash
# Run every test of the workspace on a fresh machine: installs what is missing, checks the crate
# layering and that a crate's files do not import each other in a circle, then runs
# the whole test suite in release mode (faer/nalgebra are ~100x slower in debug).
# The suite is built with slam-app's feature `rerun`, so that the rerun recording test (a recording of
# the shipped excerpt read back with rerun's own decoder) runs in CI too; rerun's SDK adds about 12-17
# minutes to a first build on 2 cores (README, "A run in 3-D"). SLAM_TEST_RERUN=0 leaves it out (the
# tests then check that --rerun is refused without the feature).
# tools/setup.sh installs ONNX Runtime (the detector's runtime) into .ort/ first. The detector's CUDA test
# needs a GPU: a plain cargo test lists it as ignored; it runs here, after the suite, where nvidia-smi lists
# a GPU (setup then installed the GPU runtime too).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
bash tools/check-deps.sh
# no import circle among the files of any crate (issue 40; tools/module-cycles.py)
python3 tools/module-cycles.py crates/*/src
features=slam-quadric/serde
if [ "${SLAM_TEST_RERUN:-1}" != 0 ]; then
  features="$features,slam-app/rerun"
fi
cargo test --release --workspace --features "$features" "$@"
if command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L 2>/dev/null | grep -q '^GPU '; then
  cargo test --release -p slam-frontend --test gpu -- --ignored
else
  echo "test.sh: the detector's CUDA test (slam-frontend, tests/gpu.rs) skipped: no GPU found (nvidia-smi lists none)"
fi
