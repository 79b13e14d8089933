"""Benchmark 5: the same coverage map with diffraction off and on (the seed paid 46x).

Usage: python benchmarks/diffraction_cost.py [--quick] [--out DIR]

Writes DIR/bench.json and DIR/index.html with this benchmark only; `wavepaths bench`
runs all five. See docs/benchmarks.md.
"""

import argparse

from wavepaths.bench.report import run_bench

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/bench-diffraction_cost")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    summary = run_bench(args.out, quick=args.quick, only=["diffraction_cost"], command=f"python benchmarks/diffraction_cost.py --out {args.out}"
                        + (" --quick" if args.quick else ""))
    print({k: summary["headline"][k] for k in ("point_search_ns", "point_search_speedup", "sionna_paths_time_ratio",
                                               "diffraction_cost_ratio")})
