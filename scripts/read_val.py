#!/usr/bin/env python3
"""Reads the light-model records (`.val`) that relume's `write` stage saves for the
`lights` product (paper 004's area lights and SH9), and prints them as JSON: a reader
written from the documented layout alone (crates/scene/src/light/record.rs), standard library only.

    scripts/read_val.py out/val/lights/000000.val [more.val ...]
"""

import json
import struct
import sys


def decode_normal(u, v):
    u, v = u / 32767.0, v / 32767.0
    y = 1.0 - abs(u) - abs(v)
    if y < 0.0:
        sign = lambda c: 1.0 if c >= 0.0 else -1.0
        u, v = (1.0 - abs(v)) * sign(u), (1.0 - abs(u)) * sign(v)
    n = (u * u + y * y + v * v) ** 0.5
    return [u / n, y / n, v / n]


def read(path):
    data = open(path, "rb").read()
    if data[:4] != b"RVAL":
        raise ValueError(f"{path}: not a light-model record")
    version, count = struct.unpack_from("<HH", data, 4)
    if version != 1:
        raise ValueError(f"{path}: version {version}, this reader knows 1")
    if len(data) != 8 + 32 * count + 108:
        raise ValueError(f"{path}: {len(data)} bytes for {count} lights")
    lights = []
    for j in range(count):
        px, py, pz, nu, nv, ir, ig, ib, area = struct.unpack_from("<3f2h4f", data, 8 + 32 * j)
        lights.append({
            "position": [px, py, pz],
            "normal": decode_normal(nu, nv),
            "intensity": [ir, ig, ib],
            "area": area,
        })
    sh = struct.unpack_from("<27f", data, 8 + 32 * count)
    return {"lights": lights, "sh9": [list(sh[3 * k:3 * k + 3]) for k in range(9)]}


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    print(json.dumps({path: read(path) for path in sys.argv[1:]}, indent=1))
