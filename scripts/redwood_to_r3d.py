"""Writes a Redwood / Open3D folder (color/, depth/ in mm, a .log trajectory) as a Record3D
`.r3d` export, the way an iPhone's LiDAR records: depth at a quarter of the color
resolution in float32 metres (LZFSE), ARKit poses (camera looking down -z, y up). For
trying `relume import record3d` on real images:

    python scripts/redwood_to_r3d.py ../shared/data/livingroom1 lr.r3d [--frames N]

Needs numpy, pillow and pyliblzfse. The Redwood intrinsics (PrimeSense: fx = fy = 525,
centre 319.5, 239.5) go into the metadata's K.
"""

import argparse
import json
import math
import zipfile
from pathlib import Path

import liblzfse
import numpy as np
from PIL import Image


def read_log(path):
    """Camera-to-world 4x4 matrices (optical frame: y down, z forward)."""
    lines = [l.split() for l in Path(path).read_text().splitlines() if l.strip()]
    return [np.array(lines[i + 1:i + 5], dtype=float) for i in range(0, len(lines), 5)]


def quaternion(r):
    """x, y, z, w of a rotation matrix."""
    w = math.sqrt(max(0.0, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    return [x, y, z, w]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder")
    ap.add_argument("out")
    ap.add_argument("--frames", type=int, default=None)
    a = ap.parse_args()
    folder = Path(a.folder)
    colors = sorted((folder / "color").glob("*"))
    depths = sorted((folder / "depth").glob("*.png"))
    poses = read_log(next(folder.glob("*.log")))
    n = min(len(colors), len(depths), len(poses), a.frames or 1 << 30)
    w, h = Image.open(colors[0]).size
    flip = np.diag([1.0, -1.0, -1.0])  # optical camera axes to ARKit's
    meta = {
        "w": w, "h": h, "dw": w // 4, "dh": h // 4, "fps": 30, "cameraType": 1,
        "K": [525.0, 0.0, 0.0, 0.0, 525.0, 0.0, 319.5, 239.5, 1.0],
        "poses": [quaternion(p[:3, :3] @ flip) + list(p[:3, 3]) for p in poses[:n]],
    }
    with zipfile.ZipFile(a.out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("metadata", json.dumps(meta))
        for k in range(n):
            z.writestr(f"rgbd/{k}.jpg", colors[k].read_bytes(), compress_type=zipfile.ZIP_STORED)
            mm = np.asarray(Image.open(depths[k]), dtype=np.float32)
            # The depth pixel of each 4x4 block nearest its centre.
            metres = (mm[1::4, 1::4] / 1000.0).astype("<f4")
            z.writestr(f"rgbd/{k}.depth", liblzfse.compress(metres.tobytes()))
    print(f"wrote {a.out}: {n} frames, color {w}x{h}, depth {w // 4}x{h // 4}")


if __name__ == "__main__":
    main()
