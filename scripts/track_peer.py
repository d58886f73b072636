#!/usr/bin/env python3
"""Compares relume's camera tracker (`pose.track`) with Open3D's RGB-D odometry on the
same frames, scored the same way.

    python scripts/track_peer.py REC.relume --relume PATH/TO/relume [--frames A..B]
        [--work DIR] [--terms hybrid,color] [--depth-trunc M] [--json]

1. Runs `relume replay REC -p pipelines/tracking.toml --frames A..B --save
   color,depth,pose,recorded_pose --out WORK`: relume's tracked trajectory (WORK/pose),
   the recording's poses (WORK/recorded_pose), and the frames' color (8-bit sRGB) and
   depth (16-bit millimetres) as PNGs. Its timing table gives pose.track's median ms
   per frame.
2. Runs `relume eval REC -p pipelines/tracking.toml --frames A..B --json` for relume's
   own scores of pose.track, and checks that this script's ATE of the replayed
   trajectory equals relume eval's `ate_rmse_m` (exit status 2 when it does not).
3. Runs Open3D's `o3d.pipelines.odometry.compute_rgbd_odometry` on the same PNGs,
   chained frame to frame (frame i onto frame i-1, the relative motions accumulated),
   from the first frame's recorded pose, once per Jacobian term (hybrid: depth and
   intensity, color: intensity only), with the default OdometryOption and the
   recording's color intrinsics. A frame whose odometry reports failure keeps the
   previous pose and is counted as lost. Each odometry call is timed (the median is
   reported; reading the PNGs and making the RGBD images are not counted, as relume's
   PNG decoding is another stage).
4. Scores each trajectory against the recording's poses by the TUM RGB-D benchmark's
   definitions (Sturm et al. 2012): ATE RMSE after the best rigid alignment (rotation
   and translation, no scale: Horn/Umeyama), and the RPE over one-frame steps (RMS of
   the translation, in metres, and of the rotation angle, in degrees, of
   E_i = (Q_i^-1 Q_i+1)^-1 (P_i^-1 P_i+1)). Frames relume lost have no pose and are
   left out, as relume eval does; Open3D's lost frames hold the previous pose and are
   scored.

Prints a table (or, with --json, one JSON object). Needs numpy and open3d (0.19) from
PyPI in a virtual environment:

    python3 -m venv target/tmp/open3d-venv
    target/tmp/open3d-venv/bin/pip install open3d==0.19.0 numpy
    target/tmp/open3d-venv/bin/python scripts/track_peer.py lr.relume \\
        --relume target/release/relume --frames 0..20

Open3D 0.19's wheel needs libusb-1.0 (Debian: apt-get install libusb-1.0-0).
"""

import argparse
import json
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
INSTALL = (
    "python3 -m venv target/tmp/open3d-venv && "
    "target/tmp/open3d-venv/bin/pip install open3d==0.19.0 numpy"
)
TERMS = {
    "hybrid": "RGBDOdometryJacobianFromHybridTerm",
    "color": "RGBDOdometryJacobianFromColorTerm",
}
# The TUM files relume writes give translations to 1e-9 m: the script's ATE of them may
# differ from relume eval's (computed from the full-precision poses) by that much.
ATE_ABS_TOLERANCE_M = 1e-8
ATE_REL_TOLERANCE = 1e-6


class Failure(Exception):
    """An error to report in one line, without a traceback."""


