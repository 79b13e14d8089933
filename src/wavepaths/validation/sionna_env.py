"""Locate libLLVM and import NVIDIA Sionna RT safely.

Sionna RT 2.x runs on the CPU through Mitsuba's ``llvm_ad_mono_polarized``
variant, whose Dr.Jit backend loads ``libLLVM`` at ``import drjit`` time. Dr.Jit
needs LLVM >= 16: an older library (Debian 12 ships 14 and 15) imports fine and
even runs small kernels, then aborts the whole process with ``LLVM ERROR:
Cannot select ... fmaximum`` inside the path solver. This module therefore
picks a suitable ``libLLVM`` *before* Dr.Jit is imported and turns every missing
piece into a :class:`wavepaths.errors.DependencyError` with the install command.

Nothing here imports Sionna, Mitsuba or Dr.Jit at module import time, and the
Mitsuba variant is only set by :func:`ensure_sionna`.

Functions
---------
find_libllvm
    Path of a usable ``libLLVM`` (major version >= 16), or ``None``.
libllvm_major_version
    Major LLVM version encoded in a ``libLLVM`` file name.
ensure_sionna
    Import and return ``sionna.rt`` with the LLVM variant set.
sionna_version
    Installed ``sionna-rt`` version, or ``None``.

Examples
--------
>>> from wavepaths.validation.sionna_env import ensure_sionna  # doctest: +SKIP
>>> rt = ensure_sionna()  # doctest: +SKIP
>>> scene = rt.load_scene(rt.scene.simple_wedge)  # doctest: +SKIP
"""

from __future__ import annotations

import glob
import importlib
import importlib.metadata
import importlib.util
import os
import platform
import re
import site
import sys
import sysconfig
from collections.abc import Iterable, Mapping, Sequence
from types import ModuleType

from wavepaths.errors import DependencyError

__all__ = [
    "INSTALL_COMMAND",
    "LLVM_MIN_VERSION",
    "SIONNA_VARIANT",
    "ensure_sionna",
    "find_libllvm",
    "libllvm_major_version",
    "sionna_version",
]

#: Oldest LLVM major version with which Dr.Jit runs Sionna RT's solvers.
LLVM_MIN_VERSION: int = 16

#: The Mitsuba variant used for every Sionna computation in wavepaths.
SIONNA_VARIANT: str = "llvm_ad_mono_polarized"

#: Command (run from the repository root, as root) that installs what is missing.
INSTALL_COMMAND: str = "bash scripts/install-sionna.sh"

_ENV_VAR = "DRJIT_LIBLLVM_PATH"

# "libLLVM-19.so", "libLLVM-14.0.6.so.1", "libLLVM-22-rust-1.95.0-stable.so"
_DASH_VERSION = re.compile(r"^libLLVM-(\d+)")
# "libLLVM.so.19.1", "libLLVM.so.23.1", "libLLVM.so.22.1-rust-1.95.0-stable"
_SO_VERSION = re.compile(r"^libLLVM\.so\.(\d+)")
# Whole shared-library names only: not "libLLVMSupport.a", not "libLLVMCore.so".
_LIBLLVM_NAME = re.compile(r"^libLLVM(-[^/]*\.so(\.[^/]*)?|\.so(\.[^/]*)?)$")

_sionna_rt: ModuleType | None = None


def libllvm_major_version(path: str) -> int | None:
    """Return the LLVM major version that a ``libLLVM`` file name encodes.

    Parameters
    ----------
    path : str
        Path or bare file name, e.g. ``/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1``.
        A versionless name (``libLLVM.so``) that is a symbolic link is resolved
        and its target's name is read instead.

    Returns
    -------
    int or None
        The major version, or ``None`` when neither the name nor a link target
        carries one.

    Examples
    --------
    >>> libllvm_major_version("libLLVM-19.so")
    19
    >>> libllvm_major_version("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")
    19
    >>> libllvm_major_version("libLLVM-14.0.6.so.1")
    14
    >>> libllvm_major_version("libLLVM.so") is None
    True
    """
    name = os.path.basename(path)
    for pattern in (_DASH_VERSION, _SO_VERSION):
        match = pattern.match(name)
        if match:
            return int(match.group(1))
    if os.path.islink(path):
        target = os.path.realpath(path)
        if os.path.basename(target) != name:
            return libllvm_major_version(target)
    return None


def _is_libllvm_name(name: str) -> bool:
    return bool(_LIBLLVM_NAME.match(name))


def _usable(path: str, min_version: int) -> bool:
    if not os.path.isfile(path):  # follows links: a dangling link is unusable
        return False
    version = libllvm_major_version(path)
    return version is not None and version >= min_version


def _best(paths: Iterable[str], min_version: int) -> str | None:
    """The usable candidate with the highest major version (ties: first seen)."""
    best: str | None = None
    best_version = -1
    seen: set[str] = set()
    for path in paths:
        if path in seen or not _is_libllvm_name(os.path.basename(path)):
            continue
        seen.add(path)
        if not _usable(path, min_version):
            continue
        version = libllvm_major_version(path)
        assert version is not None
        if version > best_version:
            best, best_version = path, version
    return best


