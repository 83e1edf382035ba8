"""A run's results as numpy arrays (``load_run``), and a run of ``slam-app`` from Python (``run``).

``slam-app run SEQUENCE --out DIR`` writes, among others (docs/system.md, "The running system"):

* ``trajectory.kitti.txt``: one line per frame with a pose, 12 numbers: the 3x4 row-major
  camera-to-world pose of the left camera (world = the first played frame's left camera);
* ``tracking.csv``: one row per played frame, ``frame,state,inliers,tracked_map_points,
  reprojection_rms_px,time_ms`` (the RMS is empty when it is undefined);
* ``map.json``: the map database: keyframes (pose ``[qx, qy, qz, qw, tx, ty, tz]``, world from camera),
  map points (``position``), objects, and ``trajectory``, one entry per played frame whose ``keyframe``
  is null for a frame without a pose (a run in a saved map before it was placed there): the frames of
  ``trajectory.kitti.txt``'s lines, in order;
* ``objects.json``: the object map: ``id``, ``class`` (COCO index), ``class_name``, ``center``,
  ``semi_axes``, ``rotation`` (3x3 row-major, world from object), ``frames``, ``dynamic``, ``moving``;
* ``camera.json``: the left camera's ``fx, fy, cx, cy, width, height``.

Every file is checked as it is read; a missing file or a value that does not fit is a ``RunError``
(a ValueError) naming the file and, where there is one, the line or entry.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Union

import numpy as np

PathLike = Union[str, "os.PathLike[str]"]

#: The columns of ``tracking.csv``, in order.
TRACKING_COLUMNS = ("frame", "state", "inliers", "tracked_map_points", "reprojection_rms_px", "time_ms")
#: Every state a frame of ``tracking.csv`` can be in.
STATES = ("initialised", "tracked", "weak", "relocalised", "predicted", "lost", "unreadable")


class RunError(ValueError):
    """A run's output cannot be read (a file missing or malformed), or ``slam-app`` failed."""


@dataclass(frozen=True)
class Objects:
    """The object map: one entry per object with an ellipsoid, in the file's order."""

    ids: np.ndarray
    """(K,) object ids."""
    classes: np.ndarray
    """(K,) COCO class indices."""
    class_names: List[str]
    """K class names."""
    centres: np.ndarray
    """(K, 3) centres, world frame, metres."""
    axes: np.ndarray
    """(K, 3) semi-axes along the object's x (length), y (height), z (width), metres."""
    rotations: np.ndarray
    """(K, 3, 3) world-from-object rotations."""
    dynamic: np.ndarray
    """(K,) flagged dynamic."""
    moving: np.ndarray
    """(K,) its points moved: a moving object, not mapped (kept for inspection)."""
    frames: List[np.ndarray]
    """The frames of each object's detections."""

    def __len__(self) -> int:
        return len(self.ids)

    def ellipsoids(self) -> list:
        """Each object as a ``quadric_slam.Ellipsoid``."""
        from ._quadric_slam import Ellipsoid

        return [Ellipsoid.from_centre(c, a, r) for c, a, r in zip(self.centres, self.axes, self.rotations)]


@dataclass(frozen=True)
class Run:
    """What ``slam-app run`` wrote into one output folder, as arrays."""

    path: Path
    """The output folder."""
    frame_ids: np.ndarray
    """(F,) the id of every played frame (``tracking.csv``)."""
    states: np.ndarray
    """(F,) each played frame's tracking state (a string of ``STATES``)."""
    inliers: np.ndarray
    """(F,) pose inliers of each frame."""
    tracked_map_points: np.ndarray
    """(F,) map points found in each frame."""
    reprojection_rms_px: np.ndarray
    """(F,) RMS reprojection error of each frame, pixels (NaN where undefined)."""
    time_ms: np.ndarray
    """(F,) tracking time of each frame (extraction, stereo, tracking), milliseconds."""
    pose_frame_ids: np.ndarray
    """(N,) the frame id of each pose of ``trajectory``."""
    trajectory: np.ndarray
    """(N, 4, 4) camera-to-world poses of the left camera (world = the first played frame's)."""
    keyframe_ids: np.ndarray
    """(K,) keyframe ids."""
    keyframe_frame_ids: np.ndarray
    """(K,) the frame of each keyframe."""
    keyframe_poses: np.ndarray
    """(K, 4, 4) keyframe poses, world from camera."""
    point_ids: np.ndarray
    """(M,) map point ids."""
    points: np.ndarray
    """(M, 3) map points, world frame, metres."""
    objects: Objects
    """The object map (``objects.json``)."""
    camera: Dict[str, float]
    """The left camera: ``fx, fy, cx, cy, width, height`` and, from the map, ``baseline``."""
    log: Optional[str] = field(default=None, repr=False)
    """What ``slam-app`` printed (stdout), when the run was made by ``run``."""

    @property
    def frames(self) -> int:
        """Frames played."""
        return len(self.frame_ids)

    def count(self, state: str) -> int:
        """Frames in a tracking state."""
        if state not in STATES:
            raise ValueError(f"state: {state!r} is not one of {', '.join(STATES)}")
        return int(np.count_nonzero(self.states == state))

    def ground_truth_errors(self) -> Optional[Dict[str, float]]:
        """The errors against ground truth that ``slam-app`` printed (see ``ground_truth_errors``), when
        this run was made by ``run`` and its sequence has ground truth."""
        return ground_truth_errors(self.log) if self.log is not None else None


