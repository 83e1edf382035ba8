#!/usr/bin/env bash
# Idempotent setup for a fresh Debian bookworm machine with a rustup toolchain.
#
# Installs only what is missing:
#   - apt: libopencv-dev (front end), clang + libclang-dev (opencv-rust's binding generator), pkg-config
#   - pip: rust-just (the `just` task runner; optional convenience, CI does not need it)
# Prints one line per component and does nothing when everything is present.
set -euo pipefail

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
