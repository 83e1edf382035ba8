"""quadric_slam: the quadric (ellipsoid) geometry of quadric-slam from Python, a run's results as arrays,
and many drives mapped at once on Ray.

The geometry (native, from the Rust crate ``slam-quadric``): ``Camera``, ``Ellipsoid``, ``DualConic``,
``project`` (one ellipsoid), ``project_many`` / ``bounds_many`` (many in one call), ``predict_box`` (a box
with its Jacobians), the initialisers ``Dqp``, ``Tri``, ``QSlamSvd``, ``Conic``, and the metrics
``e_trans``, ``e_axe``, ``e_yaw``, ``iou``, ``projected_iou``, ``box_iou``. Arrays are numpy arrays in and
out; every bad input is a ``ValueError`` (``ProjectionError`` and ``InitError`` are ValueErrors too).

A run: ``load_run(out_dir)`` reads what ``slam-app run`` wrote; ``run(sequence, out_dir, **settings)``
runs it. Many drives on Ray: ``quadric_slam.fleet`` and the ``slam-fleet`` command.
"""

from ._quadric_slam import (
    ROTATION_TOLERANCE,
    Camera,
    Conic,
    Dqp,
    DualConic,
    Ellipsoid,
    InitError,
    ProjectionError,
    QSlamSvd,
    Tri,
    __version__,
    bounds_many,
    box_iou,
    e_axe,
    e_trans,
    e_yaw,
    iou,
    predict_box,
    project,
    project_many,
    projected_iou,
)
from .results import Objects, Run, RunError, load_run, run

__all__ = [
    "ROTATION_TOLERANCE",
    "Camera",
    "Conic",
    "Dqp",
    "DualConic",
    "Ellipsoid",
    "InitError",
    "Objects",
    "ProjectionError",
    "QSlamSvd",
    "Run",
    "RunError",
    "Tri",
    "__version__",
    "bounds_many",
    "box_iou",
    "e_axe",
    "e_trans",
    "e_yaw",
    "iou",
    "load_run",
    "predict_box",
    "project",
    "project_many",
    "projected_iou",
    "run",
]
