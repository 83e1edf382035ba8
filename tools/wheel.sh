#!/usr/bin/env bash
# Build the Python wheel of the geometry crate (crates/slam-py, module quadric_slam) into target/wheels/:
# maturin, release, abi3 (one wheel for CPython 3.9 and later), linked through zig against glibc 2.17 so
# that it is manylinux2014 and installs on any x86-64 Linux of the last decade; compiled for the baseline
# x86-64 target (no -C target-cpu: the wheel must run on every x86-64 CPU; crates/slam-py/tests checks its
# disassembly). maturin and zig come from tools/setup.sh's .py/build. Prints the wheel's path last.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .py/build/bin/maturin ]; then
  bash tools/setup.sh
fi
case " ${RUSTFLAGS:-} ${CARGO_ENCODED_RUSTFLAGS:-} " in
  *target-cpu*)
    echo "wheel.sh: RUSTFLAGS set a target CPU (${RUSTFLAGS:-}${CARGO_ENCODED_RUSTFLAGS:-}); the wheel must be built for baseline x86-64" >&2
    exit 1
    ;;
esac
mkdir -p target/wheels
rm -f target/wheels/quadric_slam-*.whl
# maturin runs zig through the Python it finds: the build environment's
PATH="$(pwd)/.py/build/bin:$PATH" VIRTUAL_ENV="$(pwd)/.py/build" \
  maturin build --release --zig --quiet -m crates/slam-py/Cargo.toml -o target/wheels >&2
ls target/wheels/quadric_slam-*.whl
