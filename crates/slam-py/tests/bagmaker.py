"""Writes a ROS 1 stereo bag from the shipped odometry excerpt, for the bag tests (test_bags.py, test_fleet.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

FRAMES = 12
SEQUENCE = Path("fixtures/kitti_odom_06/sequences/06")


def calib(repo) -> dict:
    rows = {}
    for line in (repo / SEQUENCE / "calib.txt").read_text().splitlines():
        name, _, values = line.partition(":")
        rows[name] = [float(v) for v in values.split()]
    return rows


def write_bag(
    path: Path, repo: Path, frames: int = FRAMES, right: bool = True, info: bool = True, encoding="mono8", ros2=False
):
    """A stereo bag of the excerpt's first frames at 10 Hz: ROS 1 (a .bag file) or ROS 2 (a folder, sqlite3)."""
    from rosbags.typesys import Stores, get_typestore

    if ros2:
        from rosbags.rosbag2 import Writer

        ts = get_typestore(Stores.ROS2_HUMBLE)
        opened = Writer(path, version=9)
        serialize = ts.serialize_cdr
    else:
        from rosbags.rosbag1 import Writer

        ts = get_typestore(Stores.ROS1_NOETIC)
        opened = Writer(path)
        serialize = ts.serialize_ros1
    Img, Info = ts.types["sensor_msgs/msg/Image"], ts.types["sensor_msgs/msg/CameraInfo"]
    Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    RoI = ts.types["sensor_msgs/msg/RegionOfInterest"]
    p = calib(repo)
    sides = [("left", "image_0", p["P0"])] + ([("right", "image_1", p["P1"])] if right else [])
    with opened as w:
        conns = {}
        for side, _, _ in sides:
            conns[side] = w.add_connection(f"/stereo/{side}/image_rect", Img.__msgtype__, typestore=ts)
            if info:
                conns[side + "_info"] = w.add_connection(f"/stereo/{side}/camera_info", Info.__msgtype__, typestore=ts)
        for k in range(frames):
            stamp = 1_300_000_000 * 10**9 + k * 100_000_000
            time = Time(sec=stamp // 10**9, nanosec=stamp % 10**9)
            header = Header(stamp=time, frame_id="cam") if ros2 else Header(seq=k, stamp=time, frame_id="cam")
            for side, folder, proj in sides:
                pixels = np.asarray(Image.open(repo / SEQUENCE / folder / f"{k:06}.png"))
                h, w_ = pixels.shape
                if encoding == "rgb8":
                    data, step = np.repeat(pixels[:, :, None], 3, axis=2).ravel(), 3 * w_
                else:
                    data, step = pixels.ravel(), w_
                msg = Img(header=header, height=h, width=w_, encoding=encoding, is_bigendian=0, step=step, data=data)
                w.write(conns[side], stamp, serialize(msg, Img.__msgtype__))
                if info and k == 0:
                    roi = RoI(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
                    matrices = {
                        "d": np.zeros(5),
                        "k": np.array(proj)[[0, 1, 2, 4, 5, 6, 8, 9, 10]],
                        "r": np.eye(3).ravel(),
                        "p": np.array(proj),
                    }
                    if not ros2:  # ROS 1 names them in capitals
                        matrices = {name.upper(): m for name, m in matrices.items()}
                    cam = Info(header=header, height=h, width=w_, distortion_model="plumb_bob", binning_x=0, binning_y=0, roi=roi, **matrices)
                    w.write(conns[side + "_info"], stamp, serialize(cam, Info.__msgtype__))
    return path
