#!/usr/bin/env bash
# Run every test of the workspace on a fresh machine: installs what is missing, checks the crate
# layering and that a crate's files do not import each other in a circle, then runs
# the whole test suite in release mode (faer/nalgebra are ~100x slower in debug).
# The suite is built with slam-app's feature `rerun`, so that the rerun recording test (a recording of
# the shipped excerpt read back with rerun's own decoder) runs in CI too; rerun's SDK adds about 12-17
# minutes to a first build on 2 cores (README, "A run in 3-D"). SLAM_TEST_RERUN=0 leaves it out (the
# tests then check that --rerun is refused without the feature).
# Then the Python tests (issue 49, crates/slam-py/tests): the quadric_slam wheel built once (tools/wheel.sh),
# installed into .py/test (tools/setup.sh), and pytest against it: the oracle vectors against the Rust
# crate, bad input, the wheel's portability and a fresh virtual environment, load_run on the main job's
# output, the fleet on a local two-node Ray cluster with one broken drive.
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
  cargo test --release -p slam-detect --test gpu -- --ignored
else
  echo "test.sh: the detector's CUDA test (slam-detect, tests/gpu.rs) skipped: no GPU found (nvidia-smi lists none)"
fi
# the Python module and the fleet, against the wheel as a user installs it
start=$(date +%s)
wheel=$(bash tools/wheel.sh | tail -n 1)
.py/test/bin/pip install -q --disable-pip-version-check --force-reinstall --no-deps "$wheel"
echo "test.sh: wheel built and installed in $(( $(date +%s) - start )) s: $wheel"
# the geometry crate's example that writes its values on the oracle's inputs, as the suite above built it
# (already fresh: this only asks cargo for its path; cargo run -p slam-quadric would build the crate and
# nalgebra again with other features, minutes on a clean clone)
oracle_values=$(cargo test --release --workspace --features "$features" --no-run --message-format=json 2>/dev/null |
  python3 -c 'import json, sys
for m in map(json.loads, sys.stdin):
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "oracle_values" and m.get("executable"):
        print(m["executable"])')
SLAM_APP="$(pwd)/target/release/slam-app" QUADRIC_SLAM_WHEEL="$(pwd)/$wheel" ORACLE_VALUES="$oracle_values" \
  .py/test/bin/python -m pytest -q -p no:cacheprovider --durations=5 crates/slam-py/tests
echo "test.sh: the Python tests took $(( $(date +%s) - start )) s with the wheel's build"
