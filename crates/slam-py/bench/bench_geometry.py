"""Speed of quadric_slam against the Rust loop it wraps (a benchmark that prints, not a test).

    .py/test/bin/python crates/slam-py/bench/bench_geometry.py [N]

Prints, for one projection (``quadric_slam.project`` of an Ellipsoid and a Camera built once), the time of
a Python call against ``slam_quadric::project`` in a Rust loop (the example ``projection_loop``, run with
cargo): their difference is the call's overhead (target <= 5 us). And for N ellipsoids (default 10 000)
in one vectorised call (``project_many``, and ``bounds_many`` with the exact clipped boxes) against the
Rust loop over the same scene (target <= 2x). Each figure is the fastest of several repeats.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import quadric_slam as qs

REPO = Path(__file__).resolve().parents[3]
K = [[721.5377, 0.0, 609.5593], [0.0, 721.5377, 172.854], [0.0, 0.0, 1.0]]
IMAGE = (1242.0, 375.0)


def scene(n: int):
    """The scene of the Rust example projection_loop: a grid 20 m wide, 10-50 m ahead, each ellipsoid
    turned about the vertical by 0.1 i rad and scaled by 1 + 0.2 sin i."""
    i = np.arange(n)
    poses = np.tile(np.eye(4), (n, 1, 1))
    c, s = np.cos(0.1 * i), np.sin(0.1 * i)
    poses[:, 0, 0], poses[:, 0, 2], poses[:, 2, 0], poses[:, 2, 2] = c, s, -s, c
    poses[:, 0, 3] = -10.0 + 20.0 * (i % 100) / 100.0
    poses[:, 1, 3] = 1.0
    poses[:, 2, 3] = 10.0 + 40.0 * ((i // 100) % 100) / 100.0
    k = 1.0 + 0.2 * np.sin(i)
    axes = np.stack([2.1 * k, 0.8 * k, 0.85 * k], axis=1)
    return poses, axes


def best(repeats: int, f) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def rust(n: int, repeats: int) -> dict:
    cmd = ["cargo", "run", "--release", "-q", "-p", "slam-quadric", "--example", "projection_loop", "--", str(n), str(repeats)]
    line = subprocess.run(cmd, cwd=REPO, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1]
    return {k: float(v) for k, v in re.findall(r"(\w+)=([0-9.]+)", line)}


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10_000
    repeats = 50
    r = rust(n, repeats)
    camera = qs.Camera(K)
    poses, axes = scene(n)
    car = qs.Ellipsoid(poses[0], axes[0])
    calls = 100_000
    single = best(5, lambda: [qs.project(car, camera) for _ in range(calls)]) / calls
    many = best(repeats, lambda: qs.project_many(poses, axes, camera, errors="nan"))
    clipped = best(repeats, lambda: qs.bounds_many(poses, axes, camera, IMAGE, errors="nan"))
    rust_one = r["project_ns_each"] * 1e-9
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; quadric_slam {qs.__version__}")
    print(f"one projection: Python call {single * 1e6:.3f} us, Rust {rust_one * 1e6:.3f} us: overhead {(single - rust_one) * 1e6:.3f} us (target <= 5 us)")
    print(f"{n} projections: project_many {many * 1e3:.3f} ms, Rust loop {r['project_ms']:.3f} ms: {many * 1e3 / r['project_ms']:.2f}x (target <= 2x)")
    print(f"{n} clipped boxes: bounds_many {clipped * 1e3:.3f} ms, Rust loop {r['clipped_ms']:.3f} ms: {clipped * 1e3 / r['clipped_ms']:.2f}x")


if __name__ == "__main__":
    main()
