"""A stereo drive recorded as a ROS 1 bag: written here from the shipped odometry excerpt (mono8 images,
camera_info with KITTI's projection matrices, 10 Hz stamps), turned back into a KITTI sequence with the
same pixels and calibration, mapped by a fleet task with the same results as slam-app on the excerpt;
bags that lack what a stereo sequence needs are refused naming what is missing."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from bagmaker import FRAMES, SEQUENCE, calib, write_bag
from PIL import Image

from quadric_slam import bags, fleet

@pytest.fixture(scope="module")
def bag(repo, tmp_path_factory) -> Path:
    return write_bag(tmp_path_factory.mktemp("bag") / "drive06.bag", repo)


def test_a_bag_becomes_the_same_sequence(bag, repo, tmp_path):
    assert bags.is_bag(bag) and not bags.is_bag(repo / SEQUENCE)
    seq = bags.to_kitti(bag, tmp_path / "kitti")
    assert seq == tmp_path / "kitti" / "sequences" / "00"
    for folder in ("image_0", "image_1"):
        names = sorted(p.name for p in (seq / folder).iterdir())
        assert names == [f"{k:06}.png" for k in range(FRAMES)]
        for k in (0, FRAMES - 1):
            ours = np.asarray(Image.open(seq / folder / f"{k:06}.png"))
            original = np.asarray(Image.open(repo / SEQUENCE / folder / f"{k:06}.png"))
            assert ours.dtype == np.uint8 and np.array_equal(ours, original)
    written = {}
    for line in (seq / "calib.txt").read_text().splitlines():
        name, _, values = line.partition(":")
        written[name] = [float(v) for v in values.split()]
    assert written == {"P0": calib(repo)["P0"], "P1": calib(repo)["P1"]}
    times = [float(t) for t in (seq / "times.txt").read_text().split()]
    assert times == pytest.approx([0.1 * k for k in range(FRAMES)], abs=1e-9)
    with pytest.raises(bags.BagError, match="exists already"):
        bags.to_kitti(bag, tmp_path / "kitti")


def test_a_ros2_bag_too(repo, tmp_path):
    bag = write_bag(tmp_path / "drive06_ros2", repo, frames=3, ros2=True)
    assert bags.is_bag(bag)
    seq = bags.to_kitti(bag, tmp_path / "kitti")
    assert sorted(p.name for p in (seq / "image_1").iterdir()) == ["000000.png", "000001.png", "000002.png"]
    ours = np.asarray(Image.open(seq / "image_1" / "000002.png"))
    assert np.array_equal(ours, np.asarray(Image.open(repo / SEQUENCE / "image_1" / "000002.png")))
    assert (seq / "calib.txt").read_text().splitlines()[1].split()[4] == f"{calib(repo)['P1'][3]:.12e}"


def test_colour_images_are_written_grey(repo, tmp_path):
    bag = write_bag(tmp_path / "rgb.bag", repo, frames=2, encoding="rgb8")
    seq = bags.to_kitti(bag, tmp_path / "kitti")
    ours = np.asarray(Image.open(seq / "image_0" / "000001.png"))
    assert np.array_equal(ours, np.asarray(Image.open(repo / SEQUENCE / "image_0" / "000001.png")))


def test_a_fleet_task_maps_a_bag_as_the_folder(bag, repo, slam_app, tmp_path):
    import subprocess

    direct = tmp_path / "direct"
    subprocess.run([str(slam_app), "run", str(SEQUENCE), "--out", str(direct), "--frames", f"0..{FRAMES}"], cwd=repo, check=True, capture_output=True)
    result = fleet.map_one({"path": str(bag), "options": [], "slam_app": str(slam_app), "cwd": str(repo)})
    assert result["status"] == "done", result.get("error")
    assert result["frames"] == FRAMES and result["ate_m"] is None  # a bag brings no ground truth
    run = tmp_path / "from-bag"
    fleet._unpack(result["archive"], run)
    for name in ("trajectory.kitti.txt", "objects.json", "camera.json"):
        assert (run / name).read_bytes() == (direct / name).read_bytes(), name

    def states(path):
        with open(path, newline="") as f:
            return [row[:-1] for row in csv.reader(f)]

    assert states(run / "tracking.csv") == states(direct / "tracking.csv")


def test_bags_missing_what_a_sequence_needs_are_refused(repo, tmp_path):
    no_right = write_bag(tmp_path / "mono.bag", repo, frames=2, right=False)
    with pytest.raises(bags.BagError, match="no stereo image topics found"):
        bags.to_kitti(no_right, tmp_path / "a")
    with pytest.raises(bags.BagError, match="no topic /stereo/right/image_rect"):
        bags.to_kitti(no_right, tmp_path / "b", left="/stereo/left/image_rect", right="/stereo/right/image_rect")
    no_info = write_bag(tmp_path / "noinfo.bag", repo, frames=2, info=False)
    with pytest.raises(bags.BagError, match="no topic /stereo/left/camera_info"):
        bags.to_kitti(no_info, tmp_path / "c")
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"not a bag at all")
    with pytest.raises(bags.BagError, match="not readable as a ROS bag"):
        bags.to_kitti(junk, tmp_path / "d")
    # in a fleet task the refusal is the drive's error, not a crash of the task
    r = fleet.map_one({"path": str(junk), "options": [], "slam_app": None, "cwd": None})
    assert r["status"] == "failed" and "not readable as a ROS bag" in r["error"]