def parse_args(argv):
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0].replace("\n", " "),
        epilog=__doc__[__doc__.index("1. Runs") :],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("recording", type=Path, help="the recording (.relume)")
    p.add_argument(
        "--relume",
        default=None,
        help="the relume binary (default: `relume` on PATH, else target/release/relume)",
    )
    p.add_argument(
        "--frames",
        default=None,
        help="frames to compare, as relume takes them: A..B (B excluded), A.., ..B "
        "(default: every frame; Open3D takes about 0.3 s a frame per term at 640x480)",
    )
    p.add_argument(
        "--work",
        type=Path,
        default=None,
        help="folder for relume's saved frames and poses, kept afterwards "
        "(default: a temporary folder, removed)",
    )
    p.add_argument(
        "--pipeline",
        type=Path,
        default=REPO / "pipelines" / "tracking.toml",
        help="relume's tracking pipeline (default: pipelines/tracking.toml)",
    )
    p.add_argument(
        "--terms",
        default="hybrid,color",
        help="Open3D Jacobian terms to run, comma-separated: hybrid, color "
        "(default: both)",
    )
    p.add_argument(
        "--depth-trunc",
        type=float,
        default=4.0,
        help="depth (m) beyond which Open3D's RGBD images drop pixels "
        "(default 4.0, OdometryOption's depth_max)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    args = p.parse_args(argv)
    if args.frames is not None and not re.fullmatch(r"\d*\.\.\d*|\d+", args.frames):
        p.error(f"--frames {args.frames!r}: expected A..B, A.., ..B or N")
    terms = [t.strip() for t in args.terms.split(",") if t.strip()]
    for t in terms:
        if t not in TERMS:
            p.error(f"--terms: unknown term {t!r} (expected hybrid or color)")
    args.terms = terms
    return args


def import_peers():
    """numpy and open3d, or a Failure saying how to install them."""
    try:
        import numpy
    except ImportError as e:
        raise Failure(f"numpy is missing ({e}); install it with: {INSTALL}")
    try:
        import open3d
    except ImportError as e:
        hint = ""
        if "libusb" in str(e):
            hint = " (Open3D's wheel needs libusb-1.0: apt-get install libusb-1.0-0)"
        raise Failure(
            f"cannot import open3d: {e}{hint}\n"
            f"install it in a virtual environment with: {INSTALL}\n"
            "then run this script with target/tmp/open3d-venv/bin/python"
        )
    return numpy, open3d


def find_relume(given):
    if given is not None:
        path = shutil.which(given) or given
        if not Path(path).is_file():
            raise Failure(f"--relume {given}: no such file")
        return str(path)
    for candidate in (shutil.which("relume"), REPO / "target" / "release" / "relume"):
        if candidate and Path(candidate).is_file():
            return str(candidate)
    raise Failure(
        "no relume binary: pass --relume PATH (build one with cargo build --release)"
    )


def run(cmd):
    """Runs cmd; returns (stdout, stderr), or raises a Failure with both."""
    try:
        done = subprocess.run(cmd, capture_output=True, text=True)
    except OSError as e:
        raise Failure(f"cannot run {cmd[0]}: {e}")
    if done.returncode != 0:
        raise Failure(
            f"{' '.join(map(str, cmd))} failed (exit {done.returncode}):\n"
            f"{done.stdout}{done.stderr}".rstrip()
        )
    return done.stdout, done.stderr


def stage_median_ms(text, stage):
    """The `median ms` column of `stage`'s row in relume's timing table."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        head = line.split()
        if head[:3] == ["stage", "kind", "frames"] and "median" in head:
            # Header cells: stage kind frames median ms p95 ms ...: the median is the
            # fourth value of a row.
            for row in lines[i + 1 :]:
                cells = row.split()
                if len(cells) < 4:
                    break
                if cells[0] == stage:
                    return float(cells[3])
    return None


def read_tum(path, np):
    """The 4x4 camera-to-world matrix of a one-line TUM file (stamp tx ty tz qx qy qz qw)."""
    values = path.read_text().split()
    if len(values) != 8:
        raise Failure(f"{path}: expected one TUM line of 8 numbers")
    _, tx, ty, tz, qx, qy, qz, qw = map(float, values)
    return pose_matrix(np, (tx, ty, tz), (qx, qy, qz, qw))


def pose_matrix(np, t, q):
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    m = np.identity(4)
    m[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    m[:3, 3] = t
    return m


def read_poses(folder, np):
    """{frame index: 4x4 pose} of the TUM files NNNNNN.txt in folder."""
    if not folder.is_dir():
        return {}
    return {int(f.stem): read_tum(f, np) for f in sorted(folder.glob("*.txt"))}


def rigid_alignment(np, a, b):
    """R, t minimizing sum |R a_i + t - b_i|^2 (Umeyama 1991 without scale; the same
    optimum as Horn's closed form)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    s = (a - ca).T @ (b - cb)  # cross-covariance, sum (a - ca)(b - cb)^T
    u, _, vt = np.linalg.svd(s)
    d = np.identity(3)
    d[2, 2] = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ d @ u.T
    return r, cb - r @ ca


def ate_rmse(np, tracked, recorded):
    """RMS distance of the recorded positions from the rigidly aligned tracked ones."""
    if not tracked:
        return None
    a = np.array([p[:3, 3] for p in tracked])
    b = np.array([p[:3, 3] for p in recorded])
    r, t = rigid_alignment(np, a, b)
    return float(np.sqrt(np.mean(np.sum((a @ r.T + t - b) ** 2, axis=1))))


def rotation_angle_deg(np, r):
    """The angle of rotation matrix r, robust near zero (atan2 of sine and cosine)."""
    sine = 0.5 * np.linalg.norm([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    cosine = 0.5 * (np.trace(r) - 1.0)
    return math.degrees(math.atan2(sine, cosine))


def score(np, frames, tracked, recorded):
    """TUM RGB-D scores of `tracked` ({frame: pose}) against `recorded`, over `frames`."""
    both = [f for f in frames if f in tracked and f in recorded]
    t2, r2, pairs = 0.0, 0.0, 0
    for f0, f1 in zip(frames, frames[1:]):
        if not all(f in tracked and f in recorded for f in (f0, f1)):
            continue
        q = np.linalg.inv(recorded[f0]) @ recorded[f1]
        p = np.linalg.inv(tracked[f0]) @ tracked[f1]
        e = np.linalg.inv(q) @ p
        t2 += float(np.sum(e[:3, 3] ** 2))
        r2 += rotation_angle_deg(np, e[:3, :3]) ** 2
        pairs += 1
    return {
        "frames_scored": len(both),
        "ate_rmse_m": ate_rmse(
            np, [tracked[f] for f in both], [recorded[f] for f in both]
        ),
        "rpe_translation_m_per_frame": math.sqrt(t2 / pairs) if pairs else None,
        "rpe_rotation_deg_per_frame": math.sqrt(r2 / pairs) if pairs else None,
    }


def color_intrinsics(relume, recording):
    out, _ = run([relume, "inspect", str(recording), "--json"])
    info = json.loads(out)
    color, depth = info["color_intrinsics"], info["depth_intrinsics"]
    if color != depth:
        raise Failure(
            f"{recording}: the color intrinsics {color} differ from the depth "
            f"intrinsics {depth}; Open3D's RGB-D odometry needs depth registered to "
            "the color camera"
        )
    return color


def open3d_odometry(np, o3d, work, frames, intrinsics, start, term, depth_trunc):
    """Open3D's frame-to-frame odometry with Jacobian `term` over `frames`: (poses,
    lost frames, milliseconds per odometry call)."""
    k = o3d.camera.PinholeCameraIntrinsic(
        intrinsics["width"],
        intrinsics["height"],
        intrinsics["fx"],
        intrinsics["fy"],
        intrinsics["cx"],
        intrinsics["cy"],
    )
    jacobian = getattr(o3d.pipelines.odometry, TERMS[term])()
    option = o3d.pipelines.odometry.OdometryOption()

    def rgbd(f):
        name = f"{f:06d}.png"
        color = o3d.io.read_image(str(work / "color" / name))
        depth = o3d.io.read_image(str(work / "depth" / name))
        shape = np.asarray(depth).shape
        if shape != (intrinsics["height"], intrinsics["width"]):
            raise Failure(f"{work / 'depth' / name}: {shape}, not the intrinsics' size")
        return o3d.geometry.RGBDImage.create_from_color_and_depth(
            color,
            depth,
            depth_scale=1000.0,
            depth_trunc=depth_trunc,
            convert_rgb_to_intensity=True,
        )

    poses = {frames[0]: start}
    lost, ms = [], []
    previous = rgbd(frames[0])
    for f0, f1 in zip(frames, frames[1:]):
        current = rgbd(f1)
        began = time.perf_counter()
        # Source frame f1, target f0: the transform takes f1's camera coordinates
        # into f0's, so f1's camera-to-world pose is f0's times it.
        success, transform, _ = o3d.pipelines.odometry.compute_rgbd_odometry(
            current, previous, k, np.identity(4), jacobian, option
        )
        ms.append(1e3 * (time.perf_counter() - began))
        if success:
            poses[f1] = poses[f0] @ np.asarray(transform)
        else:
            poses[f1] = poses[f0]
            lost.append(f1)
        previous = current
    return poses, lost, ms


def fmt(value, scale=1.0, digits=2):
    return "-" if value is None else f"{value * scale:.{digits}f}"


def main(argv=None):
    args = parse_args(argv)
    np, o3d = import_peers()
    relume = find_relume(args.relume)
    if not args.recording.is_file():
        raise Failure(f"{args.recording}: no such recording")
    if not args.pipeline.is_file():
        raise Failure(f"{args.pipeline}: no such pipeline file")
    frames_arg = ["--frames", args.frames] if args.frames else []
    intrinsics = color_intrinsics(relume, args.recording)

    temporary = args.work is None
    work = Path(tempfile.mkdtemp(prefix="track_peer-")) if temporary else args.work
    try:
        out, err = run(
            [relume, "replay", str(args.recording), "-p", str(args.pipeline)]
            + frames_arg
            + ["--save", "color,depth,pose,recorded_pose", "--out", str(work)]
            + ["--clean-out"]
        )
        relume_ms = stage_median_ms(out + "\n" + err, "pose.track")
        out, _ = run(
            [relume, "eval", str(args.recording), "-p", str(args.pipeline)]
            + frames_arg
            + ["--json"]
        )
        evaluation = json.loads(out)
        stage = evaluation["stages"].get("pose.track")
        if stage is None:
            raise Failure(f"{args.pipeline} has no stage named pose.track")

        frames = sorted(
            int(f.stem)
            for f in (work / "color").glob("*.png")
            if (work / "depth" / f.name).is_file()
        )
        if len(frames) < 2:
            raise Failure(f"relume saved {len(frames)} frames with color and depth: need 2")
        recorded = read_poses(work / "recorded_pose", np)
        if not recorded:
            raise Failure(f"{args.recording} has no poses to score against")
        tracked = read_poses(work / "pose", np)

        methods = {}
        mine = score(np, frames, tracked, recorded)
        methods["relume"] = {
            "method": "relume pose.track",
            "frames": len(frames),
            "lost_frames": sum(f not in tracked for f in frames),
            **mine,
            "median_ms_per_frame": relume_ms,
        }
        start = recorded.get(frames[0], np.identity(4))
        for term in args.terms:
            poses, lost, ms = open3d_odometry(
                np, o3d, work, frames, intrinsics, start, term, args.depth_trunc
            )
            methods[f"open3d_{term}"] = {
                "method": f"Open3D {o3d.__version__} {term}",
                "frames": len(frames),
                "lost_frames": len(lost),
                **score(np, frames, poses, recorded),
                "median_ms_per_frame": statistics.median(ms),
            }
    finally:
        if temporary:
            shutil.rmtree(work, ignore_errors=True)

    mine_ate, eval_ate = mine["ate_rmse_m"], stage.get("ate_rmse_m")
    if mine_ate is None or eval_ate is None:
        agrees = mine_ate is None and eval_ate is None
        difference = None
    else:
        difference = abs(mine_ate - eval_ate)
        agrees = difference <= max(ATE_ABS_TOLERANCE_M, ATE_REL_TOLERANCE * eval_ate)
    check = {
        "script_ate_rmse_m": mine_ate,
        "eval_ate_rmse_m": eval_ate,
        "abs_difference_m": difference,
        "agrees": agrees,
    }
    positions = np.array([recorded[f][:3, 3] for f in frames if f in recorded])
    still = float(np.sqrt(np.mean(np.sum((positions - positions.mean(axis=0)) ** 2, axis=1))))
    report = {
        "recording": str(args.recording),
        "pipeline": str(args.pipeline),
        "frames": [frames[0], frames[-1] + 1],
        "intrinsics": intrinsics,
        "depth_trunc_m": args.depth_trunc,
        # The recorded path: its length, and the ATE of a trajectory that never moves
        # (the RMS distance of the recorded positions from their mean), a scale for
        # the ATEs.
        "recorded_path": {
            "length_m": float(np.sum(np.linalg.norm(np.diff(positions, axis=0), axis=1))),
            "ate_rmse_if_still_m": still,
        },
        "methods": methods,
        "relume_eval": stage,
        "ate_check": check,
    }
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print_table(report)
    if not agrees:
        print(
            f"error: this script's ATE of relume's trajectory ({mine_ate}) differs from "
            f"relume eval's ({eval_ate})",
            file=sys.stderr,
        )
        return 2
    return 0


def print_table(report):
    first, end = report["frames"]
    path = report["recorded_path"]
    print(
        f"{report['recording']}, frames {first}..{end}, against the recording's poses "
        f"(path {fmt(path['length_m'], 1e3, 1)} mm long; a camera that never moved "
        f"would have an ATE of {fmt(path['ate_rmse_if_still_m'], 1e3)} mm)"
    )
    header = [
        "method",
        "frames",
        "lost",
        "ATE RMSE (mm)",
        "RPE (mm/frame)",
        "RPE (deg/frame)",
        "median ms/frame",
    ]
    rows = [
        [
            m["method"],
            str(m["frames"]),
            str(m["lost_frames"]),
            fmt(m["ate_rmse_m"], 1e3),
            fmt(m["rpe_translation_m_per_frame"], 1e3, 3),
            fmt(m["rpe_rotation_deg_per_frame"], 1.0, 4),
            fmt(m["median_ms_per_frame"], 1.0, 1),
        ]
        for m in report["methods"].values()
    ]
    widths = [max(len(r[i]) for r in [header] + rows) for i in range(len(header))]
    line = lambda cells: " | ".join(
        c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths))
    )
    print(line(header))
    print("-+-".join("-" * w for w in widths))
    for r in rows:
        print(line(r))
    c = report["ate_check"]
    ev = report["relume_eval"]
    print(
        f"relume's ATE: this script {fmt(c['script_ate_rmse_m'], 1e3, 6)} mm, relume eval "
        f"{fmt(c['eval_ate_rmse_m'], 1e3, 6)} mm"
        + ("" if c["abs_difference_m"] is None else f" (differ by {c['abs_difference_m']:.1e} m)")
        + ("" if c["agrees"] else "  DISAGREE")
    )
    print(
        f"relume eval: RPE {fmt(ev.get('rpe_translation_m_per_frame'), 1e3, 3)} mm/frame, "
        f"{fmt(ev.get('rpe_rotation_deg_per_frame'), 1.0, 4)} deg/frame, "
        f"{ev.get('lost_frames')} lost"
    )
    print(
        "relume's time is pose.track's median in its replay (its own stage; PNG decoding "
        "is the decode stage); Open3D's is the median compute_rgbd_odometry call. "
        "Frames relume lost are left out of its scores; Open3D's lost frames keep the "
        "previous pose and are scored."
    )


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Failure as e:
        print(f"track_peer.py: {e}", file=sys.stderr)
        sys.exit(1)
    except KeyboardInterrupt:
        sys.exit(130)
