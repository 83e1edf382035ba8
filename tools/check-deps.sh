#!/usr/bin/env bash
# Layering check: slam-quadric's normal dependencies are nalgebra only, plus serde behind its feature.
set -euo pipefail
cd "$(dirname "$0")/.."

direct() { cargo tree -q -p slam-quadric -e normal --depth 1 --prefix none "$@" | tail -n +2 | awk '{print $1}' | sort -u | tr '\n' ' '; }

plain=$(direct)
if [ "$plain" != "nalgebra " ]; then
  echo "check-deps: slam-quadric must depend on nalgebra only; found: $plain" >&2
  exit 1
fi
with_serde=$(direct --features serde)
if [ "$with_serde" != "nalgebra serde " ]; then
  echo "check-deps: slam-quadric with --features serde must add serde only; found: $with_serde" >&2
  exit 1
fi
echo "check-deps: slam-quadric depends on [ ${plain}] (+ serde with the serde feature): ok"

# Nothing below the front end links OpenCV.
for crate in slam-quadric slam-core slam-assoc slam-optim slam-dataset slam-sim; do
  if cargo tree -q -p "$crate" --all-features -e normal --prefix none | grep -q '^opencv '; then
    echo "check-deps: $crate must not depend on opencv" >&2
    exit 1
  fi
done
echo "check-deps: no OpenCV below slam-frontend: ok"
