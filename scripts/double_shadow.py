#!/usr/bin/env python3
"""Paper 002's double shadow (Sec. 3.3, Fig. 5) on the synthetic room, against its truth.

    scripts/double_shadow.py [--relume PATH] [--out DIR] [--frame 14]

Makes the recording with the room's real lamp switched on (`relume synth --lamp-on-at
0`), runs `relume compare` with pipelines/mixed-reality-dir-room-lamp.toml (the paper's
two shadow maps and flags) and its twin -knecht2010 (the earlier method [4]: one map
per light, its front-most blocker alone decides), and scores both against the true
frame: the room with the virtual box really in it, path traced.

Besides compare's scores it measures the two regions of Fig. 5 on the frame:
- "unchanged by the truth": pixels whose truth is the recorded pixel within one level
  in every channel. The floor and wall behind the real block, which the block already
  shadows from the lamp, are among them: a method that darkens them there shadows
  them twice.
- "true shadows": pixels the truth darkens by four levels or more in every channel
  (the box's shadow on the floor and on the block's face).
- "the truth's faint changes": the rest of the pixels the truth changes, by less than
  four levels in some channel: mostly the light the box takes from the bounce (real
  surfaces it shadows bleed less onto their neighbours) and its own bleeding. Paper 002
  Fig. 6: [4] keeps the bleeding of a real surface the box shadows (no ir = 1 VPL
  there); its mean change there, against the truth's, shows that inconsistency.
and writes figure.png: recorded | truth | paper's flags | [4], cropped around the block.
Standard library only (a small PNG reader and writer for 8-bit RGB).
"""

import argparse
import json
import os
import struct
import subprocess
import sys
import zlib

PIPELINES = {
    "paper": "pipelines/mixed-reality-dir-room-lamp.toml",
    "knecht2010": "pipelines/mixed-reality-dir-room-lamp-knecht2010.toml",
}
CROP = (300, 150, 640, 480)


