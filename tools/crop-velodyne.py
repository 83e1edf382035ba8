#!/usr/bin/env python3
"""Keep the points of KITTI Velodyne scans that fall inside the left grey image (camera 0).

Usage: crop-velodyne.py DATE_DIR SCAN.bin... OUT_DIR
DATE_DIR holds calib_velo_to_cam.txt and calib_cam_to_cam.txt. Each output file keeps KITTI's format
(float32 x, y, z, reflectance per point, Velodyne frame) and the kept points' bytes unchanged; only the
points that project into the image (with a 10 px margin) at least 0.5 m in front of the camera are kept.
Pure Python (no numpy), so it runs anywhere the tests do.
"""
import os
import struct
import sys


def read_calib(path):
    values = {}
    with open(path) as f:
        for line in f:
            key, _, rest = line.partition(":")
            try:
                values[key.strip()] = [float(x) for x in rest.split()]
            except ValueError:
                pass
    return values


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    date_dir, scans, out_dir = sys.argv[1], sys.argv[2:-1], sys.argv[-1]
    velo = read_calib(os.path.join(date_dir, "calib_velo_to_cam.txt"))
    cam = read_calib(os.path.join(date_dir, "calib_cam_to_cam.txt"))
    r, t = velo["R"], velo["T"]
    rr = cam["R_rect_00"]
    p = cam["P_rect_00"]
    width, height = cam["S_rect_00"]
    os.makedirs(out_dir, exist_ok=True)
    for scan in scans:
        data = open(scan, "rb").read()
        kept = bytearray()
        total = len(data) // 16
        for i in range(total):
            chunk = data[16 * i: 16 * i + 16]
            x, y, z, _ = struct.unpack("<4f", chunk)
            c = [r[3 * k] * x + r[3 * k + 1] * y + r[3 * k + 2] * z + t[k] for k in range(3)]
            q = [rr[3 * k] * c[0] + rr[3 * k + 1] * c[1] + rr[3 * k + 2] * c[2] for k in range(3)]
            if q[2] < 0.5:
                continue
            u = (p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3]) / q[2]
            v = (p[5] * q[1] + p[6] * q[2] + p[7]) / q[2]
            if -10 <= u <= width + 10 and -10 <= v <= height + 10:
                kept += chunk
        out = os.path.join(out_dir, os.path.basename(scan))
        with open(out, "wb") as f:
            f.write(kept)
        print(f"{scan}: kept {len(kept) // 16} of {total} points -> {out}")


if __name__ == "__main__":
    main()
