#!/usr/bin/env bash
# Build the Ceres side of tools/ceres-vs-ours.sh (not part of CI).
# Needs Ceres 2.1 (Debian: apt-get install -y libceres-dev) and g++.
# Output: tools/ceres-bench/build/ceres_bal (the build folder is git-ignored).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
mkdir -p "$here/build"
if [ ! -f /usr/include/ceres/ceres.h ]; then
  echo "Ceres headers not found: apt-get install -y libceres-dev" >&2
  exit 1
fi
g++ -O3 -march=native -DNDEBUG -std=c++17 "$here/ceres_bal.cc" -o "$here/build/ceres_bal" \
  -I/usr/include/eigen3 -lceres -lglog -lgflags -lpthread
echo "built $here/build/ceres_bal"
