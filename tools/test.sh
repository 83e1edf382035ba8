#!/usr/bin/env bash
# Run every test of the workspace on a fresh machine: installs what is missing, checks the crate
# layering, then runs the whole test suite in release mode (faer/nalgebra are ~100x slower in debug).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
bash tools/check-deps.sh
cargo test --release --workspace --features slam-quadric/serde "$@"
