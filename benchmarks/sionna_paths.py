"""Benchmark 2: path queries against Sionna RT on the same CPU (simple_street_canyon, etoile crop).

Usage: python benchmarks/sionna_paths.py [--quick] [--out DIR]

Writes DIR/bench.json and DIR/index.html with this benchmark only; `wavepaths bench`
runs all five. See docs/benchmarks.md.
"""

import argparse

from wavepaths.bench.report import run_bench

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/bench-sionna_paths")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    summary = run_bench(args.out, quick=args.quick, only=["sionna_paths"], command=f"python benchmarks/sionna_paths.py --out {args.out}"
                        + (" --quick" if args.quick else ""))
    print({k: summary["headline"][k] for k in ("point_search_ns", "point_search_speedup", "sionna_paths_time_ratio",
                                               "diffraction_cost_ratio")})
