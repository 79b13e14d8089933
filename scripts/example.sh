#!/usr/bin/env bash
# The main job of README.md on a built-in scene: set up .venv, then describe the street
# canyon and list the paths from a transmitter to two receivers with their fields.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
out=${1:-out/example}
mkdir -p "$out"
.venv/bin/wavepaths info street_canyon
.venv/bin/wavepaths paths street_canyon --tx -60 0 10 --rx 20 0 1.5 --rx 60 5 1.5 --max-reflections 2
if .venv/bin/wavepaths coverage --help >/dev/null 2>&1; then
  .venv/bin/wavepaths coverage street_canyon --tx -60 0 10 --height 1.5 --cell 2 --center 0.5 0.5 --out "$out"
  echo "coverage map written to $out"
fi
