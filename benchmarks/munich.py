"""Optional scale benchmark: a coverage map of Sionna RT's munich scene at 2 m cells.

Target (issue #7): reflections to order 2 and diffraction with reflections before and
after it, in under 10 minutes and 8 GB. Runs in a child process limited to 30 minutes and
8 GiB; when the target settings fail it probes first order to measure the rate.

Usage: python benchmarks/munich.py [--out DIR]
"""

import argparse
import json

from wavepaths.bench.munich import run_munich

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/bench-munich")
    parser.add_argument("--timeout", type=float, default=1800.0)
    args = parser.parse_args()
    result = run_munich(args.out, timeout_s=args.timeout)
    with open(f"{args.out}/munich.json", "w") as f:
        json.dump(result, f, indent=1, default=str)
    print(json.dumps({k: v for k, v in result.items() if k not in ("stats", "probe")}, indent=1, default=str))
