#!/usr/bin/env bash
# Idempotent setup for a fresh Debian bookworm machine with a rustup toolchain.
#
# Installs only what is missing:
#   - apt: libopencv-dev (front end), clang + libclang-dev (opencv-rust's binding generator), pkg-config
#   - pip: rust-just (the `just` task runner; optional convenience, CI does not need it)
#   - ONNX Runtime for the detector (docs/detections.md, "ONNX Runtime"): the official `onnxruntime` wheel
#     in a virtual environment .ort/cpu, its libonnxruntime.so recorded in .ort/cpu.path, where slam-app
#     reads it (ORT_DYLIB_PATH, when set, takes precedence). Where nvidia-smi lists a GPU (or with
#     SLAM_ORT_GPU=1) also the `onnxruntime-gpu` wheel with its CUDA and cuDNN wheels in .ort/gpu, recorded in
#     .ort/gpu.path, and the folders of those CUDA libraries in .ort/gpu.libs (for --device cuda).
#   - Python tools for the quadric_slam wheel (crates/slam-py, issue 49), pinned, each in a virtual environment
#     of .py/: build (maturin and ziglang: tools/wheel.sh links the wheel through zig against glibc 2.17) and
#     test (numpy, pytest, ray, pyarrow, matplotlib, rosbags: the Python tests that tools/test.sh runs).
# Prints one line per component and does nothing when everything is present.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
for pkg in libopencv-dev clang libclang-dev pkg-config; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed'; then
    need_apt+=("$pkg")
  fi
done

if [ ${#need_apt[@]} -gt 0 ]; then
  echo "setup: installing with apt: ${need_apt[*]}" >&2
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${need_apt[@]}" >/dev/null
else
  echo "setup: apt packages present (libopencv-dev clang libclang-dev pkg-config)" >&2
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install Rust with rustup first (https://rustup.rs)" >&2
  exit 1
fi

if ! command -v just >/dev/null 2>&1; then
  if command -v pip >/dev/null 2>&1 || command -v pip3 >/dev/null 2>&1; then
    PIP=$(command -v pip || command -v pip3)
    echo "setup: installing just (rust-just) with pip" >&2
    "$PIP" install -q --root-user-action=ignore --disable-pip-version-check rust-just==1.59.0 || echo "setup: could not install just (optional; cargo commands work without it)" >&2
  fi
else
  echo "setup: just present" >&2
fi

# ONNX Runtime. Pinned: 1.32.0 is the runtime the detector was measured and tested with; the GPU wheel's newest
# is 1.31.1. Both are newer than the oldest the build accepts (1.17: the `ort` crate asks for C API 17). Only
# the shared library is used, so the CPU wheel is installed without its Python dependencies (numpy,
# protobuf, ...): 2-3 s and about 80 MB.
ORT_VERSION=1.32.0
ORT_GPU_VERSION=1.31.1
ort_dir=$(pwd)/.ort

# install_runtime NAME PIP_REQUIREMENT [PIP_OPTIONS...]: a virtual environment .ort/NAME with the wheel, and
# the path of its libonnxruntime.so in .ort/NAME.path (written last, so a record always names a whole install)
install_runtime() {
  local name=$1 requirement=$2
  shift 2
  local venv=$ort_dir/$name record=$ort_dir/$name.path
  if [ -f "$record" ] && [ -f "$(cat "$record")" ] && [ -f "$venv/installed" ] && [ "$(cat "$venv/installed")" = "$requirement" ]; then
    echo "setup: ONNX Runtime ($requirement) present: $(cat "$record")" >&2
    return
  fi
  echo "setup: installing ONNX Runtime ($requirement) into $venv" >&2
  rm -rf "$venv" "$record"
  local py
  py=$(command -v python3 || true)
  if [ -z "$py" ]; then
    echo "setup: python3 not found: it is needed to install the $requirement wheel (ONNX Runtime)" >&2
    exit 1
  fi
  if ! "$py" -m venv "$venv" >/dev/null 2>&1; then
    # Debian's own python3 keeps venv in a package of its own
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends python3-venv >/dev/null
    rm -rf "$venv"
    "$py" -m venv "$venv"
  fi
  "$venv/bin/pip" install -q --disable-pip-version-check "$@" "$requirement"
  local lib
  lib=$(find "$venv" -path '*/onnxruntime/capi/libonnxruntime.so*' -type f | sort | head -n 1)
  if [ -z "$lib" ]; then
    echo "setup: the $requirement wheel holds no libonnxruntime.so (looked in $venv)" >&2
    exit 1
  fi
  echo "$requirement" >"$venv/installed"
  echo "$lib" >"$record"
  echo "setup: ONNX Runtime library: $lib (recorded in $record)" >&2
}

install_runtime cpu "onnxruntime==$ORT_VERSION" --no-deps

if [ "${SLAM_ORT_GPU:-}" = 1 ] || { command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L 2>/dev/null | grep -q '^GPU '; }; then
  # the CUDA execution provider needs the CUDA and cuDNN libraries of the wheel's extras; they are not on the
  # loader's path, so slam-app opens them from the folders listed in gpu.libs before it starts the provider
  install_runtime gpu "onnxruntime-gpu[cuda,cudnn]==$ORT_GPU_VERSION"
  find "$ort_dir/gpu" -path '*/site-packages/nvidia/*' -name 'lib*.so*' -printf '%h\n' | sort -u >"$ort_dir/gpu.libs"
  echo "setup: CUDA library folders for --device cuda: $(wc -l <"$ort_dir/gpu.libs") (listed in $ort_dir/gpu.libs)" >&2
else
  echo "setup: no GPU found (nvidia-smi lists none): the GPU runtime is not installed (SLAM_ORT_GPU=1 installs it)" >&2
fi

# Python environments of the quadric_slam wheel (issue 49). Pinned: the versions the wheel was built and tested
# with. ray's wheel is the large one (about 70 MB to download, 500 MB installed with its dependencies).
PY_BUILD="maturin==1.16.0 ziglang==0.17.1"
PY_TEST="numpy==2.4.6 pytest==9.2.0 ray==2.60.0 pyarrow==26.0.1 matplotlib==3.11.2 rosbags==0.11.9"

# install_python_env NAME REQUIREMENTS: a virtual environment .py/NAME holding them, recorded in .py/NAME/installed
install_python_env() {
  local name=$1 requirements=$2
  local venv
  venv=$(pwd)/.py/$name
  if [ -f "$venv/installed" ] && [ "$(cat "$venv/installed")" = "$requirements" ] && [ -x "$venv/bin/python" ]; then
    echo "setup: Python environment .py/$name present ($requirements)" >&2
    return
  fi
  echo "setup: installing $requirements into .py/$name" >&2
  rm -rf "$venv"
  mkdir -p "$(dirname "$venv")"
  if ! python3 -m venv "$venv" >/dev/null 2>&1; then
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends python3-venv >/dev/null
    rm -rf "$venv"
    python3 -m venv "$venv"
  fi
  # shellcheck disable=SC2086
  "$venv/bin/pip" install -q --disable-pip-version-check $requirements
  echo "$requirements" >"$venv/installed"
}

install_python_env build "$PY_BUILD"
install_python_env test "$PY_TEST"
