#!/usr/bin/env bash
# The test command of README.md: set up .venv (with Sionna RT), run the test suite, the
# full validation against Sionna RT and the exact solutions (about 10 min; it fails when
# the report does: a path Sionna alone finds, a tolerance broken, wavepaths' UTD off the
# exact solutions), then the CLI contract check when ../shared/checks/cli_contract.py is
# present.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh test
echo "== pytest"
.venv/bin/python -m pytest -q "$@"
echo "== full validation (wavepaths validate)"
out=$(mktemp -d)
.venv/bin/wavepaths validate --out "$out"
rm -rf "$out"
contract=../shared/checks/cli_contract.py
if [ -f "$contract" ]; then
  echo "== CLI contract ($contract)"
  PATH="$PWD/.venv/bin:$PATH" .venv/bin/python "$contract"
fi
