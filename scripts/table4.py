#!/usr/bin/env python3
"""Paper 000's Table 4 with `relume bench`: sample.path's median ms per frame with the
object-aware estimate of the objects' influence (paper 000 Sec. 7) for each radiance
query (em, dit, vct), N = 8 to 128 candidate directions per pixel and cache sizes
|H_a| = 8, 16 and 32 (the most candidates meeting the objects' box that are traced).

    scripts/table4.py [RECORDING] [--frames 10..12] [--counts 8,16,32,64,128]
                      [--caches 8,16,32] [--queries em,dit,vct] [--relume PATH]

Each cell is one `relume bench --isolated --json` of pipelines/mixed-reality-vct.toml
(it makes both the distance impostor and the voxel volume, so every query can run)
with `--set sample.path.query=... --set sample.path.candidates=N --set
sample.path.cache_size=C`, object-aware sampling on for indirect and direct light, and
N / 4 direct and indirect samples for each of the 4 primaries (N per pixel and layer,
as in scripts/table3.py). Where it departs from the paper's table: relume times the
whole of sample.path (the objects, their material and the background together; the
paper times the background's differential alone, at half resolution), on the CPU.
A cache larger than N is skipped (it cannot fill). Standard library only; the
bench call and the table are scripts/table3.py's.
"""

import argparse
import sys

from table3 import bench_arguments, print_table, sample_path_ms


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    bench_arguments(ap, "8,16,32,64,128")
    ap.add_argument("--caches", default="8,16,32")
    ap.add_argument("--queries", default="em,dit,vct")
    a = ap.parse_args()
    counts = [int(n) for n in a.counts.split(",")]
    caches = [int(c) for c in a.caches.split(",")]
    rows = []
    for query in a.queries.split(","):
        for cache in caches:
            row = [f"{query} (cache {cache})"]
            for n in counts:
                if cache > n:
                    row.append("")
                    continue
                per_primary = max(n // 4, 1)
                ms = sample_path_ms(a, [("query", query), ("object_aware", "true"),
                                        ("object_aware_direct", "true"),
                                        ("candidates", n), ("cache_size", cache),
                                        ("direct", per_primary), ("indirect", per_primary)])
                row.append(f"{ms:.0f}")
                print(f"{query} cache {cache} N={n}: {ms:.0f} ms", file=sys.stderr)
            rows.append(row)
    print_table(["query"] + [f"N={n}" for n in counts], rows)


if __name__ == "__main__":
    main()
