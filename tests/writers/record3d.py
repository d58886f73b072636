"""Writes a Record3D `.r3d` export as record3d issue #93 describes it (a ZIP of metadata
JSON, rgbd/N.jpg and LZFSE-compressed float32 rgbd/N.depth), with Python's zipfile,
Pillow's JPEG encoder and pyliblzfse: writers independent of relume. For its tests.

    python record3d.py OUT.r3d FRAMES [noposes|stored]

Color 96x72, depth 32x24 (the same field of view; `--small`: 12x9 and 4x3): frame k's depth is a wall at
1.5 + 0.01 k m (0 in its top-left pixel: no measurement), its color a gradient. Poses:
ARKit camera-to-world [qx, qy, qz, qw, px, py, pz], a turn of 0.1 k rad about y and a
step of 0.2 k m along x. K is column-major: fx 80, fy 81, cx 47.5, cy 35.5. fps 30.
"""

import io
import json
import math
import sys
import zipfile

import liblzfse
import numpy as np
from PIL import Image

W, H, DW, DH = 96, 72, 32, 24
if "--small" in sys.argv:
    sys.argv.remove("--small")
    W, H, DW, DH = 12, 9, 4, 3


def pose(k):
    half = 0.1 * k / 2
    return [0.0, math.sin(half), 0.0, math.cos(half), 0.2 * k, 1.0, 0.5]


def main():
    out, frames = sys.argv[1], int(sys.argv[2])
    flag = sys.argv[3] if len(sys.argv) > 3 else ""
    with_poses = flag != "noposes"
    # `stored`: no deflate, for fuzzing seeds whose mutations should reach the entries.
    method = zipfile.ZIP_STORED if flag == "stored" else zipfile.ZIP_DEFLATED
    meta = {
        "w": W, "h": H, "dw": DW, "dh": DH, "fps": 30,
        "K": [W * 80 / 96, 0.0, 0.0, 0.0, H * 81 / 72, 0.0, (W - 1) / 2, (H - 1) / 2, 1.0],
        "cameraType": 1,
        "poses": [pose(k) for k in range(frames)] if with_poses else [],
    }
    with zipfile.ZipFile(out, "w", method) as z:
        z.writestr("metadata", json.dumps(meta))
        for k in range(frames):
            y, x = np.mgrid[0:H, 0:W]
            rgb = np.stack([(x * 2 + k) % 256, (y * 3) % 256, np.full_like(x, 90)], -1)
            jpeg = io.BytesIO()
            Image.fromarray(rgb.astype(np.uint8)).save(jpeg, "JPEG", quality=90)
            z.writestr(f"rgbd/{k}.jpg", jpeg.getvalue(), compress_type=zipfile.ZIP_STORED)
            depth = np.full((DH, DW), 1.5 + 0.01 * k, dtype="<f4")
            depth[0, 0] = 0.0
            z.writestr(f"rgbd/{k}.depth", liblzfse.compress(depth.tobytes()))
            z.writestr(f"rgbd/{k}.conf", liblzfse.compress(np.full((DH, DW), 2, np.uint8).tobytes()))


if __name__ == "__main__":
    main()
