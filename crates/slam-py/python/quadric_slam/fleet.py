"""Many drives mapped at once on Ray: each drive is one Ray task that runs ``slam-app run`` on it; the
results come back to one folder with a summary table.

    from quadric_slam import fleet
    rows = fleet.map_drives([fleet.Drive("fixtures/kitti_odom_06/sequences/06", ("--frames", "0..20"))], "out/fleet")

or from a shell, ``slam-fleet DRIVE... --out DIR`` (``--list FILE``: one drive a line, its path then its
own ``slam-app run`` options). ``address`` / ``--address`` names an existing cluster (``ray start
--head`` prints it; ``auto`` finds the local one); without it a local cluster is started for the call.

A drive is a folder ``slam-app run`` reads (any KITTI stereo layout) or a ROS bag (a ``.bag`` file, or a ROS 2
bag folder), which the task first turns into a KITTI sequence in its temporary folder (``quadric_slam.bags``).

What a task does: runs ``slam-app run DRIVE --out TMP OPTIONS`` in a temporary folder of the node it runs
on, reads the run's figures there (frames, tracked, keyframes, objects, ATE where the sequence has
ground truth), and hands the output folder back as one uncompressed tar archive through Ray's object
store, so the nodes need no shared output disk. The drive's input must be readable at the same path on
every node, and ``slam-app`` must be there (docs/fleet.md: a Kubernetes cluster with KubeRay).

A drive whose run fails (slam-app's exit status, or the task lost with its worker or node) is run once
more (``retries``); if it fails again it is reported in the table with its error, and the other drives
go on. The output folder::

    DIR/summary.csv, DIR/summary.parquet   one row per drive, in the order given
    DIR/<drive>/run/                       what slam-app run wrote (a drive that failed has none)
    DIR/<drive>/attempt-N.stdout.txt       what each attempt printed; .stderr.txt its log
    DIR/.slam-fleet                        the names this fleet wrote (a later fleet replaces only those)
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import os
import re
import shlex
import shutil
import socket
import subprocess
import sys
import tarfile
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple

from . import bags
from .results import STATES, PathLike, RunError, find_slam_app, ground_truth_errors, last_lines

#: The columns of the summary table, in order.
COLUMNS = (
    "drive",
    "path",
    "options",
    "status",
    "attempts",
    "error",
    "frames",
    "tracked",
    "keyframes",
    "objects",
    "ate_m",
    "ate_aligned_m",
    "time_s",
    "cpu_s",
    "node",
    "output",
)
MARKER = ".slam-fleet"


@dataclass(frozen=True)
class Drive:
    """One drive: a sequence folder ``slam-app run`` reads, its own run options, and a name (its output
    folder's; made from the path when not given)."""

    path: str
    options: Tuple[str, ...] = ()
    name: Optional[str] = None


@dataclass
class DriveResult:
    """One row of the summary table."""

    drive: str
    path: str
    options: str
    status: str
    """``done`` or ``failed``."""
    attempts: int
    error: Optional[str] = None
    """The last attempt's error (a failed drive's)."""
    frames: Optional[int] = None
    """Frames played (tracking.csv's rows)."""
    tracked: Optional[int] = None
    """Frames in the state ``tracked``."""
    keyframes: Optional[int] = None
    """Keyframes of the map (not culled)."""
    objects: Optional[int] = None
    """Mapped objects (objects.json, moving ones left out)."""
    ate_m: Optional[float] = None
    """ATE against the sequence's ground truth, metres (None without ground truth)."""
    ate_aligned_m: Optional[float] = None
    """The same after a rigid alignment."""
    time_s: Optional[float] = None
    """Wall time of the successful run of slam-app, seconds."""
    cpu_s: Optional[float] = None
    """Its CPU time (user + system), seconds."""
    node: Optional[str] = None
    """The host that ran it, and the Ray node's id (its first 8 hex digits)."""
    output: Optional[str] = None
    """Its output folder, relative to the fleet's folder."""
    timing: Dict[str, float] = field(default_factory=dict, repr=False)
    """Times of the successful attempt (``time.time()``): ``submitted``, ``task_start``, ``run_start``,
    ``run_end``, ``task_end``, ``received``; for the overhead benchmark."""

    def row(self) -> Dict[str, Any]:
        d = asdict(self)
        return {k: d[k] for k in COLUMNS}


class FleetError(ValueError):
    """The fleet cannot start: a bad drive list, an output folder it may not write, Ray not installed."""


def read_drive_list(path: PathLike) -> List[Drive]:
    """Drives from a list file: one a line, its path then its own ``slam-app run`` options (shell words;
    ``--name NAME`` names its output folder); blank lines and lines starting with ``#`` are skipped.

    Raises:
        FleetError: the file cannot be read or a line cannot be split, naming the line.
    """
    drives = []
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise FleetError(f"{path}: cannot read the drive list: {e}") from None
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            words = shlex.split(line)
        except ValueError as e:
            raise FleetError(f"{path} line {number}: {e}") from None
        name = None
        if "--name" in words:
            k = words.index("--name")
            if k + 1 >= len(words):
                raise FleetError(f"{path} line {number}: --name needs a value")
            name = words[k + 1]
            del words[k : k + 2]
        drives.append(Drive(words[0], tuple(words[1:]), name))
    if not drives:
        raise FleetError(f"{path}: no drive in the list")
    return drives


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("._") or "drive"


def drive_names(drives: Sequence[Drive]) -> List[str]:
    """The output folder's name of each drive: its own, else the path's last part (with ``--frames`` and
    ``--stride`` when given), made unique by ``-2``, ``-3``... in the order given.

    Raises:
        FleetError: two drives given the same name, or a name that is not a plain folder name.
    """
    names: List[str] = []
    given = [d.name for d in drives if d.name is not None]
    if len(set(given)) != len(given):
        raise FleetError(f"drive names given twice: {sorted({n for n in given if given.count(n) > 1})}")
    for d in drives:
        if d.name is not None:
            if _slug(d.name) != d.name or d.name == MARKER:
                raise FleetError(f"drive name {d.name!r}: use letters, digits, '.', '_' and '-' only")
            names.append(d.name)
            continue
        base = _slug(Path(d.path.rstrip("/")).name)
        opts = list(d.options)
        for flag in ("--frames", "--stride"):
            if flag in opts and opts.index(flag) + 1 < len(opts):
                base += f"_{flag[2:]}-{_slug(opts[opts.index(flag) + 1])}"
        name, k = base, 2
        while name in names or name in given or name in ("summary.csv", "summary.parquet"):
            name, k = f"{base}-{k}", k + 1
        names.append(name)
    return names


def _figures(out: Path, stdout: str) -> Dict[str, Any]:
    """The summary figures of a finished run in `out` (and what it printed)."""
    with open(out / "tracking.csv", encoding="utf-8", newline="") as f:
        rows = list(csv.DictReader(f))
    states = [r["state"] for r in rows]
    unknown = sorted(set(states) - set(STATES))
    if unknown:
        raise RunError(f"{out / 'tracking.csv'}: unknown tracking states {unknown}")
    with open(out / "map.json", encoding="utf-8") as f:
        keyframes = json.load(f)["keyframes"]
    with open(out / "objects.json", encoding="utf-8") as f:
        objects = json.load(f)["objects"]
    truth = ground_truth_errors(stdout) or {}
    return {
        "frames": len(rows),
        "tracked": states.count("tracked"),
        "keyframes": sum(1 for k in keyframes.values() if not k.get("culled", False)),
        "objects": sum(1 for o in objects if not o.get("moving", False)),
        "ate_m": truth.get("ate_m"),
        "ate_aligned_m": truth.get("ate_aligned_m"),
    }


def _node_name() -> str:
    """The host, and the Ray node's id when running as a task (two nodes may share a host)."""
    host = socket.gethostname()
    try:
        import ray

        if ray.is_initialized():
            return f"{host}/{ray.get_runtime_context().get_node_id()[:8]}"
    except ImportError:
        pass
    return host


def map_one(spec: Dict[str, Any]) -> Dict[str, Any]:
    """One attempt at one drive, where it runs (a Ray task's body; also callable without Ray): runs
    slam-app into a temporary folder and returns the figures, the output folder as a tar archive
    (``archive``, bytes), what slam-app printed, and the attempt's times. A failure is returned as
    ``status`` ``failed`` with ``error``, not raised."""
    task_start = time.time()
    result: Dict[str, Any] = {"node": _node_name(), "pid": os.getpid(), "task_start": task_start}
    tmp = Path(tempfile.mkdtemp(prefix="slam-fleet-"))
    try:
        out = tmp / "run"
        sequence = spec["path"]
        if bags.is_bag(sequence):
            topics = spec.get("bag_topics") or (None, None)
            sequence = str(bags.to_kitti(sequence, tmp / "bag", left=topics[0], right=topics[1]))
            result["converted_s"] = time.time() - task_start
        cmd = [find_slam_app(spec.get("slam_app")), "run", sequence, "--out", str(out), *spec["options"]]
        with open(tmp / "stdout", "w+b") as so, open(tmp / "stderr", "w+b") as se:
            result["run_start"] = time.time()
            proc = subprocess.Popen(cmd, stdout=so, stderr=se, stdin=subprocess.DEVNULL, cwd=spec.get("cwd"))
            _, status, usage = os.wait4(proc.pid, 0)
            proc.returncode = os.waitstatus_to_exitcode(status)
            result["run_end"] = time.time()
            so.seek(0)
            se.seek(0)
            stdout = so.read().decode("utf-8", "replace")
            stderr = se.read().decode("utf-8", "replace")
        result.update(
            stdout=stdout,
            stderr=stderr,
            time_s=result["run_end"] - result["run_start"],
            cpu_s=usage.ru_utime + usage.ru_stime,
        )
        if proc.returncode != 0:
            result.update(status="failed", error=f"slam-app exit status {proc.returncode}: {last_lines(stderr)}")
            return result
        result.update(_figures(out, stdout))
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode="w") as tar:
            for path in sorted(out.rglob("*")):
                tar.add(path, arcname=str(path.relative_to(out)), recursive=False)
        result.update(status="done", archive=buffer.getvalue())
        return result
    except (OSError, RunError, ValueError, KeyError) as e:  # BagError is a ValueError
        result.update(status="failed", error=f"{type(e).__name__}: {e}")
        return result
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        result["task_end"] = time.time()


