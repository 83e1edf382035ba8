"""Bad input raises ValueError with the reason and the argument's name, never a crash: wrong shapes,
NaN, matrices that are not what they must be, degenerate views."""

from __future__ import annotations

import math

import numpy as np
import pytest

import quadric_slam as qs

K = [[721.5, 0.0, 609.6], [0.0, 721.5, 172.9], [0.0, 0.0, 1.0]]


def car_pose(z: float = 15.0) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, 3] = [2.0, 0.9, z]
    return pose


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: qs.Ellipsoid(np.eye(3), [1, 1, 1]), r"^pose: expected shape \(4, 4\), got \(3, 3\)$"),
        (lambda: qs.Ellipsoid(car_pose(), [1, 1]), r"^axes: expected shape \(3,\), got \(2\)$"),
        (lambda: qs.Ellipsoid(car_pose(), [1, math.nan, 1]), r"^axes: holds NaN or infinity$"),
        (lambda: qs.Ellipsoid(car_pose(), [1, -1, 1]), r"^axes: every semi-axis must be positive"),
        (lambda: qs.Ellipsoid(car_pose(), [1, 0, 1]), r"^axes: every semi-axis must be positive"),
        (lambda: qs.Ellipsoid(np.diag([1.0, 1.0, -1.0, 1.0]), [1, 1, 1]), r"^pose: the top-left 3x3 block is not a rotation"),
        (lambda: qs.Ellipsoid(np.diag([2.0, 1.0, 1.0, 1.0]), [1, 1, 1]), r"^pose: the top-left 3x3 block is not a rotation"),
        (lambda: qs.Ellipsoid(car_pose() * 2, [1, 1, 1]), r"^pose: not a rigid pose: its last row"),
        (lambda: qs.Ellipsoid(np.full((4, 4), np.inf), [1, 1, 1]), r"^pose: holds NaN or infinity$"),
        (lambda: qs.Ellipsoid("not numbers", [1, 1, 1]), r"^pose: expected an array of real numbers"),
        (lambda: qs.Ellipsoid([[1, 2], [3]], [1, 1, 1]), r"^pose: expected an array of real numbers"),
        (lambda: qs.Ellipsoid.from_centre([0, 0, 10], [1, 1, 1], np.ones((3, 3))), r"^rotation: the top-left 3x3"),
        (lambda: qs.Ellipsoid.from_dual_quadric(np.diag([1.0, 1.0, -1.0, -1.0])), r"^matrix: quadric is not an ellipsoid"),
        (lambda: qs.Ellipsoid.from_dual_quadric(np.diag([1.0, 1.0, 1.0, 0.0])), r"^matrix: quadric has no finite centre"),
        (lambda: qs.Camera(np.diag([-700.0, 700.0, 1.0])), r"^K: focal lengths must be positive"),
        (lambda: qs.Camera(np.ones((3, 3))), r"^K: not a calibration matrix"),
        (lambda: qs.Camera(K, pose=np.zeros((4, 4))), r"^pose: "),
        (lambda: qs.Camera.from_intrinsics(700, math.nan, 600, 180), r"^K: focal lengths must be positive and every entry finite"),
        (lambda: qs.DualConic(np.eye(2)), r"^matrix: expected shape \(3, 3\)"),
        (lambda: qs.iou([0, 0, 1, 1], [0, 0, 0, 1]), r"^b: box is empty"),
        (lambda: qs.iou([0, 0, 1, math.nan], [0, 0, 2, 1]), r"^a: holds NaN or infinity$"),
    ],
)
def test_refused_with_the_reason(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_projection_failures_are_value_errors_naming_the_reason():
    cam = qs.Camera(K)
    cases = [
        (qs.Ellipsoid(car_pose(-15.0), [2.1, 0.8, 0.85]), "ellipsoid: ellipsoid is behind the camera"),
        (qs.Ellipsoid(car_pose(0.5), [2.1, 0.8, 0.85]), "ellipsoid: ellipsoid crosses the camera's principal plane"),
        (qs.Ellipsoid(np.eye(4), [1.0, 1.0, 1.0]), "ellipsoid: camera is inside the ellipsoid"),
    ]
    for e, message in cases:
        with pytest.raises(qs.ProjectionError) as info:
            qs.project(e, cam)
        assert isinstance(info.value, ValueError)
        assert str(info.value).startswith(message)
    # in front, but wholly outside the image: an ellipse, no clipped box
    far_left = car_pose(15.0)
    far_left[0, 3] = -200.0
    conic = qs.project(qs.Ellipsoid(far_left, [2.1, 0.8, 0.85]), cam)
    with pytest.raises(qs.ProjectionError, match="does not overlap the image"):
        conic.clipped_bounds((1242, 375))
    with pytest.raises(ValueError, match=r"^image_size: width and height must be positive"):
        conic.clipped_bounds((0, 375))
    with pytest.raises(qs.ProjectionError, match="not an ellipse"):
        qs.DualConic(np.diag([1.0, 1.0, 1.0])).bounds()


def test_numbers_too_large_for_double_precision_are_refused():
    """Finite inputs whose projection overflows (a centre 1e300 m away) are refused, not a conic of infinities."""
    cam = qs.Camera(K)
    far = qs.Ellipsoid.from_centre([0.0, 0.0, 1e300], [1.0, 1.0, 1.0])
    for call in (lambda: qs.project(far, cam), lambda: qs.predict_box(far, cam)):
        with pytest.raises(qs.ProjectionError, match="^ellipsoid: its projection overflows"):
            call()
    poses = np.stack([car_pose(), far.pose])
    with pytest.raises(qs.ProjectionError, match=r"^ellipsoid 1: its projection overflows"):
        qs.bounds_many(poses, np.ones((2, 3)), cam)
    out = qs.project_many(poses, np.ones((2, 3)), cam, errors="nan")
    assert np.isfinite(out[0]).all() and np.isnan(out[1]).all()


def test_batches_name_the_item():
    cam = qs.Camera(K)
    poses = np.stack([car_pose()] * 4)
    axes = np.ones((4, 3))
    bad = poses.copy()
    bad[2, 0, 0] = 5.0
    with pytest.raises(ValueError, match=r"^poses\[2\]: the top-left 3x3 block is not a rotation"):
        qs.project_many(bad, axes, cam)
    nan_axes = axes.copy()
    nan_axes[3, 1] = math.nan
    with pytest.raises(ValueError, match=r"^axes\[3\]: holds NaN or infinity$"):
        qs.project_many(poses, nan_axes, cam)
    with pytest.raises(ValueError, match=r"^poses: expected shape \(N, 4, 4\), got \(4, 16\)"):
        qs.project_many(poses.reshape(4, 16), axes, cam)
    with pytest.raises(ValueError, match="4 poses but 3 rows of axes"):
        qs.bounds_many(poses, axes[:3], cam)
    with pytest.raises(ValueError, match="errors: must be 'raise' or 'nan'"):
        qs.project_many(poses, axes, cam, errors="ignore")
    behind = poses.copy()
    behind[1, 2, 3] = -15.0
    with pytest.raises(qs.ProjectionError, match=r"^ellipsoid 1: ellipsoid is behind the camera"):
        qs.project_many(behind, axes, cam)
    out = qs.project_many(behind, axes, cam, errors="nan")
    assert np.isnan(out[1]).all() and np.isfinite(out[[0, 2, 3]]).all()
    # an empty batch is an empty answer
    assert qs.project_many(np.zeros((0, 4, 4)), np.zeros((0, 3)), cam).shape == (0, 3, 3)


def level_views(n: int, spread: float = 1.0):
    """n cameras along a straight, level road looking ahead at a car; its true boxes."""
    car = qs.Ellipsoid(car_pose(20.0), [2.1, 0.8, 0.85])
    cams = []
    for i in range(n):
        pose = np.eye(4)
        pose[2, 3] = spread * i
        cams.append(qs.Camera(K, pose))
    return cams, [qs.project(car, c).bounds() for c in cams]


def test_degenerate_views_raise_init_errors():
    cams, boxes = level_views(4)
    with pytest.raises(qs.InitError, match=r"^Q-SLAM: too few views: got 2, need 3$"):
        qs.QSlamSvd().initialize(cams[:2], boxes[:2])
    # all cameras at one place: no baseline
    same = [qs.Camera(K)] * 3
    with pytest.raises(qs.InitError, match="all cameras at one centre"):
        qs.Tri().initialize(same, boxes[:3])
    # a straight level drive leaves one entry of Q* unobserved: QuadricSLAM's SVD says so
    with pytest.raises(qs.InitError, match="degenerate views"):
        qs.QSlamSvd().initialize(cams, boxes)
    # ... while DQP, whose yaw-only model removes that entry, solves it (the depth from 3 m of travel
    # straight towards the car is weakly observed: decimetres)
    truth = qs.Ellipsoid(car_pose(20.0), [2.1, 0.8, 0.85])
    assert qs.e_trans(qs.Dqp(centre_correction=True).initialize(cams, boxes), truth) < 0.2
    with pytest.raises(ValueError, match=r"^boxes\[1\]: box is empty"):
        qs.Dqp().initialize(cams[:3], [boxes[0], [10, 10, 5, 20], boxes[2]])
    with pytest.raises(ValueError, match=r"^boxes\[1\]: holds NaN or infinity$"):
        qs.Dqp().initialize(cams[:3], [boxes[0], [math.nan, 0, 1, 1], boxes[2]])
    with pytest.raises(ValueError, match="3 cameras but 2 boxes"):
        qs.Conic().initialize(cams[:3], boxes[:2])
    with pytest.raises(ValueError, match=r"^cameras\[1\]: expected a Camera, got str"):
        qs.Conic().initialize([cams[0], "camera", cams[2]], boxes[:3])
    with pytest.raises(ValueError, match="cameras: expected a sequence of Camera"):
        qs.Conic().initialize(5, boxes[:3])


def test_metrics_refuse_what_has_no_value():
    truth = qs.Ellipsoid(car_pose(), [2.0, 0.8, 0.9])
    with pytest.raises(ValueError, match="up .* is zero"):
        qs.e_yaw(truth, truth, up=[0, 0, 0])
    assert qs.e_yaw(truth, truth) == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match=r"^up: expected shape \(3,\)"):
        qs.e_yaw(truth, truth, up=[0, 1])
