"""``wavepaths bench``: the benchmarks of issue #7 (see ``docs/benchmarks.md``)."""

from __future__ import annotations

import sys

from .report import BENCHMARKS


def _run(args) -> int:
    from .report import run_bench

    only = None if args.only is None else [x.strip() for x in args.only.split(",")]
    if only is not None:
        bad = [x for x in only if x not in BENCHMARKS]
        if bad:
            print(f"wavepaths bench: error: unknown benchmark(s) {bad}; choose from {', '.join(BENCHMARKS)}",
                  file=sys.stderr)
            return 2
    command = "wavepaths bench " + " ".join(sys.argv[2:]) if sys.argv[1:2] == ["bench"] else "wavepaths bench"

    def progress(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    summary = run_bench(args.out, quick=args.quick, only=only, munich=args.munich, profile=not args.no_profile,
                        command=command, progress=progress)
    head = summary["headline"]
    print(f"wrote {args.out}/bench.json and {args.out}/index.html in {summary['elapsed_s']:.0f} s")
    for key in ("point_search_ns", "point_search_speedup", "sionna_paths_time_ratio", "diffraction_cost_ratio"):
        v = head.get(key)
        print(f"  {key:<26} {v:.3g}" if isinstance(v, float) else f"  {key:<26} {v}")
    for k, v in head["targets"].items():
        print(f"  target {k:<45} {'met' if v else ('MISSED' if v is False else 'not run')}")
    return 0


def add_parser(sub) -> None:
    """Register ``wavepaths bench`` on the CLI's subparsers."""
    p = sub.add_parser("bench", help="run the benchmarks (point search, Sionna RT comparison, run time vs error, "
                                     "scaling, cost of diffraction) and write an HTML report and bench.json")
    p.add_argument("--out", required=True, help="output directory (bench.json, index.html, scene files)")
    p.add_argument("--quick", action="store_true", help="smaller sizes and fewer repeats (about 3 minutes)")
    p.add_argument("--only", default=None, help=f"comma-separated subset of: {', '.join(BENCHMARKS)} (all when "
                                                "not given; an empty list is an error)")
    p.add_argument("--munich", action="store_true",
                   help="also the scale target: a coverage map of Sionna's munich scene (long; child process "
                        "limited to 30 min and 8 GiB)")
    p.add_argument("--no-profile", action="store_true", help="do not profile the work behind missed targets")
    p.set_defaults(func=_run)
