"""``wavepaths validate --out DIR [--quick]``."""

from __future__ import annotations

import sys


def _run(args) -> int:
    from .report import run_validation
    from .sionna_env import ensure_sionna

    ensure_sionna()  # a clear DependencyError (exit 2) if Sionna RT or libLLVM is missing

    def progress(i, n, what):
        if not args.quiet:
            print(f"[{i}/{n}] {what}", file=sys.stderr, flush=True)

    summary = run_validation(args.out, quick=args.quick, progress=progress)
    print(f"report: {args.out}/report.html, summary: {args.out}/validation.json")
    for c in summary["cases"]:
        for pol, r in c["polarizations"].items():
            s = r["comparison_compat"]
            print(f"{c['name']:<22} {pol}  matched {s['matched']:>4}  only wavepaths {s['only_wavepaths']:>4}  "
                  f"only Sionna {s['only_sionna']:>3}  {'pass' if r['passed'] else 'FAIL'}")
    exact = summary["exact_comparison"]
    for name, fields in exact["lines"].items():
        for field, v in fields.items():
            errs = "  ".join(f"{e} {x['max_db']:.3g} dB" for e, x in v["engines"].items() if x["max_db"] is not None)
            print(f"exact {name:<16} {field}  {errs}  matches the exact solution: {v['matches_exact']}")
    print(f"exact solutions: {exact['held_engine']} {'pass' if exact['passed'] else 'FAIL'}")
    print("PASS" if summary["passed"] else "FAIL")
    return 0 if summary["passed"] else 1


def add_parser(sub) -> None:
    p = sub.add_parser("validate", help="compare with Sionna RT and exact solutions; write an HTML report")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="a subset that runs in a few minutes (as in CI)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_run)
