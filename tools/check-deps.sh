#!/usr/bin/env bash
# Layering checks (docs/architecture.md), on normal (not dev-) dependencies, from Cargo.lock alone:
#  1. slam-quadric's normal dependencies are nalgebra only, plus serde behind its feature;
#  2. nothing below the front end links OpenCV or ONNX Runtime (the `ort` crate); ONNX Runtime is the
#     detector's (slam-detect) alone: the tracker (slam-frontend) and the crates that use it without the
#     detector (slam-viz, slam-rerun) link none, and no crate but slam-detect names `ort` itself;
#  3. the seam crates (slam-map, slam-core, slam-optim) depend on no implementation crate;
#  4. implementation crates depend on seams only (slam-quadric, slam-map, slam-core, slam-optim), never on
#     each other, but for the detector (slam-detect), which reads and converts its images through the
#     front end's image I/O (slam-frontend::image_io) rather than keeping a second copy of it.
# Composition crates (slam-pipeline, slam-sim, slam-eval, slam-studies, slam-viz, slam-runner, slam-app) may combine
# implementations;
#  5. slam-eval and everything below the front end stay free of OpenCV; slam-viz (pictures, above the
#     front end) is used by slam-runner and slam-app only;
#  6. slam-runner (the run-related commands' work, and the names of the implementations behind the seams)
#     sits directly under slam-app: nothing else depends on it;
#  7. slam-py (the Python module quadric_slam) depends on slam-quadric, pyo3 and numpy only, so that its
#     wheel builds without OpenCV or ONNX Runtime; nothing depends on it.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_NET_OFFLINE=true

direct() { cargo tree -q -e normal --depth 1 --prefix none "$@" | tail -n +2 | awk '{print $1}' | sort -u | tr '\n' ' '; }

plain=$(direct -p slam-quadric)
if [ "$plain" != "nalgebra " ]; then
  echo "check-deps: slam-quadric must depend on nalgebra only; found: $plain" >&2
  exit 1
fi
with_serde=$(direct -p slam-quadric --features serde)
if [ "$with_serde" != "nalgebra serde " ]; then
  echo "check-deps: slam-quadric with --features serde must add serde only; found: $with_serde" >&2
  exit 1
fi
echo "check-deps: slam-quadric depends on [ ${plain}] (+ serde with the serde feature): ok"

# Nothing below the front end links OpenCV or ONNX Runtime: the detector's runtimes stay in slam-detect.
for crate in slam-quadric slam-map slam-core slam-assoc slam-optim slam-lm slam-dogleg slam-dataset slam-sim slam-pipeline slam-studies slam-eval; do
  tree=$(cargo tree -q -p "$crate" --all-features -e normal --prefix none)
  for lib in opencv ort; do
    if echo "$tree" | grep -q "^$lib "; then
      echo "check-deps: $crate must not depend on $lib" >&2
      exit 1
    fi
  done
done
# The tracker and the crates that use it without the detector link no ONNX Runtime at all (default
# features: rerun's crates are downloaded only where that feature was built)
for crate in slam-frontend slam-viz slam-rerun; do
  if cargo tree -q -p "$crate" -e normal --prefix none | grep -q "^ort "; then
    echo "check-deps: $crate must not depend on ort (ONNX Runtime belongs to the detector, slam-detect)" >&2
    exit 1
  fi
done
# and of the crates above the detector, none uses ort directly: they reach it through slam-detect's API
for crate in slam-runner slam-app; do
  if direct -p "$crate" | tr ' ' '\n' | grep -qx ort; then
    echo "check-deps: $crate must not depend on ort directly (ONNX Runtime belongs to slam-detect)" >&2
    exit 1
  fi
done
echo "check-deps: no OpenCV or ONNX Runtime below slam-frontend (nor in slam-eval), no ONNX Runtime in slam-frontend, slam-viz or slam-rerun, ort used by slam-detect only: ok"

# Workspace crates a crate depends on directly (normal dependencies, all features).
workspace_deps() { direct -p "$1" --all-features | tr ' ' '\n' | grep '^slam-' | tr '\n' ' ' || true; }

check_only() { # crate, allowed workspace dependencies...
  local crate=$1
  shift
  for dep in $(workspace_deps "$crate"); do
    local ok=0
    for allowed in "$@"; do
      [ "$dep" = "$allowed" ] && ok=1
    done
    if [ $ok = 0 ]; then
      echo "check-deps: $crate must not depend on $dep (allowed: $*)" >&2
      exit 1
    fi
  done
}

seams="slam-quadric slam-map slam-core slam-optim"
check_only slam-map slam-quadric
check_only slam-core slam-quadric slam-map
check_only slam-optim slam-quadric slam-core slam-map
echo "check-deps: the seams (slam-map, slam-core, slam-optim) depend on no implementation crate: ok"
for crate in slam-assoc slam-dataset slam-frontend slam-lm slam-dogleg; do
  # shellcheck disable=SC2086
  check_only "$crate" $seams
done
# the detector reads and converts its images through the tracker's crate (slam-frontend::image_io), one
# way only: slam-frontend knows nothing of it
# shellcheck disable=SC2086
check_only slam-detect $seams slam-frontend
echo "check-deps: implementation crates (slam-assoc, slam-dataset, slam-frontend, slam-lm, slam-dogleg) depend on seams only, slam-detect on seams and slam-frontend: ok"