def read_png(path):
    """Rows of (r, g, b) tuples of an 8-bit, non-interlaced RGB or RGBA PNG."""
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        sys.exit(f"{path}: not a PNG")
    pos, idat, width, height, channels = 8, b"", 0, 0, 3
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        pos += 12 + n
        if kind == b"IHDR":
            width, height, depth, color, _, _, interlace = struct.unpack(">IIBBBBB", body)
            if depth != 8 or interlace != 0 or color not in (2, 6):
                sys.exit(f"{path}: only 8-bit non-interlaced RGB(A) PNGs are read")
            channels = 3 if color == 2 else 4
        elif kind == b"IDAT":
            idat += body
    raw, stride = zlib.decompress(idat), width * channels
    rows, previous, i = [], bytearray(stride), 0
    for _ in range(height):
        kind, line = raw[i], bytearray(raw[i + 1:i + 1 + stride])
        i += 1 + stride
        for x in range(stride):
            a = line[x - channels] if x >= channels else 0
            b = previous[x]
            c = previous[x - channels] if x >= channels else 0
            if kind == 1:
                line[x] = (line[x] + a) & 255
            elif kind == 2:
                line[x] = (line[x] + b) & 255
            elif kind == 3:
                line[x] = (line[x] + (a + b) // 2) & 255
            elif kind == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append([tuple(line[x * channels:x * channels + 3]) for x in range(width)])
        previous = line
    return rows


def write_png(path, rows):
    def chunk(kind, body):
        return (struct.pack(">I", len(body)) + kind + body
                + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))
    raw = b"".join(b"\x00" + bytes(v for p in row for v in p) for row in rows)
    header = struct.pack(">IIBBBBB", len(rows[0]), len(rows), 8, 2, 0, 0, 0)
    with open(path + ".part", "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
                + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    os.replace(path + ".part", path)


def run(command):
    print("$ " + " ".join(command), file=sys.stderr)
    subprocess.run(command, check=True)


def regions(recorded, truth, composites):
    """Pixel counts and mean changes (levels, per channel) of Fig. 5's two regions."""
    unchanged, shadows, faint = [], [], []
    for y, row in enumerate(truth):
        for x, t in enumerate(row):
            r = recorded[y][x]
            if all(abs(t[c] - r[c]) <= 1 for c in range(3)):
                unchanged.append((x, y))
            elif all(t[c] <= r[c] - 4 for c in range(3)):
                shadows.append((x, y))
            elif all(abs(t[c] - r[c]) < 4 for c in range(3)):
                faint.append((x, y))

    def change(image, pixels):
        if not pixels:
            return 0.0
        return sum(sum(image[y][x][c] - recorded[y][x][c] for c in range(3))
                   for x, y in pixels) / (3 * len(pixels))

    def rms_error(image, pixels):
        if not pixels:
            return 0.0
        return (sum(sum((image[y][x][c] - truth[y][x][c]) ** 2 for c in range(3))
                    for x, y in pixels) / (3 * len(pixels))) ** 0.5

    out = {"unchanged_pixels": len(unchanged), "true_shadow_pixels": len(shadows),
           "truth_shadow_change": change(truth, shadows),
           "faint_pixels": len(faint), "truth_faint_change": change(truth, faint)}
    for name, image in composites.items():
        darkened = [(x, y) for x, y in unchanged
                    if all(image[y][x][c] <= recorded[y][x][c] - 4 for c in range(3))]
        out[name] = {
            "unchanged_darkened_pixels": len(darkened),
            "unchanged_darkened_change": change(image, darkened),
            "shadow_change": change(image, shadows),
            "faint_change": change(image, faint),
            "faint_rms_error": rms_error(image, faint),
        }
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--relume", default="target/release/relume")
    ap.add_argument("--out", default="out/double-shadow")
    ap.add_argument("--frame", type=int, default=14)
    a = ap.parse_args()
    if not os.path.isfile(a.relume):
        sys.exit(f"{a.relume} does not exist: build it with `cargo build --release` "
                 "(or name a relume binary with --relume PATH)")
    os.makedirs(a.out, exist_ok=True)
    recording = os.path.join(a.out, "lamp.relume")
    if not os.path.exists(recording):
        run([a.relume, "synth", "-o", recording, "--lamp-on-at", "0"])
    frames = f"0..{a.frame + 1}"
    compare = os.path.join(a.out, "compare")
    command = [a.relume, "compare", recording, "--frames", frames, "--out", compare]
    for pipeline in PIPELINES.values():
        command += ["-p", pipeline]
    run(command)
    # The recorded frame, as the camera saw it.
    view = os.path.join(a.out, "recorded.toml")
    with open(view, "w") as f:
        f.write('[pipeline]\nname = "recorded"\n\n[[stage]]\nkind = "decode"\n\n'
                '[[stage]]\nkind = "write"\nparams = { products = ["color"], '
                'formats = ["png"] }\n')
    run([a.relume, "replay", recording, "-p", view, "--frames", str(a.frame),
         "--out", os.path.join(a.out, "recorded"), "--clean-out"])
    frame_dir = os.path.join(compare, "frames", f"{a.frame:06d}")
    recorded = read_png(os.path.join(a.out, "recorded", "color", f"{a.frame:06d}.png"))
    truth = read_png(os.path.join(frame_dir, "truth.png"))
    composites = {}
    report = json.load(open(os.path.join(compare, "report.json")))
    for name, path in PIPELINES.items():
        label = os.path.splitext(os.path.basename(path))[0]
        composites[name] = read_png(os.path.join(frame_dir, f"{label}.composite.png"))
    measured = regions(recorded, truth, composites)
    scores = {}
    for variant in report["variants"]:
        s = variant["scores"]["composite.differential"]
        scores[variant["label"]] = {k: s.get(k) for k in (
            "psnr_db_truth", "psnr_db_truth_differential", "psnr_db_truth_objects",
            "shadow_ratio_bias")}
    x0, y0, x1, y1 = CROP

    def crop(image):
        return [row[x0:x1] for row in image[y0:y1]]

    gap = [[(255, 255, 255)] * 4 for _ in range(y1 - y0)]
    panels = [crop(recorded), gap, crop(truth), gap, crop(composites["paper"]), gap,
              crop(composites["knecht2010"])]
    figure = [sum((p[y] for p in panels), []) for y in range(y1 - y0)]
    write_png(os.path.join(a.out, "figure.png"), figure)
    result = {"frame": a.frame, "scores": scores, "regions": measured,
              "figure": os.path.join(a.out, "figure.png"),
              "panels": "recorded | truth | paper 002's flags | [4] (knecht2010)"}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
