"""The fleet on a two-node Ray cluster on this machine: four drive excerpts mapped with results identical
to sequential slam-app runs, one broken drive reported with its error after its second attempt, the
summary table as CSV and Parquet.

The cluster: ``ray start --head`` and a second ``ray start --address``, both on a loopback address, one CPU
each. (Ray replaces 127.0.0.1 given as a node's address by the machine's network address, so the nodes
use 127.0.0.2, which is loopback too.) Both run in the foreground (``--block``) as this test's own
processes and are stopped by their ids.
"""

from __future__ import annotations

import csv
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from bagmaker import write_bag

from quadric_slam import fleet

LOOPBACK = "127.0.0.2"

EXCERPTS = [
    ("fixtures/kitti_odom_06/sequences/06", ("--frames", "0..12")),
    ("fixtures/kitti_odom_06/sequences/06", ("--frames", "20..32")),
    ("fixtures/kitti_odom_01/sequences/01", ("--frames", "0..12")),
    ("fixtures/kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync", ("--frames", "0..12")),
]
SAME_FILES = ("trajectory.kitti.txt", "trajectory.tum.txt", "map.json", "map.features", "objects.json", "camera.json")


def free_port() -> int:
    with socket.socket() as s:
        s.bind((LOOPBACK, 0))
        return s.getsockname()[1]


def listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(1.0)
        return s.connect_ex((LOOPBACK, port)) == 0


@pytest.fixture(scope="module")
def cluster():
    """A head node and a worker node, one CPU each; yields the head's address."""
    ray = Path(sys.executable).with_name("ray")
    tmp = tempfile.mkdtemp(prefix="rt", dir="/tmp")  # Ray's socket paths must stay short
    # workers at niceness 0 (Ray's default 15 makes the runs yield to anything else on the machine); no
    # token authentication on this loopback-only cluster (Ray turns it on when ~/.ray/auth_token exists, and
    # the driver in this process must then hold the same token); stopped at once (on SIGTERM a node first
    # asks the head to drain it, for up to 30 s, which with the head stopped at the same time is 30 s lost)
    env = dict(
        os.environ,
        RAY_TMPDIR=tmp,
        RAY_USAGE_STATS_ENABLED="0",
        RAY_worker_niceness="0",
        RAY_AUTH_MODE="disabled",
        RAY_GRACEFUL_SHUTDOWN_DRAIN_TIMEOUT_S="0",
    )
    saved_mode = os.environ.get("RAY_AUTH_MODE")
    os.environ["RAY_AUTH_MODE"] = "disabled"
    port = free_port()
    address = f"{LOOPBACK}:{port}"
    common = ["--block", "--num-cpus=1", f"--node-ip-address={LOOPBACK}", "--disable-usage-stats"]
    logs = open(Path(tmp) / "ray-start.log", "w")
    nodes = [
        subprocess.Popen([str(ray), "start", "--head", f"--port={port}", "--include-dashboard=false", *common], env=env, stdout=logs, stderr=subprocess.STDOUT, start_new_session=True)
    ]
    try:
        import ray as ray_api

        # a loaded machine starts Ray slowly: wait for the head's GCS port, then for both nodes
        deadline = time.time() + 300
        while time.time() < deadline and not listening(port):
            assert nodes[0].poll() is None, (Path(tmp) / "ray-start.log").read_text()[-3000:]
            time.sleep(1)
        nodes.append(
            subprocess.Popen([str(ray), "start", f"--address={address}", *common], env=env, stdout=logs, stderr=subprocess.STDOUT, start_new_session=True)
        )
        alive = []
        while time.time() < deadline:
            ray_api.init(address=address, logging_level="warning")
            alive = [n for n in ray_api.nodes() if n["Alive"]]
            ray_api.shutdown()
            if len(alive) == 2:
                break
            time.sleep(2)
        else:
            pytest.fail(f"the two-node cluster did not come up: {(Path(tmp) / 'ray-start.log').read_text()[-3000:]}")
        assert {n["NodeManagerAddress"] for n in alive} == {LOOPBACK}
        yield address
    finally:
        if saved_mode is None:
            os.environ.pop("RAY_AUTH_MODE", None)
        else:
            os.environ["RAY_AUTH_MODE"] = saved_mode
        for p in reversed(nodes):
            # the foreground `ray start` stops what it started on SIGTERM; its session is its own
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in nodes:
            try:
                p.wait(timeout=60)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
        logs.close()
        shutil.rmtree(tmp, ignore_errors=True)


def sequential(repo, slam_app, tmp_path):
    outs = []
    for k, (path, options) in enumerate(EXCERPTS):
        out = tmp_path / f"seq{k}"
        subprocess.run([str(slam_app), "run", path, "--out", str(out), *options], cwd=repo, check=True, capture_output=True)
        outs.append(out)
    return outs


def tracking_without_times(path: Path):
    with open(path, newline="") as f:
        return [row[:-1] for row in csv.reader(f)]


