#!/usr/bin/env bash
# The main job: stereo odometry on the shipped KITTI odometry sequence 06 (frames 0-50), writing the
# trajectory to out/run/ and printing ATE/RPE against the ground truth. Extra arguments go to
# `slam-app run` (e.g. a path to another KITTI odometry sequence, --out DIR).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
cargo run --release -q -p slam-app -- run "$@"
