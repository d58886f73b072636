#!/usr/bin/env python3
"""Closest-hit rays per second of relume's objects' BVH against Embree 4 (the `embreex`
package on PyPI), on the same triangles and the same rays, in one run.

    python scripts/bvh_peer.py [--relume-example PATH] [--rays N] [--repeat K]
        [--work DIR] [--json]

Two scenes:
  default   the objects of pipelines/default.toml (the torus and the ball the default
            renders), dumped by relume itself (`bvh_rate dump`).
  mesh100k  a bumpy sphere of 100 352 triangles (a 224 x 224 latitude-longitude grid,
            its radius 1 + 0.05 sin(9 theta) sin(11 phi)), written here.

Rays (N of each kind, 200 000 by default, from a fixed seed):
  camera    from points 2.5-3.5 bounding radii from the scene's centre towards uniform
            points of its box enlarged by 20 %: the primary rays of a camera looking
            at the objects, mostly hits;
  bounce    from points on the plane under the box (y = its floor; within twice its
            half extent) in cosine-distributed directions about +y: the room's
            indirect rays that `sample.path` tests against the objects, mostly misses.

Each peer traces every ray for its nearest hit with t in (0, inf) on one thread:
relume's `Bvh::nearest` (examples/bvh_rate.rs, built by `cargo build --release
--example bvh_rate`) and Embree's rtcIntersect1 through embreex's `EmbreeScene.run`
(one C loop over the rays; its Python overhead is per call, not per ray). Both are
timed over K passes (5 by default) after the scene is built, and the median pass is
reported; the build times are reported beside. The hits are compared: a ray counts as
agreeing when both miss, or both hit with t within 1e-4 relative (ties between
triangles at the same t may pick different triangles). The script exits with status 2
when fewer than 99.9 % of the rays agree.

Needs numpy and embreex in a virtual environment:

    python3 -m venv target/tmp/embree-venv
    target/tmp/embree-venv/bin/pip install embreex==4.4.0.post1 numpy
    target/tmp/embree-venv/bin/python scripts/bvh_peer.py
"""

import argparse
import json
import math
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
INSTALL = (
    "python3 -m venv target/tmp/embree-venv && "
    "target/tmp/embree-venv/bin/pip install embreex==4.4.0.post1 numpy"
)

try:
    import numpy as np
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh
except ImportError as e:  # pragma: no cover - a message, not a test
    sys.exit(f"bvh_peer.py needs numpy and embreex ({e}); install them with\n  {INSTALL}")


def bumpy_sphere(n=224):
    """(2 n^2, 3, 3) float32 triangles of a bumpy sphere (see the module docs)."""
    theta = np.linspace(0.0, math.pi, n + 1)
    phi = np.linspace(0.0, 2.0 * math.pi, n + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    r = 1.0 + 0.05 * np.sin(9.0 * t) * np.sin(11.0 * p)
    v = np.stack([r * np.sin(t) * np.cos(p), r * np.cos(t), r * np.sin(t) * np.sin(p)], -1)
    a, b, c, d = v[:-1, :-1], v[1:, :-1], v[1:, 1:], v[:-1, 1:]
    quads_a = np.stack([a, b, c], -2).reshape(-1, 3, 3)
    quads_b = np.stack([a, c, d], -2).reshape(-1, 3, 3)
    return np.concatenate([quads_a, quads_b]).astype(np.float32)


def unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def rays_for(triangles, n, rng):
    """(camera rays, bounce rays), each (n, 6) float32: origin, unit direction."""
    points = triangles.reshape(-1, 3).astype(np.float64)
    lo, hi = points.min(0), points.max(0)
    centre, half = (lo + hi) / 2.0, (hi - lo) / 2.0
    radius = float(np.linalg.norm(half))
    # Camera rays.
    eye_dir = unit(rng.normal(size=(n, 3)))
    eye_dir[:, 1] = np.abs(eye_dir[:, 1])  # from above the floor, as a camera
    origins = centre + eye_dir * radius * rng.uniform(2.5, 3.5, size=(n, 1))
    targets = centre + half * 1.2 * rng.uniform(-1.0, 1.0, size=(n, 3))
    camera = np.hstack([origins, unit(targets - origins)])
    # Bounce rays: cosine-distributed about +y from the plane under the box.
    u1, u2 = rng.uniform(size=n), rng.uniform(size=n)
    r, a = np.sqrt(u1), 2.0 * math.pi * u2
    dirs = np.stack([r * np.cos(a), np.sqrt(np.maximum(0.0, 1.0 - u1)), r * np.sin(a)], -1)
    floor = np.stack(
        [
            centre[0] + 2.0 * half[0] * rng.uniform(-1.0, 1.0, size=n),
            np.full(n, lo[1] - 1e-3),
            centre[2] + 2.0 * half[2] * rng.uniform(-1.0, 1.0, size=n),
        ],
        -1,
    )
    bounce = np.hstack([floor, dirs])
    return camera.astype(np.float32), bounce.astype(np.float32)


def relume_trace(example, triangles_file, rays, work, repeat):
    rays_file, hits_file = work / "rays.f32", work / "hits.bin"
    rays.astype("<f4").tofile(rays_file)
    out = subprocess.run(
        [str(example), "trace", str(triangles_file), str(rays_file), str(hits_file),
         "--repeat", str(repeat)],
        check=True, capture_output=True, text=True,
    )
    report = json.loads(out.stdout)
    raw = np.fromfile(hits_file, dtype="<u1")
    n = len(rays)
    t = raw[: 4 * n].view("<f4")
    prim = raw[4 * n:].view("<i4")
    return report, t, prim


def embree_trace(triangles, rays, repeat):
    start = time.perf_counter()
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, triangles)
    # The first query commits the scene (builds the BVH): time it apart.
    probe = np.ascontiguousarray(rays[:1, :3]), np.ascontiguousarray(rays[:1, 3:])
    scene.run(*probe, output=1)
    build_s = time.perf_counter() - start
    origins = np.ascontiguousarray(rays[:, :3])
    dirs = np.ascontiguousarray(rays[:, 3:])
    passes = []
    result = None
    for _ in range(repeat):
        start = time.perf_counter()
        result = scene.run(origins, dirs, output=1)
        passes.append(time.perf_counter() - start)
    t = np.where(result["primID"] >= 0, result["tfar"], np.inf).astype(np.float32)
    return {"build_s": build_s, "pass_s": passes,
            "rays_per_s": len(rays) / statistics.median(passes)}, t, result["primID"]


