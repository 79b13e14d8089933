#!/usr/bin/env bash
# Create (or reuse) the virtual environment .venv and install wavepaths into it.
#   bash scripts/setup.sh            # the package, its runtime dependencies and the `fast` extra (numba)
#   bash scripts/setup.sh test       # plus the test, dask and Sionna RT extras (and libLLVM for Dr.Jit)
# Needs only Python >= 3.11 with venv and pip (and, for Sionna RT, Debian's apt as root).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "== creating .venv with $($PY --version)"
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
if [ "${1:-}" = "test" ]; then
  echo "== installing wavepaths with the test, dask and fast extras"
  .venv/bin/python -m pip install --quiet -e ".[test,dask,fast]"
  if [ "${WAVEPATHS_SKIP_SIONNA:-0}" != "1" ]; then
    echo "== installing Sionna RT and a libLLVM for Dr.Jit"
    bash scripts/install-sionna.sh .venv
  fi
else
  echo "== installing wavepaths (with the fast extra)"
  .venv/bin/python -m pip install --quiet -e ".[fast]"
fi
echo "== compiling the numba kernels (cached: once per machine)"
.venv/bin/python -c "from wavepaths.search import kernels; from wavepaths.fields import compiled; print('   compiled' if kernels.warm_up() and compiled.warm_up() else '   numba not installed: the numpy reference runs')"
