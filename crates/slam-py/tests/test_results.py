"""load_run on the main job's output, checked against what the files hold independently (map.json's
keyframe poses and per-frame relative poses, the printed summary), run() from Python, and the errors of
files that are missing or malformed."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest

import quadric_slam as qs
from quadric_slam import results


def test_main_job_as_arrays(main_job):
    r = qs.load_run(main_job)
    printed = (main_job.parent / "stdout.txt").read_text()
    # 51 frames, ids 0..=50, every one with a pose
    assert r.frames == 51
    assert r.frame_ids.tolist() == list(range(51))
    assert r.pose_frame_ids.tolist() == list(range(51))
    assert r.trajectory.shape == (51, 4, 4) and r.states.shape == (51,)
    np.testing.assert_allclose(r.trajectory[0], np.eye(4), atol=1e-9)
    rot = r.trajectory[:, :3, :3]
    np.testing.assert_allclose(rot @ rot.transpose(0, 2, 1), np.broadcast_to(np.eye(3), rot.shape), atol=1e-8)
    # the tracking states as the run printed them
    states = re.search(r"tracking states: tracked (\d+), weak (\d+), relocalised (\d+), lost (\d+)", printed)
    assert states is not None
    assert [r.count(s) for s in ("tracked", "weak", "relocalised", "lost")] == [int(x) for x in states.groups()]
    assert r.states[0] == "initialised"
    # the trajectory equals map.json's keyframe poses composed with each frame's relative pose
    m = json.loads((main_job / "map.json").read_text())
    for i, t in enumerate(m["trajectory"]):
        kf = results.quaternion_pose(m["keyframes"][str(t["keyframe"])]["pose"])
        composed = kf @ results.quaternion_pose(t["relative"])
        np.testing.assert_allclose(r.trajectory[i], composed, atol=2e-8 * max(1.0, np.abs(composed).max()))
    # keyframes, points and objects: the counts the run printed
    line = re.search(r"map: (\d+) keyframes, (\d+) points, \d+ observations; objects: (\d+) with an ellipsoid", printed)
    assert line is not None
    assert len(r.keyframe_ids) == int(line[1]) and r.points.shape == (int(line[2]), 3)
    assert len(r.objects) == int(line[3]) > 0
    assert np.isfinite(r.points).all()
    assert len(set(r.objects.ids.tolist())) == len(r.objects)
    assert set(r.objects.class_names) <= {"person", "bicycle", "car", "motorcycle", "bus", "truck"}
    # each object, back through the geometry: an ellipsoid in front of the camera of a frame that saw it
    camera = r.camera
    assert camera["fx"] == pytest.approx(707.0912) and camera["baseline"] == pytest.approx(0.537, abs=1e-3)
    K = [[camera["fx"], 0, camera["cx"]], [0, camera["fy"], camera["cy"]], [0, 0, 1]]
    for e, frames in zip(r.objects.ellipsoids(), r.objects.frames):
        k = int(np.searchsorted(r.pose_frame_ids, frames[-1]))
        box = qs.project(e, qs.Camera(K, r.trajectory[k])).clipped_bounds((camera["width"], camera["height"]))
        assert box[2] > box[0] and box[3] > box[1]
    # the ATE the run printed
    truth = results.ground_truth_errors(printed)
    assert truth is not None and 0 < truth["ate_aligned_m"] <= truth["ate_m"] < 5


def test_run_from_python(tmp_path, slam_app, repo):
    out = tmp_path / "short"
    r = qs.run(repo / "fixtures/kitti_odom_06/sequences/06", out, slam_app=slam_app, frames="0..8", detector="none")
    assert r.frames == 8 and r.frame_ids.tolist() == list(range(8))
    assert r.log is not None and "8 frames in" in r.log
    assert r.ground_truth_errors() is not None
    assert len(r.objects) == 0  # no detector
    assert qs.load_run(out).trajectory.tolist() == r.trajectory.tolist()
    with pytest.raises(qs.RunError, match=r"exit status 1: error: .*not a KITTI stereo sequence"):
        qs.run(tmp_path, tmp_path / "none", slam_app=slam_app)
    with pytest.raises(qs.RunError, match="not an executable slam-app"):
        qs.run(None, tmp_path / "none", slam_app=tmp_path / "no-such-program")


def test_options_from_keywords():
    assert results.options({"frames": "0..20", "no_ba": True, "stride": 2, "detector": None, "overlays": False}) == [
        "--frames",
        "0..20",
        "--no-ba",
        "--stride",
        "2",
    ]


@pytest.fixture()
def copied(main_job, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(main_job, out)
    return out


def test_missing_and_malformed_files_are_named(copied, tmp_path):
    (copied / "objects.json").unlink()
    with pytest.raises(qs.RunError, match=r"objects\.json: missing"):
        qs.load_run(copied)
    with pytest.raises(qs.RunError, match="not a folder"):
        qs.load_run(tmp_path / "nothing")


def test_a_bad_trajectory_line_is_named(copied):
    lines = (copied / "trajectory.kitti.txt").read_text().splitlines()
    lines[3] = " ".join(lines[3].split()[:11])
    (copied / "trajectory.kitti.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(qs.RunError, match=r"trajectory\.kitti\.txt line 4: expected 12 finite numbers"):
        qs.load_run(copied)


def test_files_of_two_runs_are_refused(copied):
    lines = (copied / "trajectory.kitti.txt").read_text().splitlines()
    (copied / "trajectory.kitti.txt").write_text("\n".join(lines[:-1]) + "\n")
    with pytest.raises(qs.RunError, match="50 poses but map.json's trajectory places 51 frames"):
        qs.load_run(copied)


def test_bad_tracking_and_objects_are_named(copied):
    text = (copied / "tracking.csv").read_text().replace(",tracked,", ",flying,", 1)
    (copied / "tracking.csv").write_text(text)
    with pytest.raises(qs.RunError, match=r"tracking\.csv line \d+: unknown tracking state 'flying'"):
        qs.load_run(copied)


def test_bad_object_is_named(copied):
    doc = json.loads((copied / "objects.json").read_text())
    doc["objects"][0]["semi_axes"] = [1.0, "wide", 1.0]
    (copied / "objects.json").write_text(json.dumps(doc))
    with pytest.raises(qs.RunError, match=r"objects\[0\]\.semi_axes: 'wide' is not a finite number"):
        qs.load_run(copied)
