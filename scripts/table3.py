#!/usr/bin/env python3
"""Paper 000's Table 3 with `relume bench`: sample.path's median ms per frame for each
radiance query (ssrt, em, dit, vct), N = 16, 32 and 64 samples per pixel and layer,
with and without the objects' self-occlusion (visibility).

    scripts/table3.py [RECORDING] [--frames 10..12] [--counts 16,32,64] [--relume PATH]

Each cell is one `relume bench --isolated --json` of pipelines/mixed-reality-vct.toml
(it makes both the distance impostor and the voxel volume, so every query can run)
with `--set sample.path.query=... --set sample.path.direct=N/4 ...` (4 primaries),
and, as the table's caption says ("Differential Background (with cache size 32)"),
the background's differential estimated object-aware (paper 000 Sec. 7, indirect and
direct light) from N candidate directions with cache size 32 (scripts/table4.py varies
the cache). The direct-light shadow rays of em, dit and vct meet the objects' solid
voxel volume (object_visibility = voxels, 32 voxels a side), as paper 000 Sec. 6.2 does
for every technique (the object-aware candidates and indirect rays meet the mesh);
ssrt, relume's own, keeps the mesh. Standard library only.
"""

import argparse
import json
import subprocess
import sys

QUERIES = ["ssrt", "em", "dit", "vct"]


def bench_arguments(ap, counts):
    """The options every paper-table script takes (scripts/table4.py too)."""
    ap.add_argument("recording", nargs="?", help="default: the built-in recording")
    ap.add_argument("--frames", default="10..12")
    ap.add_argument("--counts", default=counts)
    ap.add_argument("--repeat", default="1")
    ap.add_argument("--relume", default="target/release/relume")


def bench_stages(a, pipeline, settings):
    """The stages of one `relume bench --isolated --json` of pipelines/`pipeline`.toml
    with the sample.path `settings` (key, value); exits with relume's error."""
    cmd = [a.relume, "bench", "--isolated", "--json", "--repeat", a.repeat,
           "--frames", a.frames, "-p", f"pipelines/{pipeline}.toml"]
    if a.recording:
        cmd.append(a.recording)
    for key, value in settings:
        cmd += ["--set", f"sample.path.{key}={value}"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)}\n{done.stderr}")
    return json.loads(done.stdout)["stages"]


def sample_path_ms(a, settings):
    """sample.path's median ms a frame in one `relume bench --isolated` of
    pipelines/mixed-reality-vct.toml with the sample.path `settings` (key, value)."""
    return bench_stages(a, "mixed-reality-vct", settings)["sample.path"]["median_ms"]


def print_table(head, rows):
    """A Markdown table on stdout."""
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for row in rows:
        print("| " + " | ".join(row) + " |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    bench_arguments(ap, "16,32,64")
    a = ap.parse_args()
    counts = [int(n) for n in a.counts.split(",")]
    rows = []
    for query in QUERIES:
        row = [query]
        for n in counts:
            for visibility in ["true", "false"]:
                per_primary = max(n // 4, 1)
                objects = "mesh" if query == "ssrt" else "voxels"
                ms = sample_path_ms(a, [("query", query), ("visibility", visibility),
                                        ("object_visibility", objects),
                                        ("object_aware", "true"),
                                        ("object_aware_direct", "true"),
                                        ("candidates", n), ("cache_size", 32),
                                        ("direct", per_primary), ("indirect", per_primary)])
                row.append(f"{ms:.0f}")
                print(f"{query} N={n} visibility={visibility}: {ms:.0f} ms", file=sys.stderr)
        rows.append(row)
    print_table(["query"] + [f"N={n}{'' if v else ' novis'}" for n in counts
                             for v in (True, False)], rows)


if __name__ == "__main__":
    main()