def _file(out: Path, name: str) -> Path:
    path = out / name
    if not path.is_file():
        raise RunError(f"{path}: missing (not a slam-app run folder, or the run did not finish)")
    return path


def _read_json(path: Path) -> Any:
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise RunError(f"{path}: not readable as JSON: {e}") from None


def _numbers(values: Any, count: int, where: str) -> List[float]:
    if not isinstance(values, list) or len(values) != count:
        raise RunError(f"{where}: expected {count} numbers, got {values!r:.80}")
    out = []
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise RunError(f"{where}: {v!r} is not a finite number")
        out.append(float(v))
    return out


def _read_trajectory(path: Path) -> np.ndarray:
    poses = []
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f, start=1):
            words = line.split()
            if not words:
                continue
            try:
                values = [float(w) for w in words]
            except ValueError:
                raise RunError(f"{path} line {number}: not a list of numbers: {line.strip()[:80]!r}") from None
            if len(values) != 12 or not all(math.isfinite(v) for v in values):
                raise RunError(f"{path} line {number}: expected 12 finite numbers (a 3x4 pose), got {len(values)}")
            pose = np.eye(4)
            pose[:3, :] = np.reshape(values, (3, 4))
            poses.append(pose)
    return np.array(poses, dtype=float).reshape(-1, 4, 4)


def _read_tracking(path: Path) -> Dict[str, np.ndarray]:
    with open(path, encoding="utf-8", newline="") as f:
        rows = list(csv.reader(f))
    if not rows or tuple(rows[0]) != TRACKING_COLUMNS:
        got = ",".join(rows[0]) if rows else "nothing"
        raise RunError(f"{path}: expected the header {','.join(TRACKING_COLUMNS)}, got {got}")
    frames, states, inliers, points, rms, ms = [], [], [], [], [], []
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(TRACKING_COLUMNS):
            raise RunError(f"{path} line {number}: {len(row)} fields, expected {len(TRACKING_COLUMNS)}")
        if row[1] not in STATES:
            raise RunError(f"{path} line {number}: unknown tracking state {row[1]!r}")
        try:
            frames.append(int(row[0]))
            inliers.append(int(row[2]))
            points.append(int(row[3]))
            rms.append(float(row[4]) if row[4] else math.nan)
            ms.append(float(row[5]))
        except ValueError as e:
            raise RunError(f"{path} line {number}: {e}") from None
        states.append(row[1])
    return {
        "frame_ids": np.array(frames, dtype=np.int64),
        "states": np.array(states, dtype=str),
        "inliers": np.array(inliers, dtype=np.int64),
        "tracked_map_points": np.array(points, dtype=np.int64),
        "reprojection_rms_px": np.array(rms, dtype=float),
        "time_ms": np.array(ms, dtype=float),
    }


