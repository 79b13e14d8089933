#!/usr/bin/env bash
# The test command of README.md: set up .venv (with Sionna RT), run the test suite,
# then the CLI contract check when ../shared/checks/cli_contract.py is present.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh test
echo "== pytest"
.venv/bin/python -m pytest -q "$@"
contract=../shared/checks/cli_contract.py
if [ -f "$contract" ]; then
  echo "== CLI contract ($contract)"
  PATH="$PWD/.venv/bin:$PATH" .venv/bin/python "$contract"
fi