def agreement(t_a, prim_a, t_b, prim_b):
    hit_a, hit_b = prim_a >= 0, prim_b >= 0
    both_miss = ~hit_a & ~hit_b
    both_hit = hit_a & hit_b
    t_a, t_b = np.where(both_hit, t_a, 0.0), np.where(both_hit, t_b, 0.0)
    close = np.abs(t_a - t_b) <= 1e-4 * np.maximum(1.0, np.abs(t_b))
    agree = both_miss | (both_hit & close)
    return float(agree.mean()), float(hit_b.mean())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--relume-example", type=Path,
                    default=REPO / "target/release/examples/bvh_rate",
                    help="the bvh_rate example binary (built if missing)")
    ap.add_argument("--rays", type=int, default=200_000, help="rays of each kind")
    ap.add_argument("--repeat", type=int, default=5, help="timed passes per peer")
    ap.add_argument("--work", type=Path, help="folder for the triangle and ray files")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    if not 1 <= args.rays <= 5_000_000:
        sys.exit("--rays must be 1 to 5000000")
    if not 1 <= args.repeat <= 100:
        sys.exit("--repeat must be 1 to 100")
    example = args.relume_example
    if not example.exists():
        subprocess.run(["cargo", "build", "--release", "--example", "bvh_rate"],
                       cwd=REPO, check=True)
    work_dir = tempfile.TemporaryDirectory() if args.work is None else None
    work = Path(work_dir.name) if work_dir else args.work
    work.mkdir(parents=True, exist_ok=True)

    default_file = work / "default.f32"
    subprocess.run([str(example), "dump", str(REPO / "pipelines/default.toml"),
                    str(default_file)], check=True, capture_output=True)
    scenes = {
        "default": np.fromfile(default_file, dtype="<f4").reshape(-1, 3, 3),
        "mesh100k": bumpy_sphere(),
    }
    rng = np.random.default_rng(58)
    rows, worst = [], 1.0
    for name, triangles in scenes.items():
        tri_file = work / f"{name}.f32"
        triangles.astype("<f4").tofile(tri_file)
        for kind, rays in zip(("camera", "bounce"), rays_for(triangles, args.rays, rng)):
            ours, t_r, p_r = relume_trace(example, tri_file, rays, work, args.repeat)
            theirs, t_e, p_e = embree_trace(triangles, rays, args.repeat)
            agree, hit_share = agreement(t_r, p_r, t_e, p_e)
            worst = min(worst, agree)
            rows.append({
                "scene": name, "rays": kind, "triangles": len(triangles),
                "hit_share": hit_share, "agree": agree,
                "relume_rays_per_s": ours["rays_per_s"],
                "embree_rays_per_s": theirs["rays_per_s"],
                "ratio": ours["rays_per_s"] / theirs["rays_per_s"],
                "relume_build_s": ours["build_s"], "embree_build_s": theirs["build_s"],
            })
    if args.json:
        print(json.dumps({"rows": rows}, indent=1))
    else:
        print(f"{'scene':9} {'rays':7} {'triangles':>9} {'hits':>6} {'agree':>8} "
              f"{'relume Mrays/s':>14} {'Embree Mrays/s':>14} {'ratio':>6} "
              f"{'build ms r/E':>13}")
        for r in rows:
            print(f"{r['scene']:9} {r['rays']:7} {r['triangles']:9d} "
                  f"{r['hit_share']:6.1%} {r['agree']:8.4%} "
                  f"{r['relume_rays_per_s'] / 1e6:14.2f} {r['embree_rays_per_s'] / 1e6:14.2f} "
                  f"{r['ratio']:6.2f} "
                  f"{1e3 * r['relume_build_s']:6.0f}/{1e3 * r['embree_build_s']:<6.0f}")
        print("one thread each; rays per second of the median of the timed passes")
    if worst < 0.999:
        print(f"the peers disagree on {1 - worst:.3%} of some scene's rays", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