def test_fleet_on_two_nodes(cluster, repo, slam_app, tmp_path):
    broken = tmp_path / "broken-drive"
    (broken / "image_0").mkdir(parents=True)
    drives = [fleet.Drive(str(repo / p), o) for p, o in EXCERPTS[:2]]
    drives.append(fleet.Drive(str(broken), ()))
    drives += [fleet.Drive(str(repo / p), o) for p, o in EXCERPTS[2:]]
    # and the first excerpt again, recorded as a ROS bag: the task turns it into a sequence first
    drives.append(fleet.Drive(str(write_bag(tmp_path / "drive06.bag", repo, frames=12)), ()))
    out = tmp_path / "fleet"
    rows = fleet.map_drives(drives, out, address=cluster, slam_app=slam_app, cwd=repo, progress=True)
    assert [r.drive for r in rows] == [
        "06_frames-0..12",
        "06_frames-20..32",
        "broken-drive",
        "01_frames-0..12",
        "2011_09_26_drive_0005_sync_frames-0..12",
        "drive06.bag",
    ]
    done = [r for r in rows if r.status == "done"]
    failed = [r for r in rows if r.status != "done"]
    assert len(done) == 5 and [r.drive for r in failed] == ["broken-drive"]
    from_bag = done.pop()
    # the broken drive: run twice, reported with slam-app's own error
    bad = failed[0]
    assert bad.attempts == 2 and "not a KITTI stereo sequence" in bad.error and "exit status 1" in bad.error
    assert (out / "broken-drive" / "attempt-2.stderr.txt").is_file() and (out / "broken-drive" / "error.txt").is_file()
    # both nodes took tasks
    assert len({r.node for r in rows}) == 2, [r.node for r in rows]
    # the results equal sequential runs of the same excerpts
    for r, seq in zip(done, sequential(repo, slam_app, tmp_path)):
        run = out / r.output
        for name in SAME_FILES:
            assert (run / name).read_bytes() == (seq / name).read_bytes(), f"{r.drive}: {name} differs"
        assert tracking_without_times(run / "tracking.csv") == tracking_without_times(seq / "tracking.csv")
        assert r.frames == 12 and r.tracked >= 10 and r.keyframes >= 2 and r.attempts == 1
        assert r.ate_m is not None and 0 <= r.ate_aligned_m <= r.ate_m < 2, r
        assert r.time_s > 0 and r.cpu_s > 0
    # the bag: the first excerpt's results (it carries no ground truth: no ATE)
    assert from_bag.frames == 12 and from_bag.ate_m is None
    for name in ("trajectory.kitti.txt", "objects.json", "camera.json"):
        assert (out / from_bag.output / name).read_bytes() == (out / done[0].output / name).read_bytes(), name
    # the summary table: CSV and Parquet, one row per drive in the order given
    with open(out / "summary.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert tuple(table[0]) == fleet.COLUMNS
    assert [t["drive"] for t in table] == [r.drive for r in rows]
    assert table[2]["status"] == "failed" and table[2]["ate_m"] == "" and table[2]["attempts"] == "2"
    import pyarrow.parquet as pq

    parquet = pq.read_table(out / "summary.parquet").to_pylist()
    assert [p["drive"] for p in parquet] == [t["drive"] for t in table]
    assert parquet[0]["frames"] == 12 and parquet[2]["frames"] is None and parquet[2]["status"] == "failed"
    assert parquet[3]["ate_m"] == pytest.approx(rows[3].ate_m)


def test_drive_lists_and_names(tmp_path):
    listing = tmp_path / "drives.txt"
    listing.write_text("# two excerpts of one drive\n/data/06 --frames 0..20\n\n/data/06 --frames 20..40 --name later\n/data/06\n/data/06\n")
    drives = fleet.read_drive_list(listing)
    assert drives[0] == fleet.Drive("/data/06", ("--frames", "0..20"))
    assert drives[1] == fleet.Drive("/data/06", ("--frames", "20..40"), "later")
    assert fleet.drive_names(drives) == ["06_frames-0..20", "later", "06", "06-2"]
    with pytest.raises(fleet.FleetError, match="names given twice"):
        fleet.drive_names([fleet.Drive("/a", (), "x"), fleet.Drive("/b", (), "x")])
    bad = tmp_path / "bad.txt"
    bad.write_text("/data/06 --frames '0..20\n")
    with pytest.raises(fleet.FleetError, match=r"bad\.txt line 1: "):
        fleet.read_drive_list(bad)


def test_an_output_folder_of_something_else_is_refused(tmp_path, slam_app):
    (tmp_path / "mine.txt").write_text("keep me")
    with pytest.raises(fleet.FleetError, match="was not written by slam-fleet"):
        fleet.map_drives([fleet.Drive("/data/06")], tmp_path, slam_app=slam_app)
    assert (tmp_path / "mine.txt").read_text() == "keep me"


def test_the_command_line_reports_usage_errors(tmp_path, capsys):
    assert fleet.main(["--out", str(tmp_path / "o"), "--list", str(tmp_path / "none.txt")]) == 2
    assert "cannot read the drive list" in capsys.readouterr().err


def test_a_local_cluster_without_slam_app_is_refused_before_it_starts(tmp_path, monkeypatch, capsys):
    # the local cluster's runs would run slam-app on this machine: none there is one error up front, not
    # every drive failing twice; nothing is written and Ray is not started
    monkeypatch.delenv("SLAM_APP", raising=False)
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    out = tmp_path / "fleet"
    with pytest.raises(fleet.FleetError, match=r"slam-app: not found on PATH .*--slam-app to slam-fleet\); the local cluster"):
        fleet.map_drives([fleet.Drive("/data/06")], out)
    with pytest.raises(fleet.FleetError, match=r"/no/slam-app: not an executable slam-app"):
        fleet.map_drives([fleet.Drive("/data/06")], out, slam_app="/no/slam-app")
    assert fleet.main(["/data/06", "/data/07", "--out", str(out), "--slam-app", str(tmp_path)]) == 2
    assert f"slam-fleet: error: {tmp_path}: not an executable slam-app" in capsys.readouterr().err
    assert not out.exists()
    import ray

    assert not ray.is_initialized()
