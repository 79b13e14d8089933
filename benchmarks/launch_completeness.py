"""Launched candidates against the exhaustive search: completeness and cost per fan density.

Random street-level receivers of a scene, R2+D2 diffraction (see
:mod:`wavepaths.bench.launch`). munich takes about 10 minutes (its context, then the
exhaustive search at several seconds per receiver); simple_street_canyon under a minute.

Usage: python benchmarks/launch_completeness.py [--scene munich|simple_street_canyon] [--cells N] [--out DIR]
"""

import argparse
import json
import os

from wavepaths.bench.launch import launch_completeness
from wavepaths.bench.munich import MUNICH_TX
from wavepaths.bench.scenes import STREET_CANYON_TX

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="munich", choices=["munich", "simple_street_canyon"])
    parser.add_argument("--cells", type=int, default=32)
    parser.add_argument("--fans", default="64,256,1024")
    parser.add_argument("--out", default="out/bench-launch")
    args = parser.parse_args()
    tx = MUNICH_TX if args.scene == "munich" else STREET_CANYON_TX
    result = launch_completeness(args.scene, tx, args.cells, tuple(int(f) for f in args.fans.split(",")))
    os.makedirs(args.out, exist_ok=True)
    with open(f"{args.out}/launch-{args.scene}.json", "w") as f:
        json.dump(result, f, indent=1)
    print(json.dumps({k: v for k, v in result.items() if k != "fans"}, indent=1))
