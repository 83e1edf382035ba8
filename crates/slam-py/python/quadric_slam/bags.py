"""A stereo drive recorded as a ROS bag, turned into the KITTI odometry layout ``slam-app run`` reads.

    from quadric_slam import bags
    seq = bags.to_kitti("drive.bag", "out/drive")          # → out/drive/sequences/00

ROS 1 bags (``.bag``) and ROS 2 bags (a folder with ``metadata.yaml``) are read with the ``rosbags``
package (pure Python; ``pip install 'quadric-slam[bags]'``). The left and right images come from two
topics (``sensor_msgs/Image`` in ``mono8``, ``rgb8`` or ``bgr8``, or ``sensor_msgs/CompressedImage`` in PNG),
their calibration from the ``camera_info`` topic beside each (``/cam/left/image_raw`` →
``/cam/left/camera_info``): its projection matrix ``P`` is the rectified camera's, as KITTI's ``calib.txt``
holds it (the right camera's ``P[0][3] = -fx * baseline``), so the images must be rectified already (the
``image_rect`` topics of ``stereo_image_proc``). A left and a right image with the same header stamp
(within ``max_skew`` seconds) are one frame; frames are numbered 0, 1, ... in time order, and
``times.txt`` holds their stamps from the first. Colour images are written as grey (ITU-R BT.601 weights,
as OpenCV converts them), which is what the tracker uses.

Every refusal is a ``BagError`` (a ValueError) naming the bag and what is missing: a topic, its
camera_info, a frame's partner, an encoding not read here (JPEG: decode it first).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

from .results import PathLike

#: Image topics tried when none is given: the first pair present in the bag.
DEFAULT_TOPICS = (
    ("/stereo/left/image_rect", "/stereo/right/image_rect"),
    ("/camera/left/image_rect", "/camera/right/image_rect"),
    ("/left/image_rect", "/right/image_rect"),
    ("/stereo/left/image_raw", "/stereo/right/image_raw"),
    ("/camera/left/image_raw", "/camera/right/image_raw"),
    ("/left/image_raw", "/right/image_raw"),
)


class BagError(ValueError):
    """A bag that cannot be turned into a stereo sequence."""


def is_bag(path: PathLike) -> bool:
    """A ROS 1 bag file or a ROS 2 bag folder."""
    p = Path(path)
    return (p.is_file() and p.suffix == ".bag") or (p.is_dir() and (p / "metadata.yaml").is_file())


def png_bytes(grey: np.ndarray) -> bytes:
    """An 8-bit greyscale image as PNG (no filter, zlib level 6)."""
    if grey.dtype != np.uint8 or grey.ndim != 2:
        raise ValueError("png_bytes: an (H, W) uint8 image")
    h, w = grey.shape
    raw = b"".join(b"\x00" + grey[y].tobytes() for y in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def _grey(msg, where: str) -> bytes:
    """PNG bytes of one image message."""
    if hasattr(msg, "format"):  # CompressedImage
        data = bytes(msg.data)
        if data[:8] != b"\x89PNG\r\n\x1a\n":
            raise BagError(f"{where}: a compressed image in {msg.format!r}; only PNG is read (decode JPEG first)")
        return data
    h, w, step, enc = int(msg.height), int(msg.width), int(msg.step), str(msg.encoding)
    channels = {"mono8": 1, "8UC1": 1, "rgb8": 3, "bgr8": 3}.get(enc)
    if channels is None:
        raise BagError(f"{where}: image encoding {enc!r} is not read (mono8, rgb8 or bgr8)")
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if h <= 0 or w <= 0 or step < w * channels or len(data) < h * step:
        raise BagError(f"{where}: {len(data)} bytes for a {w}x{h} {enc} image of row step {step}")
    rows = data[: h * step].reshape(h, step)[:, : w * channels]
    if channels == 1:
        return png_bytes(np.ascontiguousarray(rows))
    rgb = rows.reshape(h, w, 3).astype(np.float64)
    if enc == "bgr8":
        rgb = rgb[:, :, ::-1]
    grey = np.rint(rgb @ np.array([0.299, 0.587, 0.114])).clip(0, 255).astype(np.uint8)
    return png_bytes(grey)


def _stamp(msg) -> int:
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def _projection(msg) -> List[float]:
    p = getattr(msg, "p", None)
    if p is None:
        p = getattr(msg, "P", None)
    values = [float(v) for v in p] if p is not None else []
    if len(values) != 12:
        raise BagError(f"camera_info without a 3x4 projection matrix P ({len(values)} numbers)")
    return values


def to_kitti(
    bag: PathLike,
    out_dir: PathLike,
    left: Optional[str] = None,
    right: Optional[str] = None,
    max_skew: float = 0.005,
) -> Path:
    """Write the stereo images of a ROS bag as a KITTI odometry sequence ``out_dir/sequences/00`` (image_0,
    image_1, calib.txt, times.txt) and return that folder.

    Args:
        bag: a ROS 1 ``.bag`` file or a ROS 2 bag folder.
        out_dir: where to write (created; must not hold a sequence already).
        left, right: the image topics; None: the first pair of ``DEFAULT_TOPICS`` in the bag.
        max_skew: the largest difference of a left and a right stamp taken as one frame, seconds.

    Raises:
        BagError: the bag cannot be read, or lacks what a stereo sequence needs (the message says what).
    """
    try:
        from rosbags.highlevel import AnyReader
    except ImportError:
        raise BagError("reading a bag needs the rosbags package: pip install 'quadric-slam[bags]'") from None
    bag = Path(bag)
    seq = Path(out_dir) / "sequences" / "00"
    if seq.exists():
        raise BagError(f"{seq}: exists already")
    images: Dict[str, List[Tuple[int, bytes]]] = {}
    infos: Dict[str, List[float]] = {}
    try:
        with AnyReader([bag]) as reader:
            topics = {c.topic for c in reader.connections}
            if left is None or right is None:
                pair = next(((a, b) for a, b in DEFAULT_TOPICS if a in topics and b in topics), None)
                if pair is None:
                    raise BagError(f"{bag}: no stereo image topics found (give left= and right=); it has {sorted(topics)}")
                left, right = pair
            wanted = (left, right)
            info_topic = {t: t.rsplit("/", 1)[0] + "/camera_info" for t in wanted}
            for t in [*wanted, *info_topic.values()]:  # in this order: the message names the first missing
                if t not in topics:
                    raise BagError(f"{bag}: no topic {t}")
            connections = [c for c in reader.connections if c.topic in wanted or c.topic in info_topic.values()]
            for conn, _, raw in reader.messages(connections=connections):
                msg = reader.deserialize(raw, conn.msgtype)
                if conn.topic in wanted:
                    where = f"{bag}: {conn.topic} at {_stamp(msg)} ns"
                    images.setdefault(conn.topic, []).append((_stamp(msg), _grey(msg, where)))
                elif conn.topic not in infos:
                    try:
                        infos[conn.topic] = _projection(msg)
                    except BagError as e:
                        raise BagError(f"{bag}: {conn.topic}: {e}") from None
    except BagError:
        raise
    except Exception as e:  # rosbags' own errors: a file that is not a bag, a truncated chunk
        raise BagError(f"{bag}: not readable as a ROS bag: {type(e).__name__}: {e}") from None
    for t in (left, right):
        if not images.get(t):
            raise BagError(f"{bag}: no image on {t}")
        if info_topic[t] not in infos:
            raise BagError(f"{bag}: no message on {info_topic[t]}")
    pairs = _pair(images[left], images[right], int(max_skew * 1e9), bag)
    (seq / "image_0").mkdir(parents=True)
    (seq / "image_1").mkdir()
    for k, ((_, l_png), (_, r_png)) in enumerate(pairs):
        (seq / "image_0" / f"{k:06}.png").write_bytes(l_png)
        (seq / "image_1" / f"{k:06}.png").write_bytes(r_png)
    p0, p1 = infos[info_topic[left]], infos[info_topic[right]]
    (seq / "calib.txt").write_text(
        "".join(f"{name}: {' '.join(f'{v:.12e}' for v in p)}\n" for name, p in (("P0", p0), ("P1", p1)))
    )
    t0 = pairs[0][0][0]
    (seq / "times.txt").write_text("".join(f"{(first[0] - t0) * 1e-9:.9e}\n" for first, _ in pairs))
    return seq


def _pair(lefts, rights, skew_ns: int, bag: Path):
    """Left and right images of one frame: each left with the right nearest in time, within skew_ns."""
    lefts = sorted(lefts, key=lambda x: x[0])
    rights = sorted(rights, key=lambda x: x[0])
    stamps = np.array([r[0] for r in rights], dtype=np.int64)
    pairs = []
    for stamp, png in lefts:
        k = int(np.searchsorted(stamps, stamp))
        near = [j for j in (k - 1, k) if 0 <= j < len(stamps)]
        j = min(near, key=lambda j: abs(int(stamps[j]) - stamp))
        if abs(int(stamps[j]) - stamp) > skew_ns:
            raise BagError(f"{bag}: the left image at {stamp} ns has no right image within {skew_ns * 1e-9:.3f} s")
        pairs.append(((stamp, png), rights[j]))
    if len({r[0] for _, r in pairs}) != len(pairs):
        raise BagError(f"{bag}: two left images share one right image (the cameras' rates differ)")
    return pairs
