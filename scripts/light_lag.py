#!/usr/bin/env python3
"""How fast each mixed-reality pipeline follows a light switched off: the lag table of
issue 57 ("things move").

    scripts/light_lag.py [--frames 45] [--off-at 15] [--stride 8] [--pipelines a,b]
                         [--relume PATH] [--dir DIR]

Makes two synthetic rooms with `relume synth`: the ceiling panel switched off at
frame OFF_AT, and the same room with the panel off from frame 0 (the change long past).
Runs `relume eval --score-frames 10..FRAMES` of each pipeline on both and compares,
frame by frame, the composite's share of the true differential
(`differential_ratio_by_frame`: the least-squares gain of the composite's shadows and
bleeding on the truth's). The settled share of a frame is the one the same pipeline
shows there when the panel was off all along, so the camera's motion, which moves the
share by itself, is not taken for lag. Prints, per pipeline: the share before the
switch and settled after it, the share's deficit on the switch frame and the next
three, and the lag: frames from the switch until the share stays within 5 % of the
settled one, and until it stays within 0.05 of it (5 % of the truth's differential: for
pipelines whose share is small, 5 % of it is below their noise); also eval's own
single-run `change_lag_frames` (within 5 % of the run's own final share, which counts the
camera's drift as lag). Standard library only.
"""

import argparse
import json
import os
import subprocess
import sys

PIPELINES = [
    "mixed-reality", "mixed-reality-reference", "mixed-reality-fast", "mixed-reality-dir",
    "mixed-reality-val", "mixed-reality-nei-low", "mixed-reality-nei-medium",
    "mixed-reality-nei-high", "mixed-reality-vct", "mixed-reality-vct-reuse",
    "mixed-reality-dit", "mixed-reality-probe",
]
TOLERANCE = 0.05


def run(cmd):
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)}\n{done.stderr}")
    return done.stdout


def scores(a, recording, pipeline):
    out = run([a.relume, "eval", recording, "-p", f"pipelines/{pipeline}.toml",
               "--score-frames", f"10..{a.frames}", "--reference-stride", str(a.stride),
               "--stage", "composite.differential", "--json"])
    composite = json.loads(out)["stages"]["composite.differential"]
    if "differential_ratio_by_frame" not in composite:
        why = composite.get("truth_unavailable", "no true frames were scored")
        sys.exit(f"{recording}: {why} (delete it to have it made again)")
    return composite


def lag(frames, switched, settled, off_at, absolute=False):
    """Frames from `off_at` until every later share is within 5 % of the settled one
    (`absolute`: within 0.05 of it)."""
    last = None
    for i, (f, r, s) in enumerate(zip(frames, switched, settled)):
        if f < off_at:
            continue
        tolerance = TOLERANCE if absolute or s is None else TOLERANCE * abs(s)
        if r is None or s is None or abs(r - s) > tolerance:
            last = i
    return 0 if last is None else frames[last] + 1 - off_at


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=45)
    ap.add_argument("--off-at", type=int, default=15)
    ap.add_argument("--stride", type=int, default=8)
    ap.add_argument("--pipelines", default=",".join(PIPELINES))
    ap.add_argument("--relume", default="target/release/relume")
    ap.add_argument("--dir", default="recordings", help="where the two rooms are written")
    a = ap.parse_args()
    if a.off_at < 11 or a.off_at >= a.frames - 10:
        sys.exit("--off-at must leave frames 10.. before it and 10 frames after it")
    os.makedirs(a.dir, exist_ok=True)
    rooms = {}
    for name, off in [("switched", a.off_at), ("settled", 0)]:
        path = os.path.join(a.dir, f"panel-off-{off}-{a.frames}.relume")
        if not os.path.exists(path):
            run([a.relume, "synth", "-o", path, "--frames", str(a.frames),
                 "--panel-off-at", str(off)])
        rooms[name] = path
    print(f"| pipeline | share before | settled | deficit at {a.off_at}, +1, +2, +3 "
          f"| lag: within 5 % | within 0.05 | eval's change_lag_frames |")
    print("|---|---:|---:|---|---:|---:|---:|")
    for pipeline in a.pipelines.split(","):
        switched = scores(a, rooms["switched"], pipeline)
        settled = scores(a, rooms["settled"], pipeline)
        frames = switched["scored_frames"]
        r = switched["differential_ratio_by_frame"]
        s = settled["differential_ratio_by_frame"]
        after = [(f, x, y) for f, x, y in zip(frames, r, s) if f >= a.off_at]
        deficits = ", ".join(
            f"{100 * (x / y - 1):+.0f} %" if x is not None and y else "-"
            for _, x, y in after[:4])
        def median(values):
            values = sorted(v for v in values if v is not None)
            return values[len(values) // 2] if values else float("nan")
        before = median(x for f, x in zip(frames, r) if f < a.off_at)
        print(f"| {pipeline} | {before:.2f} "
              f"| {median(y for _, _, y in after[-5:]):.2f} | {deficits} "
              f"| {lag(frames, r, s, a.off_at)} | {lag(frames, r, s, a.off_at, True)} "
              f"| {switched.get('change_lag_frames', '-')} |",
              flush=True)


if __name__ == "__main__":
    main()
