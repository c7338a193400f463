"""LLVM discovery, variant choice and plugin packaging."""

import os
import subprocess
import sys

import pytest

from nidar_mi import backend
from nidar_mi.errors import NidarError


def test_find_libllvm_picks_newest_supported(tmp_path):
    for name in ("libLLVM-14.so.1", "libLLVM-15.so", "libLLVM-17.so.1", "libLLVM-19.so"):
        (tmp_path / name).write_bytes(b"")
    assert backend.find_libllvm((str(tmp_path / "libLLVM-*.so*"),)) == str(
        tmp_path / "libLLVM-19.so"
    )


def test_find_libllvm_rejects_old(tmp_path):
    (tmp_path / "libLLVM-15.so").write_bytes(b"")
    assert backend.find_libllvm((str(tmp_path / "libLLVM-*.so*"),)) is None


def test_user_setting_wins(monkeypatch):
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/opt/custom/libLLVM.so")
    assert backend.configure_llvm() == "/opt/custom/libLLVM.so"


def test_import_sets_libllvm_path():
    env = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    code = "import os, nidar_mi; print(os.environ.get('DRJIT_LIBLLVM_PATH', ''))"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    path = out.stdout.strip()
    assert path == (backend.find_libllvm() or "")
    if path:
        assert backend._llvm_major(path) >= backend.LLVM_MIN_VERSION


def test_rejects_non_spectral_and_unknown_variants():
    with pytest.raises(NidarError, match="not spectral"):
        backend.set_variant("llvm_ad_rgb")
    with pytest.raises(NidarError, match="unknown Mitsuba variant"):
        backend.set_variant("vulkan_spectral")


def test_default_variant_is_spectral(variant):
    assert backend.default_variant() in backend.SUPPORTED_VARIANTS


def test_plugins_ship_inside_the_package():
    import nidar_mi.plugins as plugins

    assert plugins.__name__ == "nidar_mi.plugins"
    assert "lidar" in plugins.PLUGIN_MODULES
    for name in plugins.PLUGIN_MODULES:
        mod = __import__(f"nidar_mi.plugins.{name}", fromlist=["register"])
        assert callable(mod.register)
