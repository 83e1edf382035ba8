#!/usr/bin/env bash
# The optional third command: the main job (tools/run.sh) with a rerun recording of the run, out/run.rrd
# (the frame timeline: images with boxes and projected ellipsoids, camera and frustum, estimated and
# ground-truth trajectories, map points, ellipsoids, tracking state). slam-app is built with its feature
# `rerun` (rerun's SDK: a longer first build, see README). Open the recording with `rerun out/run.rrd`
# (`pip install rerun-sdk==0.36.3`). Extra arguments go to `slam-app run`; `--rerun FILE` picks another file.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
rrd=out/run.rrd
for arg in "$@"; do
  case "$arg" in --rerun | --rerun=*) rrd="" ;; esac
done
mkdir -p out
cargo run --release -q -p slam-app --features rerun -- run --overlays --overlay-every 5 --overlay-format jpg \
  ${rrd:+--rerun "$rrd"} "$@"
