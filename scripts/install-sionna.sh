#!/usr/bin/env bash
# Install what wavepaths needs to run NVIDIA Sionna RT on the CPU:
#   * the Python dependencies of `wavepaths[sionna]` (the project's dependencies
#     plus sionna-rt==2.2.0, which pulls in mitsuba and drjit) into a virtual
#     environment (wavepaths itself is not installed: use PYTHONPATH=src or
#     `pip install -e .` as usual), and
#   * a libLLVM >= 16 for Dr.Jit's LLVM backend (Debian 12 ships only 14 and 15;
#     with those, Sionna's path solver aborts the whole process).
#
# Usage (normally as root on Debian 12 with Python 3.11):
#   bash scripts/install-sionna.sh [VENV]        # VENV defaults to <repo>/.venv
#
# libLLVM route: Debian's `libllvm19` package when apt can install it (needs
# root); otherwise the PyPI wheel `karellen-llvm-core`, which puts libLLVM.so.NN
# into <VENV>/lib. WAVEPATHS_LLVM_ROUTE=pypi skips apt (default: auto).
# Safe to run again: what is already there is detected and kept.
# Ends by importing Sionna RT and tracing one free-space path; exits non-zero
# with a message naming the failed step otherwise.
set -Eeuo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${1:-$REPO/.venv}"
PYTHON_FOR_VENV="${PYTHON:-python3}"
LLVM_DEB="libllvm19"
LLVM_WHEEL="karellen-llvm-core"
LLVM_ROUTE="${WAVEPATHS_LLVM_ROUTE:-auto}"
STEP="start"
T_START=$(date +%s)

say() { printf '[install-sionna] %s\n' "$*"; }
die() { printf '[install-sionna] ERROR: %s\n' "$*" >&2; exit 1; }
trap 'rc=$?; printf "[install-sionna] ERROR: step \"%s\" failed (exit %s).\n" "$STEP" "$rc" >&2; exit "$rc"' ERR

[[ "$LLVM_ROUTE" == auto || "$LLVM_ROUTE" == pypi ]] \
    || die "WAVEPATHS_LLVM_ROUTE must be 'auto' or 'pypi', not '$LLVM_ROUTE'"

timed() {  # timed "description" command...
    local t0
    t0=$(date +%s)
    say "$1 ..."
    shift
    "$@"
    say "  done in $(( $(date +%s) - t0 )) s"
}

# Run Python code that needs only wavepaths.errors and
# wavepaths.validation.sionna_env, without executing the package __init__ files
# (which import the rest of wavepaths and its dependencies).
wp_python() {
    "$PY" - "$REPO/src" "$@" <<EOF
import importlib.util, sys, types
src = sys.argv.pop(1)
for name, path in (("wavepaths", src + "/wavepaths"),
                   ("wavepaths.validation", src + "/wavepaths/validation")):
    if name not in sys.modules:
        pkg = types.ModuleType(name)
        pkg.__path__ = [path]
        sys.modules[name] = pkg
$(cat)
EOF
}

# ---------------------------------------------------------------- venv
STEP="virtual environment"
if [[ ! -x "$VENV/bin/python" ]]; then
    command -v "$PYTHON_FOR_VENV" >/dev/null 2>&1 \
        || die "no virtual environment at $VENV and no $PYTHON_FOR_VENV to create one"
    timed "creating virtual environment $VENV" "$PYTHON_FOR_VENV" -m venv "$VENV"
fi
PY="$VENV/bin/python"
"$PY" -c 'import sys; assert sys.version_info >= (3, 11), sys.version' \
    || die "$PY is older than Python 3.11, which wavepaths requires"
say "virtual environment: $VENV (Python $("$PY" -c 'import sys; print(sys.version.split()[0])'))"

