#!/usr/bin/env bash
# The main job: the whole system (stereo tracking, local mapping, the shipped detector, objects) on the
# shipped KITTI odometry sequence 06 (frames 0-50), writing the trajectory, map, object map, a top-down map
# picture and an overlay every 5 frames to out/run/, and printing ATE/RPE against the ground truth. Extra
# arguments go to `slam-app run` (e.g. a path to another KITTI sequence, --out DIR, --detector none).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
cargo run --release -q -p slam-app -- run --overlays --overlay-every 5 --overlay-format jpg "$@"
