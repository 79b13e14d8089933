"""Benchmark 1: the seed's diffraction point search, closed form against numerical (seed §4).

Usage: python benchmarks/point_search.py [--quick] [--out DIR]

Writes DIR/bench.json and DIR/index.html with this benchmark only; `wavepaths bench`
runs all five. See docs/benchmarks.md.
"""

import argparse

from wavepaths.bench.report import run_bench

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/bench-point_search")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    summary = run_bench(args.out, quick=args.quick, only=["point_search"], command=f"python benchmarks/point_search.py --out {args.out}"
                        + (" --quick" if args.quick else ""))
    print({k: summary["headline"][k] for k in ("point_search_ns", "point_search_speedup", "sionna_paths_time_ratio",
                                               "diffraction_cost_ratio")})
