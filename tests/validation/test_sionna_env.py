"""Tests of wavepaths.validation.sionna_env that need neither Sionna nor libLLVM.

``find_libllvm`` is run on fake directory trees under ``tmp_path``; ``ensure_sionna``
is checked to fail with a DependencyError (never a Dr.Jit crash) when no usable
libLLVM exists. Sionna is not imported here.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from wavepaths.errors import DependencyError
from wavepaths.validation import sionna_env
from wavepaths.validation.sionna_env import find_libllvm, libllvm_major_version


def touch(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"\x7fELF fake")
    return path


def link(path: Path, target: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    os.symlink(target, path)
    return path


@pytest.fixture
def multiarch(monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setattr(sionna_env.platform, "machine", lambda: "x86_64")
    return "x86_64-linux-gnu"


@pytest.mark.parametrize(
    ("name", "version"),
    [
        ("libLLVM-19.so", 19),
        ("libLLVM.so.19.1", 19),
        ("libLLVM-15.so.1", 15),
        ("libLLVM-14.0.6.so.1", 14),
        ("libLLVM.so.23.1", 23),
        ("libLLVM-22-rust-1.95.0-stable.so", 22),
        ("libLLVM.so", None),
    ],
)
def test_major_version_from_name(name: str, version: int | None) -> None:
    assert libllvm_major_version(name) == version


def test_versionless_symlink_is_resolved(tmp_path: Path) -> None:
    touch(tmp_path / "libLLVM.so.18.1")
    lib = link(tmp_path / "libLLVM.so", "libLLVM.so.18.1")
    assert libllvm_major_version(str(lib)) == 18


def test_debian_12_without_new_llvm_finds_nothing(tmp_path: Path, multiarch: str) -> None:
    # What Debian 12 has by default: libllvm14 and libllvm15 only.
    libdir = tmp_path / "usr" / "lib" / multiarch
    touch(libdir / "libLLVM-14.0.6.so.1")
    link(libdir / "libLLVM-14.so.1", "libLLVM-14.0.6.so.1")
    touch(libdir / "libLLVM-15.so.1")
    link(libdir / "libLLVM-15.so", "libLLVM-15.so.1")
    touch(tmp_path / "usr" / "lib" / "llvm-14" / "lib" / "libLLVMSupport.a")
    assert find_libllvm(env={}, system_root=str(tmp_path), site_dirs=[]) is None


def test_debian_libllvm19_is_found(tmp_path: Path, multiarch: str) -> None:
    libdir = tmp_path / "usr" / "lib" / multiarch
    touch(libdir / "libLLVM-15.so.1")
    real = touch(libdir / "libLLVM.so.19.1")
    link(libdir / "libLLVM-19.so", "libLLVM.so.19.1")
    found = find_libllvm(env={}, system_root=str(tmp_path), site_dirs=[])
    assert found is not None
    assert libllvm_major_version(found) == 19
    assert os.path.realpath(found) == str(real)


def test_llvm_nn_folder_and_highest_version(tmp_path: Path, multiarch: str) -> None:
    touch(tmp_path / "usr" / "lib" / "llvm-16" / "lib" / "libLLVM-16.so")
    touch(tmp_path / "usr" / "lib" / "llvm-18" / "lib" / "libLLVM-18.so")
    touch(tmp_path / "usr" / "lib" / "llvm-18" / "lib" / "libLLVMCore.so")  # not the library
    found = find_libllvm(env={}, system_root=str(tmp_path), site_dirs=[])
    assert found == str(tmp_path / "usr" / "lib" / "llvm-18" / "lib" / "libLLVM-18.so")


def test_dangling_link_is_ignored(tmp_path: Path, multiarch: str) -> None:
    link(tmp_path / "usr" / "lib" / multiarch / "libLLVM-19.so", "libLLVM.so.19.1")
    assert find_libllvm(env={}, system_root=str(tmp_path), site_dirs=[]) is None


def test_library_shipped_in_python_environment(tmp_path: Path, multiarch: str) -> None:
    system = tmp_path / "root"
    touch(system / "usr" / "lib" / multiarch / "libLLVM-15.so.1")
    site = tmp_path / "venv" / "lib" / "python3.11" / "site-packages"
    wheel_lib = touch(site / "somellvm" / "lib" / "libLLVM.so.20.1")
    prefix_lib = tmp_path / "venv" / "lib"
    found = find_libllvm(env={}, system_root=str(system), site_dirs=[str(site), str(prefix_lib)])
    assert found == str(wheel_lib)


def test_library_in_venv_prefix_lib(tmp_path: Path, multiarch: str) -> None:
    # The karellen-llvm-core wheel installs <venv>/lib/libLLVM.so.23.1.
    lib = touch(tmp_path / "venv" / "lib" / "libLLVM.so.23.1")
    found = find_libllvm(env={}, system_root=str(tmp_path / "none"),
                         site_dirs=[str(tmp_path / "venv" / "lib")])
    assert found == str(lib)


def test_debian_is_preferred_over_python_environment(tmp_path: Path, multiarch: str) -> None:
    deb = touch(tmp_path / "usr" / "lib" / multiarch / "libLLVM.so.19.1")
    touch(tmp_path / "venv" / "lib" / "libLLVM.so.23.1")
    found = find_libllvm(env={}, system_root=str(tmp_path), site_dirs=[str(tmp_path / "venv" / "lib")])
    assert found == str(deb)


def test_environment_variable_wins(tmp_path: Path, multiarch: str) -> None:
    touch(tmp_path / "usr" / "lib" / multiarch / "libLLVM.so.19.1")
    custom = touch(tmp_path / "opt" / "llvm" / "libLLVM.so")  # no version: trusted
    env = {"DRJIT_LIBLLVM_PATH": str(custom)}
    assert find_libllvm(env=env, system_root=str(tmp_path), site_dirs=[]) == str(custom)


def test_environment_variable_too_old_or_missing_falls_back(tmp_path: Path, multiarch: str) -> None:
    deb = touch(tmp_path / "usr" / "lib" / multiarch / "libLLVM.so.19.1")
    old = touch(tmp_path / "usr" / "lib" / multiarch / "libLLVM-15.so.1")
    for value in (str(old), str(tmp_path / "missing" / "libLLVM-19.so")):
        env = {"DRJIT_LIBLLVM_PATH": value}
        assert find_libllvm(env=env, system_root=str(tmp_path), site_dirs=[]) == str(deb)


def test_min_version_parameter(tmp_path: Path, multiarch: str) -> None:
    touch(tmp_path / "usr" / "lib" / multiarch / "libLLVM-15.so.1")
    assert find_libllvm(env={}, system_root=str(tmp_path), site_dirs=[]) is None
    assert find_libllvm(env={}, system_root=str(tmp_path), site_dirs=[], min_version=15) is not None


def test_ensure_sionna_without_libllvm_raises_dependency_error(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    missing = tmp_path / "nowhere" / "libLLVM-19.so"
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", str(missing))
    # Whatever this machine has: pretend the search finds nothing, that Sionna
    # is installed, and that Dr.Jit has not been imported yet.
    real_find = sionna_env.find_libllvm
    monkeypatch.setattr(
        sionna_env, "find_libllvm",
        lambda **kw: real_find(system_root=str(tmp_path / "empty"), site_dirs=[], **kw))
    monkeypatch.setattr(sionna_env, "_sionna_installed", lambda: True)
    monkeypatch.setattr(sionna_env, "_sionna_rt", None)
    monkeypatch.delitem(sys.modules, "drjit", raising=False)
    modules_before = set(sys.modules)

    with pytest.raises(DependencyError) as info:
        sionna_env.ensure_sionna()

    message = str(info.value)
    assert "bash scripts/install-sionna.sh" in message
    assert "libLLVM >= 16" in message
    assert str(missing) in message and "does not exist" in message
    assert "\n" not in message  # one paragraph
    assert os.environ["DRJIT_LIBLLVM_PATH"] == str(missing)  # left untouched
    imported = set(sys.modules) - modules_before
    assert not {m for m in imported if m.split(".")[0] in {"drjit", "mitsuba", "sionna"}}


def test_ensure_sionna_without_sionna_raises_dependency_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sionna_env, "_sionna_installed", lambda: False)
    monkeypatch.setattr(sionna_env, "_sionna_rt", None)
    with pytest.raises(DependencyError, match="install-sionna.sh") as info:
        sionna_env.ensure_sionna()
    assert "sionna-rt" in str(info.value)


def test_sionna_version_is_a_string_or_none() -> None:
    version = sionna_env.sionna_version()
    assert version is None or version.count(".") >= 1