def _debian_candidates(system_root: str) -> list[str]:
    root = os.path.abspath(system_root)
    machine = platform.machine() or "x86_64"
    multiarch = {"x86_64": "x86_64-linux-gnu", "amd64": "x86_64-linux-gnu",
                 "aarch64": "aarch64-linux-gnu", "arm64": "aarch64-linux-gnu"}
    triplet = multiarch.get(machine.lower(), f"{machine}-linux-gnu")
    patterns = [
        # Debian's llvm-N packages: /usr/lib/llvm-19/lib/libLLVM.so.19.1 etc.
        os.path.join(root, "usr", "lib", "llvm-[1-9][0-9]", "lib", "libLLVM*.so*"),
        # Debian's libllvmN package: /usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
        # (and libLLVM-19.so); older ones are libLLVM-15.so.1 and are filtered out.
        os.path.join(root, "usr", "lib", triplet, "libLLVM*.so*"),
        os.path.join(root, "usr", "lib64", "libLLVM*.so*"),
    ]
    found: list[str] = []
    for pattern in patterns:
        found.extend(sorted(glob.glob(pattern)))
    return found


def _python_env_dirs() -> list[str]:
    dirs: list[str] = []
    for getter in (site.getsitepackages,):
        try:
            dirs.extend(getter())
        except AttributeError:  # pragma: no cover - some embedded interpreters
            pass
    for key in ("purelib", "platlib"):
        path = sysconfig.get_paths().get(key)
        if path:
            dirs.append(path)
    # Wheels that install data into the environment prefix (e.g.
    # karellen-llvm-core puts libLLVM.so.23.1 into <venv>/lib).
    dirs.append(os.path.join(sys.prefix, "lib"))
    unique: list[str] = []
    for path in dirs:
        if path not in unique:
            unique.append(path)
    return unique


def _python_env_candidates(site_dirs: Sequence[str]) -> list[str]:
    found: list[str] = []
    for base in site_dirs:
        for pattern in ("libLLVM*.so*", os.path.join("*", "libLLVM*.so*"),
                        os.path.join("*", "lib", "libLLVM*.so*"),
                        os.path.join("*", "lib64", "libLLVM*.so*"),
                        os.path.join("*", "*", "lib", "libLLVM*.so*")):
            found.extend(sorted(glob.glob(os.path.join(base, pattern))))
    return found


def find_libllvm(*, env: Mapping[str, str] | None = None,
                 system_root: str = "/",
                 site_dirs: Sequence[str] | None = None,
                 min_version: int = LLVM_MIN_VERSION) -> str | None:
    """Find a ``libLLVM`` shared library that Dr.Jit can use for Sionna RT.

    Candidates are looked at in this order, and the first group that holds a
    usable library wins (within a group, the highest major version):

    1. ``DRJIT_LIBLLVM_PATH`` from ``env``, if it names an existing file whose
       name carries a major version >= ``min_version`` or no version at all;
    2. Debian's packages: ``/usr/lib/llvm-NN/lib/libLLVM*.so*`` and
       ``/usr/lib/<multiarch>/libLLVM*.so*`` (``libllvm19`` installs
       ``libLLVM.so.19.1`` and ``libLLVM-19.so`` there);
    3. a ``libLLVM`` shipped inside the Python environment: in the
       site-packages folders (up to two levels down) or in ``<sys.prefix>/lib``.

    Parameters
    ----------
    env : Mapping[str, str], optional
        Environment to read ``DRJIT_LIBLLVM_PATH`` from; ``os.environ`` if None.
    system_root : str, default "/"
        Root under which the Debian paths are searched (tests use a fake tree).
    site_dirs : Sequence[str], optional
        Python environment folders to search; the running interpreter's
        site-packages and ``<sys.prefix>/lib`` if None.
    min_version : int, default 16
        Oldest acceptable LLVM major version.

    Returns
    -------
    str or None
        Path of the library, or ``None`` if no usable one was found.
    """
    environ = os.environ if env is None else env
    explicit = environ.get(_ENV_VAR, "")
    if explicit and os.path.isfile(explicit):
        version = libllvm_major_version(explicit)
        # A name without a version is trusted: ensure_sionna() checks the
        # version that Dr.Jit actually loaded.
        if version is None or version >= min_version:
            return explicit
    groups = (
        _debian_candidates(system_root),
        _python_env_candidates(_python_env_dirs() if site_dirs is None else site_dirs),
    )
    for group in groups:
        best = _best(group, min_version)
        if best is not None:
            return best
    return None


def sionna_version() -> str | None:
    """Return the installed ``sionna-rt`` distribution version, or ``None``.

    Reads package metadata only: Sionna, Mitsuba and Dr.Jit are not imported.
    """
    try:
        return importlib.metadata.version("sionna-rt")
    except importlib.metadata.PackageNotFoundError:
        return None


