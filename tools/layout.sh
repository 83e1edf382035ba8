#!/usr/bin/env bash
# A derived layout of an odometry sequence, as a sequence of its own (slam_dataset::layout): the frames
# linked, not copied; the calibration linked; frame times at the sequence's period; the ground-truth
# poses in the same order. `slam-app run OUT/sequences/NN` and `slam-app track-bench --case` take it.
#
#   bash tools/layout.sh there-and-back fixtures/kitti_odom_06/sequences/06 out/tab5 5
#   bash tools/layout.sh standstill fixtures/kitti_odom_06/sequences/06 out/still30 20 30
#   bash tools/layout.sh reversed fixtures/kitti_odom_06/sequences/06 out/back
#
# there-and-back SEQUENCE OUT [LEGS]: the frames forwards, backwards, forwards, ... (LEGS legs, default 5;
# a reversal does not repeat its end frame). standstill SEQUENCE OUT FRAME EXTRA: frame FRAME shown
# EXTRA more times. reversed SEQUENCE OUT: the frames from the last to the first (the street driven the
# other way: `slam-app run OUT/sequences/NN --map` in the forward drive's map). OUT must not exist or be
# empty.
# SEQUENCE and OUT are read from the folder the script is called from.
set -euo pipefail
args=("$@")
for i in 1 2; do
  if [ "$#" -gt "$i" ] && [ -n "${args[i]}" ]; then
    args[i]=$(realpath -m -- "${args[i]}")
  fi
done
cd "$(dirname "$0")/.."
exec cargo run --quiet --release -p slam-dataset --example layout -- ${args[@]+"${args[@]}"}
