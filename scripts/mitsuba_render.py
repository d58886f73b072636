#!/usr/bin/env python3
"""Renders a Mitsuba 3 scene written by relume's exporter (relume_recording::synth::mitsuba).

    python scripts/mitsuba_render.py SCENE.xml OUT_DIR --spp N --max-depth D [--seed S]
        [--positions]

Loads SCENE.xml with the CPU variant `scalar_rgb` and renders every sensor in the order
the file declares them, with the `path` integrator (`max_depth` D, -1 for no limit;
emitters visible), N samples per pixel and seed S (default 0). Writes OUT_DIR/view_K.pfm
for sensor K: linear RGB radiance as 32-bit floats (colour PFM, little-endian, rows
bottom to top as PFM stores them). With --positions it renders instead, with the `aov`
integrator, the world position of the first hit averaged over each pixel, to
OUT_DIR/view_K_position.pfm (a check of the camera: --max-depth is then ignored).
Prints one line per view with its render time. Needs only the `mitsuba` package from
PyPI (no numpy).
"""

import argparse
import array
import os
import sys
import time


def write_pfm(path, image):
    """Writes a Mitsuba tensor of shape (height, width, 3) as a little-endian colour PFM."""
    height, width, channels = image.shape
    if channels != 3:
        raise ValueError(f"expected 3 channels, the render has {channels}")
    values = array.array("f", image.array)
    if sys.byteorder != "little":
        values.byteswap()
    row = width * 3
    with open(path, "wb") as out:
        out.write(f"PF\n{width} {height}\n-1.0\n".encode("ascii"))
        for y in range(height - 1, -1, -1):
            values[y * row:(y + 1) * row].tofile(out)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", help="the scene.xml to render")
    parser.add_argument("out_dir", help="folder for view_K.pfm (made if missing)")
    parser.add_argument("--spp", type=int, required=True, help="samples per pixel")
    parser.add_argument(
        "--max-depth", type=int, required=True,
        help="longest path in segments (2: direct light only; -1: no limit)")
    parser.add_argument("--seed", type=int, default=0, help="sampler seed (default 0)")
    parser.add_argument(
        "--positions", action="store_true",
        help="render the first hit's world position instead of radiance")
    args = parser.parse_args()

    if not os.path.isfile(args.scene):
        sys.exit(f"mitsuba_render.py: no scene file at {args.scene}")
    if args.spp < 1:
        sys.exit(f"mitsuba_render.py: --spp must be at least 1, not {args.spp}")
    if args.max_depth == 0 or args.max_depth < -1:
        sys.exit(f"mitsuba_render.py: --max-depth must be -1 or at least 1, not {args.max_depth}")
    try:
        import mitsuba as mi
    except ImportError as e:
        sys.exit(f"mitsuba_render.py: cannot import mitsuba ({e}): `pip install mitsuba`")
    mi.set_variant("scalar_rgb")
    os.makedirs(args.out_dir, exist_ok=True)

    start = time.perf_counter()
    try:
        scene = mi.load_file(os.path.abspath(args.scene))
    except Exception as e:  # Mitsuba raises RuntimeError naming the missing file or tag.
        sys.exit(f"mitsuba_render.py: cannot load {args.scene}: {e}")
    print(f"loaded {args.scene} in {time.perf_counter() - start:.2f} s", flush=True)
    if args.positions:
        integrator = mi.load_dict({"type": "aov", "aovs": "position:position"})
        suffix = "_position"
    else:
        integrator = mi.load_dict({
            "type": "path",
            "max_depth": args.max_depth,
            "hide_emitters": False,
        })
        suffix = ""
    sensors = scene.sensors()
    if not sensors:
        sys.exit(f"mitsuba_render.py: {args.scene} declares no sensor")
    total = time.perf_counter()
    for index, sensor in enumerate(sensors):
        start = time.perf_counter()
        image = mi.render(scene, sensor=sensor, integrator=integrator, spp=args.spp,
                          seed=args.seed + index)
        path = os.path.join(args.out_dir, f"view_{index}{suffix}.pfm")
        write_pfm(path, image)
        height, width, _ = image.shape
        print(f"view {index}: {width}x{height}, {args.spp} spp, "
              f"{'positions' if args.positions else f'max depth {args.max_depth}'}: "
              f"{time.perf_counter() - start:.2f} s", flush=True)
    print(f"rendered {len(sensors)} views in {time.perf_counter() - total:.2f} s", flush=True)


if __name__ == "__main__":
    main()
