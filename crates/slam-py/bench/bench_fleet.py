"""How the fleet scales on this machine (a benchmark that prints, not a test).

    PATH=target/release:$PATH .py/test/bin/python crates/slam-py/bench/bench_fleet.py [OUT]

Eight drive excerpts (odometry 06 and 01 in halves, drive 0005 in quarters, the shipped detector) mapped
by ``quadric_slam.fleet.map_drives`` with 2 Ray workers (a local cluster of 2 CPUs, one CPU a task).
Prints:

* the wall time against the floor the cores set: the runs' summed CPU time (user + system of each
  slam-app, from wait4) over the 2 cores (target: wall <= 1.15x that);
* Ray's overhead per task: from the moment a task could have started (its submission, or the end of the
  task before it in the same CPU slot) to its start in the worker, plus the task's own work around the
  run (temporary folder, archive), plus the time from its end to the driver holding its result (target
  <= 0.5 s per task, mean and largest printed).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import ray

from quadric_slam import fleet

REPO = Path(__file__).resolve().parents[3]
ODO6 = "fixtures/kitti_odom_06/sequences/06"
ODO1 = "fixtures/kitti_odom_01/sequences/01"
RAW5 = "fixtures/kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync"
DRIVES = [
    (ODO6, "0..25"),
    (ODO6, "25..51"),
    (ODO1, "0..25"),
    (ODO1, "25..51"),
    (RAW5, "0..23"),
    (RAW5, "23..46"),
    (RAW5, "46..69"),
    (RAW5, "69..91"),
]
WORKERS = 2


def overheads(rows) -> list:
    """Each task's overhead (module docstring), with the tasks in start order on WORKERS slots."""
    tasks = sorted((r.timing for r in rows if r.status == "done"), key=lambda t: t["task_start"])
    free = [min(t["submitted"] for t in tasks)] * WORKERS
    out = []
    for t in tasks:
        slot = min(range(WORKERS), key=lambda k: free[k])
        ready = max(free[slot], t["submitted"])
        start_latency = max(0.0, t["task_start"] - ready)
        around_run = (t["run_start"] - t["task_start"]) + (t["task_end"] - t["run_end"])
        gather = t["received"] - t["task_end"]
        out.append(start_latency + around_run + gather)
        free[slot] = t["task_end"]
    return out


def main() -> None:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="fleet-bench-")) / "fleet"
    drives = [fleet.Drive(str(REPO / path), ("--frames", frames)) for path, frames in DRIVES]
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores before the run")
    # the workers at niceness 0, as map_drives' own local cluster has them (Ray's default is 15)
    ray.init(
        num_cpus=WORKERS,
        include_dashboard=False,
        logging_level="warning",
        log_to_driver=False,
        _system_config={"worker_niceness": 0},
    )
    try:
        # warm the workers' imports, as a long-lived cluster has them
        ray.get([ray.remote(lambda: __import__("quadric_slam.fleet")).remote() for _ in range(WORKERS)])
        t = time.time()
        rows = fleet.map_drives(drives, out, cwd=REPO, progress=False)
        wall = time.time() - t
    finally:
        ray.shutdown()
    failed = [r.drive for r in rows if r.status != "done"]
    if failed:
        sys.exit(f"drives failed: {failed}; see {out}")
    cpu = sum(r.cpu_s for r in rows)
    floor = cpu / WORKERS
    each = overheads(rows)
    print(f"{len(rows)} drives, {sum(r.frames for r in rows)} frames, {WORKERS} Ray workers; results in {out}")
    for r in rows:
        print(f"  {r.drive}: {r.frames} frames, {r.time_s:.2f} s wall, {r.cpu_s:.2f} s CPU on {r.node}")
    busy = sum(r.time_s for r in rows)
    print(f"the runs' own CPU share: {cpu / busy:.2f} of a core each on average (CPU over wall time of each slam-app);"
          f" load average {os.getloadavg()[0]:.2f} after the run")
    print(f"wall {wall:.2f} s; floor {floor:.2f} s (summed CPU {cpu:.2f} s / {WORKERS} cores): {wall / floor:.3f}x (target <= 1.15x)")
    print(f"Ray's overhead per task: mean {sum(each) / len(each):.3f} s, largest {max(each):.3f} s (target <= 0.5 s)")


if __name__ == "__main__":
    main()
