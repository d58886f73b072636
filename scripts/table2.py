#!/usr/bin/env python3
"""Paper 000's Table 2 with `relume bench`: the rendering phase's time per row (ms a
frame) for each quality preset, sample.path's time split into the paper's rows
(material estimation, virtual object, differential background).

    scripts/table2.py [RECORDING] [--frames 10..12] [--repeat 1] [--relume PATH]

Columns, as the paper's: EM low (pipelines/mixed-reality-nei-low.toml), EM med (the
medium preset with query = em and, as the paper's EM columns, material_query = dit), DIT med (pipelines/mixed-reality-nei-medium.toml),
VCT med (pipelines/mixed-reality-vct.toml, which makes the scene's voxel volume, with
the medium preset's self_bounce = false) and DIT high
(pipelines/mixed-reality-nei-high.toml). Each is one `relume bench --isolated --json`
(every stage timed alone, one frame at a time). Rows: paper 000 Table 2's, each the
relume stage or part that does that work; then what relume runs that the table does
not time (acquisition and light: paper 000's Table 1 phase; the VCT pipeline's
filter). The total is the sum of the rows' medians (file writes left out). Standard
library only.
"""

import argparse
import sys

from table3 import bench_stages, print_table

# (column, pipeline, sample.path settings)
COLUMNS = [
    ("EM low", "mixed-reality-nei-low", []),
    ("EM med", "mixed-reality-nei-medium", [("query", "em"), ("material_query", "dit")]),
    ("DIT med", "mixed-reality-nei-medium", []),
    ("VCT med", "mixed-reality-vct", [("self_bounce", "false")]),
    ("DIT high", "mixed-reality-nei-high", []),
]

# (Table 2's row, the stage, the part of it or None for the whole stage)
ROWS = [
    ("Update and apply c_t", "color.compensate", None),
    ("G-Buffer splatting and push-pull", "gbuffer.splat", None),
    ("Render virtual object", "sample.path", "object"),
    ("Material estimation", "sample.path", "material"),
    ("Diff. background", "sample.path", "differential"),
    ("sample.path's setup (depth pyramid)", "sample.path", "setup"),
    ("Apply c_t^-1 and compose", "composite.differential", None),
]
NOT_IN_TABLE = "Not in Table 2: acquisition, light, filter"
WRITES = {"write"}


def column(stages):
    """The rows' medians (ms) of one bench, then the rest, the total and the rate."""
    if "parts" not in stages.get("sample.path", {}):
        sys.exit("this relume's sample.path does not split its time (rebuild it)")
    values, counted = [], set()
    for _, stage, part in ROWS:
        s = stages[stage]
        values.append(s["parts"][part]["median_ms"] if part else s["median_ms"])
        counted.add(stage)
    rest = sum(s["median_ms"] for name, s in stages.items()
               if name not in counted and s["kind"] not in WRITES and s["kind"] != "read")
    total = sum(values) + rest
    return values + [rest, total, 1e3 / total]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recording", nargs="?", help="default: the built-in recording")
    ap.add_argument("--frames", default="10..12")
    ap.add_argument("--repeat", default="1")
    ap.add_argument("--relume", default="target/release/relume")
    a = ap.parse_args()
    columns = []
    for name, pipeline, settings in COLUMNS:
        columns.append(column(bench_stages(a, pipeline, settings)))
        print(f"{name}: {columns[-1][-2]:.0f} ms a frame", file=sys.stderr)
    labels = [r[0] for r in ROWS] + [NOT_IN_TABLE, "Total frame", "Frame rate [Hz]"]
    rows = []
    for i, label in enumerate(labels):
        fmt = "{:.2f}" if label.startswith("Frame rate") else "{:.1f}"
        rows.append([label] + [fmt.format(c[i]) for c in columns])
    print_table(["ms a frame"] + [c[0] for c in COLUMNS], rows)


if __name__ == "__main__":
    main()