def quaternion_pose(values: Sequence[float]) -> np.ndarray:
    """A 4x4 pose from the map file's ``[qx, qy, qz, qw, tx, ty, tz]`` (the quaternion normalised)."""
    x, y, z, w = values[:4]
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n > 0:
        raise ValueError("a zero quaternion")
    x, y, z, w = x / n, y / n, z / n, w / n
    pose = np.eye(4)
    pose[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    pose[:3, 3] = values[4:7]
    return pose


def _read_map(path: Path) -> Dict[str, Any]:
    m = _read_json(path)
    if not isinstance(m, dict) or m.get("format") != "quadric-slam-map":
        raise RunError(f"{path}: not a quadric-slam map file (its format is not quadric-slam-map)")
    for key, kind in (("keyframes", dict), ("points", dict), ("trajectory", list)):
        if not isinstance(m.get(key), kind):
            raise RunError(f"{path}: {key} missing or not a JSON {'object' if kind is dict else 'array'}")
    kf_ids, kf_frames, kf_poses = [], [], []
    for key in sorted(m["keyframes"], key=int):
        k = m["keyframes"][key]
        where = f"{path}: keyframes.{key}"
        if not isinstance(k, dict) or not isinstance(k.get("frame"), int):
            raise RunError(f"{where}: no frame id")
        try:
            pose = quaternion_pose(_numbers(k.get("pose"), 7, f"{where}.pose"))
        except ValueError as e:
            raise RunError(f"{where}.pose: {e}") from None
        kf_ids.append(int(key))
        kf_frames.append(k["frame"])
        kf_poses.append(pose)
    point_ids = sorted(m["points"], key=int)
    points = [_numbers(m["points"][p].get("position"), 3, f"{path}: points.{p}.position") for p in point_ids]
    placed = []
    for i, t in enumerate(m["trajectory"]):
        if not isinstance(t, dict) or not isinstance(t.get("frame"), int):
            raise RunError(f"{path}: trajectory[{i}] has no frame id")
        if t.get("keyframe") is not None:
            placed.append(t["frame"])
    camera = m.get("camera") or {}
    return {
        "keyframe_ids": np.array(kf_ids, dtype=np.int64),
        "keyframe_frame_ids": np.array(kf_frames, dtype=np.int64),
        "keyframe_poses": np.array(kf_poses, dtype=float).reshape(-1, 4, 4),
        "point_ids": np.array([int(p) for p in point_ids], dtype=np.int64),
        "points": np.array(points, dtype=float).reshape(-1, 3),
        "pose_frame_ids": np.array(placed, dtype=np.int64),
        "baseline": camera.get("baseline"),
    }


def _read_objects(path: Path) -> Objects:
    doc = _read_json(path)
    if not isinstance(doc, dict) or not isinstance(doc.get("objects"), list):
        raise RunError(f"{path}: not an object map (no objects array)")
    ids, classes, names, centres, axes, rotations, dynamic, moving, frames = [], [], [], [], [], [], [], [], []
    for i, o in enumerate(doc["objects"]):
        where = f"{path}: objects[{i}]"
        if not isinstance(o, dict):
            raise RunError(f"{where}: not a JSON object")
        for key in ("id", "class"):
            if not isinstance(o.get(key), int) or isinstance(o.get(key), bool):
                raise RunError(f"{where}.{key}: not an integer")
        for key in ("dynamic", "moving"):
            if not isinstance(o.get(key, False), bool):
                raise RunError(f"{where}.{key}: not true or false")
        ids.append(o["id"])
        classes.append(o["class"])
        names.append(str(o.get("class_name", "")))
        centres.append(_numbers(o.get("center"), 3, f"{where}.center"))
        axes.append(_numbers(o.get("semi_axes"), 3, f"{where}.semi_axes"))
        rotations.append(np.reshape(_numbers(o.get("rotation"), 9, f"{where}.rotation"), (3, 3)))
        dynamic.append(o.get("dynamic", False))
        moving.append(o.get("moving", False))
        f = o.get("frames", [])
        if not isinstance(f, list) or not all(isinstance(x, int) for x in f):
            raise RunError(f"{where}.frames: not a list of frame ids")
        frames.append(np.array(f, dtype=np.int64))
    return Objects(
        ids=np.array(ids, dtype=np.int64),
        classes=np.array(classes, dtype=np.int64),
        class_names=names,
        centres=np.array(centres, dtype=float).reshape(-1, 3),
        axes=np.array(axes, dtype=float).reshape(-1, 3),
        rotations=np.array(rotations, dtype=float).reshape(-1, 3, 3),
        dynamic=np.array(dynamic, dtype=bool),
        moving=np.array(moving, dtype=bool),
        frames=frames,
    )


def load_run(out_dir: PathLike, log: Optional[str] = None) -> Run:
    """Read the output folder of ``slam-app run`` as arrays.

    Args:
        out_dir: the folder (``slam-app run --out DIR``).
        log: what the run printed, if known (kept as ``Run.log``).

    Raises:
        RunError: a file is missing or malformed (the message names it, and the line or entry).
    """
    out = Path(out_dir)
    if not out.is_dir():
        raise RunError(f"{out}: not a folder")
    trajectory = _read_trajectory(_file(out, "trajectory.kitti.txt"))
    tracking = _read_tracking(_file(out, "tracking.csv"))
    map_path = _file(out, "map.json")
    m = _read_map(map_path)
    if len(m["pose_frame_ids"]) != len(trajectory):
        raise RunError(
            f"{out}: trajectory.kitti.txt has {len(trajectory)} poses but map.json's trajectory places "
            f"{len(m['pose_frame_ids'])} frames: the files are not of one run"
        )
    objects = _read_objects(_file(out, "objects.json"))
    cam = _read_json(_file(out, "camera.json"))
    camera: Dict[str, float] = {}
    for key in ("fx", "fy", "cx", "cy", "width", "height"):
        camera[key] = _numbers([cam.get(key) if isinstance(cam, dict) else None], 1, f"{out / 'camera.json'}: {key}")[0]
    if m["baseline"] is not None:
        camera["baseline"] = float(m["baseline"])
    return Run(
        path=out,
        pose_frame_ids=m["pose_frame_ids"],
        trajectory=trajectory,
        keyframe_ids=m["keyframe_ids"],
        keyframe_frame_ids=m["keyframe_frame_ids"],
        keyframe_poses=m["keyframe_poses"],
        point_ids=m["point_ids"],
        points=m["points"],
        objects=objects,
        camera=camera,
        log=log,
        **tracking,
    )


_TRUTH_LINE = re.compile(
    r"^ground truth: path (?P<path>[0-9.]+) m over (?P<frames>\d+) frames; ATE (?P<ate>[0-9.]+) m "
    r"\(aligned (?P<aligned>[0-9.]+) m\); end-point drift (?P<drift>[0-9.]+|–)",
    re.MULTILINE,
)


def ground_truth_errors(log: str) -> Optional[Dict[str, float]]:
    """The errors against ground truth from what ``slam-app run`` printed (its line ``ground truth: path
    P m over N frames; ATE A m (aligned B m); end-point drift D %``): ``path_m``, ``ate_m``,
    ``ate_aligned_m``, ``drift_pct`` (NaN when printed as a dash); None when the run printed none (its
    sequence has no ground truth)."""
    match = _TRUTH_LINE.search(log)
    if match is None:
        return None
    drift = match["drift"]
    return {
        "path_m": float(match["path"]),
        "ate_m": float(match["ate"]),
        "ate_aligned_m": float(match["aligned"]),
        "drift_pct": math.nan if drift == "–" else float(drift),
    }


def find_slam_app(slam_app: Optional[PathLike] = None) -> str:
    """The ``slam-app`` to run: the one given, else ``$SLAM_APP``, else the one on PATH.

    Raises:
        RunError: none found, or the one given is not an executable file.
    """
    given = slam_app if slam_app is not None else os.environ.get("SLAM_APP")
    if given is not None:
        path = Path(given)
        if not (path.is_file() and os.access(path, os.X_OK)):
            raise RunError(f"{path}: not an executable slam-app")
        return str(path)
    found = shutil.which("slam-app")
    if found is None:
        raise RunError(
            "slam-app: not found on PATH (build it with `cargo build --release -p slam-app` and put target/release "
            "on PATH, or set SLAM_APP, or name it: slam_app= in Python, --slam-app to slam-fleet)"
        )
    return found


def options(settings: Mapping[str, Any]) -> List[str]:
    """``slam-app run`` options from keyword settings: ``frames="0..20"`` is ``--frames 0..20``,
    ``no_ba=True`` is ``--no-ba``; False and None leave an option out; a list repeats it."""
    args: List[str] = []
    for key, value in settings.items():
        flag = "--" + key.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            args.append(flag)
        elif isinstance(value, (list, tuple)):
            for v in value:
                args += [flag, str(v)]
        else:
            args += [flag, str(value)]
    return args


def run_command(
    sequence: Optional[PathLike], out_dir: PathLike, settings: Mapping[str, Any], slam_app: Optional[PathLike] = None
) -> List[str]:
    """The command line of ``run``."""
    cmd = [find_slam_app(slam_app), "run"]
    if sequence is not None:
        cmd.append(str(sequence))
    return cmd + ["--out", str(out_dir)] + options(settings)


def run(
    sequence: Optional[PathLike],
    out_dir: PathLike,
    *,
    slam_app: Optional[PathLike] = None,
    cwd: Optional[PathLike] = None,
    **settings: Any,
) -> Run:
    """Run ``slam-app run`` on a KITTI stereo sequence and read what it wrote.

    Args:
        sequence: the sequence's folder (any layout ``slam-app run`` reads); None: its default (the
            shipped odometry excerpt).
        out_dir: the output folder (replaced as a whole by the run).
        slam_app: the executable; else ``$SLAM_APP``, else ``slam-app`` on PATH.
        cwd: the working directory of the run (where it looks for ``fixtures/`` and ``.ort/`` first).
        **settings: options of ``slam-app run``: ``frames="0..20"``, ``detector="none"``, ``no_ba=True``.

    Raises:
        RunError: slam-app not found, or it failed (its exit status and the end of what it printed on
            stderr), or its output is unreadable.
    """
    cmd = run_command(sequence, out_dir, settings, slam_app)
    done = subprocess.run(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, check=False)
    if done.returncode != 0:
        raise RunError(f"{' '.join(cmd)}: exit status {done.returncode}: {last_lines(done.stderr)}")
    return load_run(out_dir, log=done.stdout)


def last_lines(text: str, count: int = 5) -> str:
    """The last lines of a program's output, joined, for an error message (the error line first)."""
    lines = [line for line in text.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("error:")]
    tail = lines[-count:]
    picked = errors[-1:] + [line for line in tail if line not in errors[-1:]]
    return " | ".join(picked) if picked else "(nothing on stderr)"