def _unpack(archive: bytes, into: Path) -> None:
    """Unpack a task's archive (plain files and folders only, nothing outside `into`)."""
    with tarfile.open(fileobj=io.BytesIO(archive), mode="r") as tar:
        for member in tar.getmembers():
            target = (into / member.name).resolve()
            if not (member.isfile() or member.isdir()) or not str(target).startswith(str(into.resolve())):
                raise RunError(f"the archive of a run holds {member.name!r}, which is not a file of its folder")
        into.mkdir(parents=True, exist_ok=True)
        for member in tar.getmembers():
            target = into / member.name
            if member.isdir():
                target.mkdir(parents=True, exist_ok=True)
                continue
            target.parent.mkdir(parents=True, exist_ok=True)
            source = tar.extractfile(member)
            assert source is not None
            with open(target, "wb") as f:
                shutil.copyfileobj(source, f)


def _prepare_output(out: Path, names: Sequence[str]) -> None:
    """Make the fleet's folder: new, empty, or one an earlier fleet wrote (its entries are replaced)."""
    if out.exists() and not out.is_dir():
        raise FleetError(f"{out}: exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        marker = out / MARKER
        if not marker.is_file():
            raise FleetError(f"{out}: exists, is not empty and was not written by slam-fleet; name another folder")
        for name in marker.read_text(encoding="utf-8").split():
            target = out / name
            if target.is_dir():
                shutil.rmtree(target)
            elif target.exists():
                target.unlink()
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text("\n".join(["summary.csv", "summary.parquet", *names]) + "\n", encoding="utf-8")


class Progress:
    """A progress bar on stderr (a line that redraws on a terminal; a line per finished drive elsewhere)."""

    def __init__(self, total: int, enabled: bool = True) -> None:
        self.total, self.enabled, self.start = total, enabled, time.time()
        self.done = self.failed = self.retrying = 0
        self.tty = sys.stderr.isatty()

    def update(self, line: Optional[str] = None) -> None:
        if not self.enabled:
            return
        elapsed = time.time() - self.start
        width = 30
        filled = int(width * (self.done + self.failed) / max(self.total, 1))
        bar = f"[{'#' * filled}{'.' * (width - filled)}] {self.done + self.failed}/{self.total} drives"
        extra = f", {self.failed} failed" if self.failed else ""
        extra += f", {self.retrying} retrying" if self.retrying else ""
        status = f"{bar}{extra}, {elapsed:.0f} s"
        if self.tty:
            if line:
                sys.stderr.write("\r\033[K" + line + "\n")
            sys.stderr.write("\r\033[K" + status)
            sys.stderr.flush()
        elif line:
            sys.stderr.write(f"slam-fleet: {line} ({status})\n")
            sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            sys.stderr.write("\n")
            sys.stderr.flush()


def _ray():
    try:
        import ray
    except ImportError:
        raise FleetError("the fleet needs Ray: pip install 'quadric-slam[fleet]' (or ray and pyarrow)") from None
    return ray


def map_drives(
    drives: Sequence[Drive],
    out_dir: PathLike,
    *,
    address: Optional[str] = None,
    slam_app: Optional[PathLike] = None,
    cwd: Optional[PathLike] = None,
    retries: int = 1,
    cpus_per_task: float = 1.0,
    options: Sequence[str] = (),
    progress: bool = True,
    bag_topics: Optional[Tuple[str, str]] = None,
) -> List[DriveResult]:
    """Map every drive with one Ray task each and gather the results into ``out_dir``.

    Args:
        drives: the drives (relative paths are made absolute here, on the driver).
        out_dir: the fleet's folder: new, empty, or written by an earlier fleet.
        address: an existing Ray cluster (``ray start --head`` prints it, or ``auto``); None: a local
            cluster for this call, its workers at niceness 0 (Ray's default is 15: start a cluster's
            nodes with ``RAY_worker_niceness=0`` in their environment for the same). Ray already
            initialised in this process is used as it is.
        slam_app: the executable on the nodes; else ``$SLAM_APP``, else ``slam-app`` on each node's PATH.
        cwd: the working directory of the runs on the nodes (where slam-app looks for ``fixtures/`` and
            ``.ort/`` first).
        retries: further attempts at a drive that failed (default 1).
        cpus_per_task: CPUs Ray reserves for each task (a run uses about one core; its threads overlap).
        options: ``slam-app run`` options for every drive, before each drive's own.
        progress: draw a progress bar on stderr.
        bag_topics: the left and right image topics of drives that are ROS bags (``quadric_slam.bags``:
            each is turned into a KITTI sequence in the task's temporary folder first); None: the first
            pair of ``bags.DEFAULT_TOPICS`` present.

    Returns:
        One row per drive, in the order given (also written to ``summary.csv`` and ``summary.parquet``).

    Raises:
        FleetError: no drive, a name given twice, an output folder it may not write, Ray missing, or
            (for a local cluster) no slam-app on this machine.
    """
    if not drives:
        raise FleetError("no drive to map")
    if retries < 0 or not cpus_per_task > 0:
        raise FleetError("retries must be >= 0 and cpus_per_task > 0")
    names = drive_names(drives)
    ray = _ray()
    if address is None and not ray.is_initialized():
        # the local cluster's runs run here: a slam-app missing here would fail every drive twice
        try:
            slam_app = find_slam_app(slam_app)
        except RunError as e:
            raise FleetError(f"{e}; the local cluster's runs need it on this machine") from None
    out = Path(out_dir)
    _prepare_output(out, names)
    started_here = False
    if not ray.is_initialized():
        if address is None:
            # Ray runs its workers at niceness 15 by default, so that a run would yield the CPU to anything
            # else on the machine; a fleet's runs are the work, at the driver's priority
            ray.init(
                include_dashboard=False,
                logging_level="warning",
                log_to_driver=False,
                _system_config={"worker_niceness": 0},
            )
        else:
            ray.init(address=address, logging_level="warning", log_to_driver=False)
        started_here = True
    try:
        task = ray.remote(num_cpus=cpus_per_task, max_retries=0)(map_one)
        specs = [
            {
                "path": os.path.abspath(d.path),
                "options": [*options, *d.options],
                "slam_app": None if slam_app is None else os.path.abspath(slam_app),
                "cwd": None if cwd is None else os.path.abspath(cwd),
                "bag_topics": None if bag_topics is None else tuple(bag_topics),
            }
            for d in drives
        ]
        results = _gather(ray, task, specs, names, out, retries, Progress(len(drives), progress))
    finally:
        if started_here:
            ray.shutdown()
    rows = [results[i] for i in range(len(drives))]
    write_summary(rows, out)
    return rows


def _gather(ray, task, specs, names, out: Path, retries: int, bar: Progress) -> Dict[int, DriveResult]:
    pending: Dict[Any, Tuple[int, int, float]] = {}

    def submit(i: int, attempt: int) -> None:
        pending[task.remote(specs[i])] = (i, attempt, time.time())

    for i in range(len(specs)):
        submit(i, 1)
    results: Dict[int, DriveResult] = {}
    bar.update()
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
        if not ready:
            bar.update()
            continue
        ref = ready[0]
        i, attempt, submitted = pending.pop(ref)
        try:
            r = ray.get(ref)
        except Exception as e:  # the task or its worker or node was lost: an attempt that failed
            r = {"status": "failed", "error": f"task lost: {type(e).__name__}: {str(e).splitlines()[0][:300]}"}
        received = time.time()
        folder = out / names[i]
        folder.mkdir(exist_ok=True)
        for stream in ("stdout", "stderr"):
            if stream in r:
                (folder / f"attempt-{attempt}.{stream}.txt").write_text(r[stream], encoding="utf-8")
        spec = specs[i]
        if r.get("status") == "done":
            _unpack(r["archive"], folder / "run")
            results[i] = DriveResult(
                drive=names[i],
                path=spec["path"],
                options=" ".join(shlex.quote(o) for o in spec["options"]),
                status="done",
                attempts=attempt,
                frames=r["frames"],
                tracked=r["tracked"],
                keyframes=r["keyframes"],
                objects=r["objects"],
                ate_m=r["ate_m"],
                ate_aligned_m=r["ate_aligned_m"],
                time_s=round(r["time_s"], 3),
                cpu_s=round(r["cpu_s"], 3),
                node=r["node"],
                output=f"{names[i]}/run",
                timing={k: r[k] for k in ("task_start", "run_start", "run_end", "task_end") if k in r}
                | {"submitted": submitted, "received": received, "pid": r.get("pid", 0)},
            )
            bar.done += 1
            bar.retrying -= attempt > 1
            bar.update(f"{names[i]} done: {r['frames']} frames in {r['time_s']:.1f} s on {r['node']}")
        elif attempt <= retries:
            bar.retrying += attempt == 1
            bar.update(f"{names[i]} failed ({r['error']}); running it again")
            submit(i, attempt + 1)
        else:
            (folder / "error.txt").write_text(r["error"] + "\n", encoding="utf-8")
            results[i] = DriveResult(
                drive=names[i],
                path=spec["path"],
                options=" ".join(shlex.quote(o) for o in spec["options"]),
                status="failed",
                attempts=attempt,
                error=r["error"],
                node=r.get("node"),
            )
            bar.failed += 1
            bar.retrying -= attempt > 1
            bar.update(f"{names[i]} failed after {attempt} attempts: {r['error']}")
    bar.close()
    return results


def write_summary(rows: Sequence[DriveResult], out: Path) -> None:
    """``summary.csv`` and ``summary.parquet``: one row per drive (empty fields / nulls where a figure
    does not exist: a failed drive's, ATE without ground truth)."""
    table = [r.row() for r in rows]
    with open(out / "summary.csv", "w", encoding="utf-8", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        for row in table:
            w.writerow({k: "" if v is None else v for k, v in row.items()})
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise FleetError("summary.parquet needs pyarrow: pip install 'quadric-slam[fleet]'") from None
    types = {
        "attempts": pa.int64(),
        "frames": pa.int64(),
        "tracked": pa.int64(),
        "keyframes": pa.int64(),
        "objects": pa.int64(),
        "ate_m": pa.float64(),
        "ate_aligned_m": pa.float64(),
        "time_s": pa.float64(),
        "cpu_s": pa.float64(),
    }
    schema = pa.schema([(c, types.get(c, pa.string())) for c in COLUMNS])
    columns = {c: [row[c] for row in table] for c in COLUMNS}
    pq.write_table(pa.table(columns, schema=schema), out / "summary.parquet")


def _print_table(rows: Iterable[DriveResult]) -> None:
    def cell(v: Any) -> str:
        if v is None:
            return "–"
        if isinstance(v, float):
            return f"{v:.3f}" if not math.isnan(v) else "–"
        return str(v)

    cols = ("drive", "status", "attempts", "frames", "tracked", "keyframes", "objects", "ate_m", "time_s", "node")
    print("| " + " | ".join(cols) + " |")
    print("|" + "|".join("---" for _ in cols) + "|")
    for r in rows:
        d = r.row()
        print("| " + " | ".join(cell(d[c]) for c in cols) + " |")


def _topics(text: Optional[str]) -> Optional[Tuple[str, str]]:
    if text is None:
        return None
    parts = [t.strip() for t in text.split(",")]
    if len(parts) != 2 or not all(parts):
        raise FleetError(f"--bag-topics: expected LEFT,RIGHT, got {text!r}")
    return parts[0], parts[1]


def main(argv: Optional[Sequence[str]] = None) -> int:
    """The ``slam-fleet`` command."""
    p = argparse.ArgumentParser(
        prog="slam-fleet",
        description="Map many drives at once on a Ray cluster: one task per drive running slam-app run; "
        "the results and a summary table (CSV and Parquet) in one folder.",
    )
    p.add_argument("drives", nargs="*", help="drives: folders of any KITTI stereo layout slam-app run reads, or ROS bags")
    p.add_argument("--list", dest="list_file", help="a file of drives: one a line, its path then its own slam-app run options")
    p.add_argument("--out", required=True, help="the fleet's output folder")
    p.add_argument("--address", help="an existing Ray cluster (as ray start --head prints it, or auto); default: a local one")
    p.add_argument("--slam-app", help="the slam-app executable on the nodes (default: $SLAM_APP, else slam-app on PATH)")
    p.add_argument("--cwd", help="the runs' working directory on the nodes")
    p.add_argument("--retries", type=int, default=1, help="further attempts at a failed drive (default 1)")
    p.add_argument("--cpus-per-task", type=float, default=1.0, help="CPUs reserved for each run (default 1)")
    p.add_argument("--run-options", default="", help="slam-app run options for every drive, as one string")
    p.add_argument("--bag-topics", help="LEFT,RIGHT: the image topics of drives that are ROS bags")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    a = p.parse_args(argv)
    try:
        drives = [Drive(d) for d in a.drives]
        if a.list_file:
            drives += read_drive_list(a.list_file)
        if not drives:
            p.error("no drive: give drive folders or --list FILE")
        rows = map_drives(
            drives,
            a.out,
            address=a.address,
            slam_app=a.slam_app,
            cwd=a.cwd,
            retries=a.retries,
            cpus_per_task=a.cpus_per_task,
            options=shlex.split(a.run_options),
            progress=not a.no_progress,
            bag_topics=_topics(a.bag_topics),
        )
    except (FleetError, RunError) as e:
        print(f"slam-fleet: error: {e}", file=sys.stderr)
        return 2
    _print_table(rows)
    failed = [r for r in rows if r.status != "done"]
    print(f"\n{len(rows) - len(failed)} of {len(rows)} drives mapped; summary in {Path(a.out) / 'summary.csv'} and summary.parquet")
    for r in failed:
        print(f"failed: {r.drive}: {r.error}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