# slam-studies (the benchmarks and studies of the reusable crates) composes the optimiser seam and the
# associators only: the libraries it studies stay free of it, and it of the running system.
check_only slam-studies slam-quadric slam-core slam-optim slam-assoc
echo "check-deps: slam-studies depends on [ $(workspace_deps slam-studies)]: ok"

# slam-viz sits near the top, under slam-runner, slam-rerun and the app only: no other library crate depends on it.
for crate in slam-quadric slam-core slam-assoc slam-optim slam-lm slam-dogleg slam-dataset slam-sim slam-pipeline slam-studies slam-eval slam-frontend slam-detect; do
  if workspace_deps "$crate" | tr ' ' '\n' | grep -qx slam-viz; then
    echo "check-deps: $crate must not depend on slam-viz (pictures are for the app)" >&2
    exit 1
  fi
done
check_only slam-viz slam-quadric slam-core slam-sim slam-pipeline slam-frontend
echo "check-deps: slam-viz depends on [ $(workspace_deps slam-viz)] and only slam-runner, slam-rerun and slam-app depend on it: ok"

# slam-runner sits directly under the app: no library crate depends on it.
for crate in slam-quadric slam-core slam-assoc slam-optim slam-lm slam-dogleg slam-dataset slam-sim slam-pipeline slam-studies slam-eval slam-frontend slam-detect slam-viz; do
  if workspace_deps "$crate" | tr ' ' '\n' | grep -qx slam-runner; then
    echo "check-deps: $crate must not depend on slam-runner (only slam-app may)" >&2
    exit 1
  fi
done
# (it names the implementations behind the seams, `wiring`: the backends and associators it may build)
check_only slam-runner slam-quadric slam-map slam-core slam-optim slam-dataset slam-frontend slam-detect slam-pipeline slam-eval slam-viz \
  slam-sim slam-assoc slam-lm slam-dogleg
echo "check-deps: slam-runner depends on [ $(workspace_deps slam-runner)] and only slam-app depends on it: ok"

# slam-rerun (recordings) sits directly under the app, beside slam-runner: no library crate depends on it,
# and it composes the pipeline, the pictures' rules and the front end's image encoding only. Its rerun
# crates are optional (feature rerun), so its own checks read its default dependencies: a machine that
# never built the feature has not downloaded them.
for crate in slam-quadric slam-core slam-assoc slam-optim slam-lm slam-dogleg slam-dataset slam-sim slam-pipeline slam-studies slam-eval slam-frontend slam-detect slam-viz slam-runner; do
  if workspace_deps "$crate" | tr ' ' '\n' | grep -qx slam-rerun; then
    echo "check-deps: $crate must not depend on slam-rerun (only slam-app may)" >&2
    exit 1
  fi
  # rerun's crates (re_sdk, re_sdk_types, re_log_encoding, ...) enter through slam-rerun's feature alone
  if cargo tree -q -p "$crate" --all-features -e normal --prefix none | grep -q '^re_'; then
    echo "check-deps: $crate must not depend on rerun's crates (they belong to slam-rerun's feature rerun)" >&2
    exit 1
  fi
done
rerun_deps=$(direct -p slam-rerun)
for dep in $(echo "$rerun_deps" | tr ' ' '\n' | grep '^slam-' || true); do
  case " slam-quadric slam-map slam-core slam-pipeline slam-viz slam-frontend " in
    *" $dep "*) ;;
    *) echo "check-deps: slam-rerun must not depend on $dep (allowed: slam-quadric slam-map slam-core slam-pipeline slam-viz slam-frontend)" >&2; exit 1 ;;
  esac
done
if echo "$rerun_deps" | tr ' ' '\n' | grep -q '^re_'; then
  echo "check-deps: slam-rerun must depend on rerun's crates only with its feature rerun; found: $rerun_deps" >&2
  exit 1
fi
echo "check-deps: slam-rerun depends on [ $(echo "$rerun_deps" | tr ' ' '\n' | grep '^slam-' | tr '\n' ' ')] (+ rerun's crates with its feature rerun), and only slam-app depends on it: ok"

# slam-py, the Python module of the geometry: slam-quadric, pyo3 and numpy only (the wheel builds on a machine
# without OpenCV, ONNX Runtime or any other crate of the system), and no crate depends on it.
py_deps=$(direct -p slam-py --all-features)
if [ "$py_deps" != "numpy pyo3 slam-quadric " ]; then
  echo "check-deps: slam-py must depend on slam-quadric, pyo3 and numpy only; found: $py_deps" >&2
  exit 1
fi
for dep in $(cargo tree -q -p slam-py --all-features -e normal --prefix none | awk '{print $1}' | sort -u); do
  case "$dep" in
    opencv|ort|re_*) echo "check-deps: slam-py must not depend on $dep (the wheel needs no OpenCV, ONNX Runtime or rerun)" >&2; exit 1 ;;
    slam-py|slam-quadric) ;;
    slam-*) echo "check-deps: slam-py must not depend on $dep (only the geometry crate)" >&2; exit 1 ;;
  esac
done
for crate in $(cargo metadata -q --offline --no-deps --format-version 1 | python3 -c 'import json,sys; print(" ".join(p["name"] for p in json.load(sys.stdin)["packages"]))'); do
  if [ "$crate" != slam-py ] && workspace_deps "$crate" | tr ' ' '\n' | grep -qx slam-py; then
    echo "check-deps: $crate must not depend on slam-py (the Python module is a leaf)" >&2
    exit 1
  fi
done
echo "check-deps: slam-py depends on [ $py_deps] (no OpenCV, no ONNX Runtime, no other slam crate), and no crate depends on it: ok"
