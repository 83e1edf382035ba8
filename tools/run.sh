#!/usr/bin/env bash
# The main job. Until the stereo front end lands this is the geometry example: project a car-sized
# ellipsoid into a KITTI camera and print its box, clipped box and a Jacobian entry.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
cargo run --release -q -p slam-quadric --example project_ellipsoid -- "$@"
