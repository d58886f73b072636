#!/usr/bin/env python3
"""Which trajectory do a Redwood folder's images agree with, step by step?

For each pair of consecutive frames, frame b's depth is back-projected, moved into
frame a by a trajectory's relative pose, and frame a's gray value there compared with
frame b's: the mean absolute difference (0..255) is the step's photometric residual
under that trajectory. Run on a recording's poses and relume's tracked ones, it finds
steps where the recorded trajectory disagrees with the images (livingroom1: frames
99 -> 100 and 199 -> 200), and prints the ATE any tracker would score that followed
the recorded steps exactly except where the images ask otherwise (its "floor").

  relume replay lr.relume -p pipelines/tracking.toml --save pose,recorded_pose --out t
  cat t/pose/*.txt > tracked.txt; cat t/recorded_pose/*.txt > recorded.txt
  python3 scripts/step_check.py ../shared/data/livingroom1 recorded.txt tracked.txt

Needs numpy and Pillow (the Open3D peer's virtual environment has both). Intrinsics:
PrimeSense's (fx = fy = 525, cx = 319.5, cy = 239.5), as livingroom1 has.
"""

import argparse
import sys

try:
    import numpy as np
    from PIL import Image
except ImportError as e:
    sys.exit(f"step_check.py: {e}: install numpy and Pillow (pip install numpy pillow)")

FX = FY = 525.0
CX, CY = 319.5, 239.5


def read_tum(path):
    """4x4 camera-to-world matrices of a TUM trajectory file, in order."""
    poses = []
    for n, line in enumerate(open(path), 1):
        if not line.strip() or line.startswith("#"):
            continue
        v = [float(x) for x in line.split()]
        if len(v) != 8:
            sys.exit(f"{path}:{n}: expected 8 numbers (stamp tx ty tz qx qy qz qw)")
        x, y, z, w = v[4:8]
        r = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ])
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = r, v[1:4]
        poses.append(m)
    return poses


def residual(folder, a, b, pose_a, pose_b):
    """Mean |gray_a(warped) - gray_b| over frame b's pixels that land in frame a."""
    gray = lambda i: np.asarray(Image.open(f"{folder}/color/{i:05d}.jpg").convert("L"), float)
    z = np.asarray(Image.open(f"{folder}/depth/{b:05d}.png"), float) / 1000.0
    h, w = z.shape
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    m = z > 0
    p = np.stack([(u - CX) / FX * z, (v - CY) / FY * z, z, np.ones_like(z)], -1)[m]
    q = p @ (np.linalg.inv(pose_a) @ pose_b).T
    ua = np.round(q[:, 0] / q[:, 2] * FX + CX).astype(int)
    va = np.round(q[:, 1] / q[:, 2] * FY + CY).astype(int)
    ok = (q[:, 2] > 0) & (ua >= 0) & (ua < w) & (va >= 0) & (va < h)
    return np.abs(gray(a)[va[ok], ua[ok]] - gray(b)[m][ok]).mean()


def ate(reference, estimate):
    """ATE RMSE after the rigid (Horn) alignment of the estimate's positions."""
    a = np.array([p[:3, 3] for p in reference])
    b = np.array([p[:3, 3] for p in estimate])
    ma, mb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((b - mb).T @ (a - ma))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1, 1, d]) @ u.T
    return np.sqrt((((r @ (b - mb).T).T + ma - a) ** 2).sum(1).mean())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", help="the Redwood folder (color/NNNNN.jpg, depth/NNNNN.png)")
    ap.add_argument("recorded", help="the recording's trajectory (TUM file)")
    ap.add_argument("tracked", help="the tracked trajectory (TUM file), same frames")
    ap.add_argument("--ratio", type=float, default=1.5,
                    help="a step whose residual under the recorded poses exceeds this "
                         "times the tracked one's is taken as the recording's error")
    a = ap.parse_args()
    rec, tr = read_tum(a.recorded), read_tum(a.tracked)
    if len(rec) != len(tr):
        sys.exit(f"{a.recorded} has {len(rec)} poses, {a.tracked} {len(tr)}")
    step = lambda t, i: np.linalg.inv(t[i - 1]) @ t[i]
    floor, bad = [rec[0]], []
    print("step        recorded: mm  residual   tracked: mm  residual")
    for i in range(1, len(rec)):
        rr = residual(a.folder, i - 1, i, rec[i - 1], rec[i])
        rt = residual(a.folder, i - 1, i, tr[i - 1], tr[i])
        take_tracked = rr > a.ratio * rt
        if take_tracked:
            bad.append(i)
            print(f"{i - 1:4d} -> {i:<4d} {np.linalg.norm(step(rec, i)[:3, 3]) * 1e3:12.1f}"
                  f" {rr:9.2f} {np.linalg.norm(step(tr, i)[:3, 3]) * 1e3:13.1f} {rt:9.2f}")
        floor.append(floor[-1] @ (step(tr, i) if take_tracked else step(rec, i)))
    print(f"{len(bad)} of {len(rec) - 1} steps disagree with the images under the recorded "
          f"poses (residual over {a.ratio} times the tracked one's)")
    print(f"ATE of the tracked trajectory: {ate(rec, tr) * 1e3:.2f} mm")
    print(f"ATE of the recorded steps with those replaced (any tracker that agrees with "
          f"the images there scores at least about this): {ate(rec, floor) * 1e3:.2f} mm")


if __name__ == "__main__":
    main()