# ---------------------------------------------------------------- Python packages
STEP="read wavepaths[sionna] requirements from pyproject.toml"
mapfile -t REQS < <("$PY" - "$REPO/pyproject.toml" <<'EOF'
import sys, tomllib
with open(sys.argv[1], "rb") as f:
    project = tomllib.load(f)["project"]
for req in project["dependencies"] + project["optional-dependencies"]["sionna"]:
    print(req)
EOF
)
[[ ${#REQS[@]} -gt 0 ]] || die "no requirements found in $REPO/pyproject.toml"
STEP="pip install wavepaths[sionna] requirements"
timed "pip install ${REQS[*]}" "$PY" -m pip install --quiet "${REQS[@]}"
"$PY" - <<'EOF'
from importlib.metadata import version
print("[install-sionna] versions: " + ", ".join(
    f"{n} {version(n)}" for n in ("sionna-rt", "mitsuba", "drjit", "numpy")))
EOF

# ---------------------------------------------------------------- libLLVM
find_llvm() {
    wp_python <<'EOF'
from wavepaths.validation.sionna_env import find_libllvm
print(find_libllvm() or "")
EOF
}

STEP="look for libLLVM >= 16"
LLVM_PATH="$(find_llvm)"
if [[ -n "$LLVM_PATH" ]]; then
    say "libLLVM >= 16 already present: $LLVM_PATH"
else
    if [[ "$LLVM_ROUTE" == pypi ]]; then
        say "WAVEPATHS_LLVM_ROUTE=pypi: not using apt"
    elif [[ "$(id -u)" -eq 0 ]] && command -v apt-get >/dev/null 2>&1; then
        STEP="apt-get update"
        timed "apt-get update" apt-get update -qq
        STEP="apt-cache policy $LLVM_DEB"
        CANDIDATE="$(apt-cache policy "$LLVM_DEB" 2>/dev/null | awk '/Candidate:/ {print $2}')"
        if [[ -n "$CANDIDATE" && "$CANDIDATE" != "(none)" ]]; then
            STEP="apt-get install $LLVM_DEB"
            APT_LOG="$(mktemp)"
            apt_install() {
                DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$LLVM_DEB" >"$APT_LOG" 2>&1
            }
            if ! timed "apt-get install -y $LLVM_DEB ($CANDIDATE)" apt_install; then
                tail -n 20 "$APT_LOG" >&2
                say "apt-get install $LLVM_DEB failed (output above); trying PyPI"
            fi
            rm -f "$APT_LOG"
        else
            say "apt has no candidate for $LLVM_DEB; trying PyPI"
        fi
    else
        say "not root or no apt-get: trying PyPI"
    fi
    STEP="look for libLLVM >= 16"
    LLVM_PATH="$(find_llvm)"
    if [[ -z "$LLVM_PATH" ]]; then
        STEP="pip install $LLVM_WHEEL"
        timed "pip install $LLVM_WHEEL (libLLVM inside the venv, ~90 MB)" \
            "$PY" -m pip install --quiet "$LLVM_WHEEL"
        # The wheel's .pth hook (wheel-axle) creates its libc++ symlinks on the
        # first interpreter start; libLLVM cannot be loaded before that.
        "$PY" -c 'pass'
        STEP="look for libLLVM >= 16"
        LLVM_PATH="$(find_llvm)"
    fi
    [[ -n "$LLVM_PATH" ]] \
        || die "no libLLVM >= 16 after trying apt ($LLVM_DEB) and PyPI ($LLVM_WHEEL)"
    say "libLLVM: $LLVM_PATH"
fi

# ---------------------------------------------------------------- check
STEP="check: import Sionna RT and trace a free-space path"
wp_python <<'EOF'
import math, os, tempfile, time
from wavepaths.validation.sionna_env import ensure_sionna
t0 = time.perf_counter()
rt = ensure_sionna()
import drjit as dr, mitsuba as mi
with tempfile.TemporaryDirectory() as tmp:
    xml = os.path.join(tmp, "empty.xml")
    with open(xml, "w") as f:
        f.write('<scene version="2.1.0"></scene>\n')
    scene = rt.load_scene(xml)
scene.frequency = 3.5e9
scene.tx_array = rt.PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
scene.rx_array = rt.PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
scene.add(rt.Transmitter("tx", position=mi.Point3f(0, 0, 10)))
scene.add(rt.Receiver("rx", position=mi.Point3f(100, 0, 10)))
paths = rt.PathSolver()(scene, max_depth=1)
a = float(paths.a[0].numpy().ravel()[0])
expected = scene.wavelength[0] / (4 * math.pi * 100.0)
assert abs(a / expected - 1) < 1e-5, (a, expected)
print(f"[install-sionna] OK: sionna-rt {rt.__version__}, variant {mi.variant()}, "
      f"libLLVM {'.'.join(map(str, dr.detail.llvm_version()))} "
      f"({os.environ['DRJIT_LIBLLVM_PATH']}); free-space |a| = lambda/(4 pi d) "
      f"({time.perf_counter() - t0:.1f} s)")
EOF
say "finished in $(( $(date +%s) - T_START )) s"