def _missing_llvm_message(explicit: str) -> str:
    why = ""
    if explicit:
        if not os.path.isfile(explicit):
            why = (f" DRJIT_LIBLLVM_PATH is set to {explicit!r}, which does not"
                   " exist.")
        else:
            why = (f" DRJIT_LIBLLVM_PATH is set to {explicit!r}, whose version"
                   f" is older than {LLVM_MIN_VERSION} or unknown.")
    return (
        f"Sionna RT needs libLLVM >= {LLVM_MIN_VERSION} for Dr.Jit's CPU (LLVM) "
        "backend, and none was found (looked at DRJIT_LIBLLVM_PATH, "
        "/usr/lib/llvm-NN/lib, the system's multiarch library folder and the "
        f"Python environment).{why} An older libLLVM (Debian 12's 14 or 15) "
        "would make Dr.Jit abort the process inside the path solver. Install "
        f"one with `{INSTALL_COMMAND}` (as root: it installs Debian's libllvm19, "
        "or else the karellen-llvm-core wheel into the virtual environment), or "
        "set DRJIT_LIBLLVM_PATH to the full path of a libLLVM.so of version "
        f"{LLVM_MIN_VERSION} or newer."
    )


def _missing_sionna_message() -> str:
    return (
        "Sionna RT is not installed in this Python environment (the module "
        "`sionna.rt` from the PyPI package sionna-rt==2.2.0 was not found), so "
        "the comparison with Sionna cannot run. Install it, together with a "
        f"libLLVM >= {LLVM_MIN_VERSION} that its Dr.Jit backend needs, with "
        f"`{INSTALL_COMMAND}` (run from the repository root as root; pass the "
        "virtual environment as its argument if it is not .venv)."
    )


def _sionna_installed() -> bool:
    return sionna_version() is not None and importlib.util.find_spec("sionna") is not None


def _loaded_llvm_version(drjit: ModuleType) -> tuple[int, ...] | None:
    try:
        version = drjit.detail.llvm_version()
    except Exception:  # noqa: BLE001 - backend missing or very old Dr.Jit
        return None
    if not version:
        return None
    return tuple(int(v) for v in version)


def ensure_sionna() -> ModuleType:
    """Import Sionna RT with a usable libLLVM and the LLVM polarized variant.

    Sets ``DRJIT_LIBLLVM_PATH`` to :func:`find_libllvm`'s answer when Dr.Jit has
    not been imported yet, imports Mitsuba, selects the variant
    ``llvm_ad_mono_polarized`` and imports ``sionna.rt``. Later calls return the
    cached module.

    Returns
    -------
    types.ModuleType
        The ``sionna.rt`` module.

    Raises
    ------
    DependencyError
        If sionna-rt is not installed, if no libLLVM >= 16 can be found, or if
        Dr.Jit was already imported (by other code) with an LLVM that is too old
        or missing. The message says what is missing and how to install it.
    """
    global _sionna_rt
    if _sionna_rt is not None:
        return _sionna_rt

    if not _sionna_installed():
        raise DependencyError(_missing_sionna_message())

    explicit = os.environ.get(_ENV_VAR, "")
    if "drjit" not in sys.modules:
        lib = find_libllvm()
        if lib is None:
            raise DependencyError(_missing_llvm_message(explicit))
        os.environ[_ENV_VAR] = lib

    try:
        import drjit
    except ImportError as exc:  # pragma: no cover - broken installation
        raise DependencyError(
            f"Dr.Jit (a dependency of sionna-rt) cannot be imported: {exc}. "
            f"Reinstall it with `{INSTALL_COMMAND}`."
        ) from exc

    if not drjit.has_backend(drjit.JitBackend.LLVM):
        raise DependencyError(_missing_llvm_message(os.environ.get(_ENV_VAR, "")))
    loaded = _loaded_llvm_version(drjit)
    if loaded is not None and loaded[0] < LLVM_MIN_VERSION:
        raise DependencyError(
            f"Dr.Jit was already imported with libLLVM {'.'.join(map(str, loaded))}, "
            f"older than the {LLVM_MIN_VERSION} that Sionna RT's solvers need "
            "(it would abort the process). Call ensure_sionna() before anything "
            "imports drjit or mitsuba, or set DRJIT_LIBLLVM_PATH to a libLLVM >= "
            f"{LLVM_MIN_VERSION} before starting Python; `{INSTALL_COMMAND}` "
            "installs one."
        )

    try:
        import mitsuba as mi

        if mi.variant() != SIONNA_VARIANT:
            mi.set_variant(SIONNA_VARIANT)
        rt = importlib.import_module("sionna.rt")
    except ImportError as exc:
        raise DependencyError(
            f"Sionna RT could not be imported with the Mitsuba variant "
            f"{SIONNA_VARIANT!r}: {exc}. Reinstall it with `{INSTALL_COMMAND}`."
        ) from exc
    if mi.variant() != SIONNA_VARIANT:  # sionna.rt imported earlier with another
        mi.set_variant(SIONNA_VARIANT)
    _sionna_rt = rt
    return rt
