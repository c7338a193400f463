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


def test_plugins_ship_inside_the_package(variant):
    import sys

    import mitsuba as mi
    import nidar_mi.plugins as plugins

    assert plugins.__name__ == "nidar_mi.plugins"
    assert "lidar" in plugins.PLUGIN_MODULES
    for name in plugins.PLUGIN_MODULES:
        mod = __import__(f"nidar_mi.plugins.{name}", fromlist=["VARIANT"])
        assert mod is plugins.plugin_module(name) is sys.modules[f"nidar_mi.plugins.{name}"]
        assert mod.VARIANT == variant == mi.variant()
    assert issubclass(plugins.plugin_module("lidar").LidarSensor, mi.Sensor)
    assert issubclass(plugins.plugin_module("retroreflector").Retroreflector, mi.BSDF)


def test_plugins_are_defined_once_per_variant(variant):
    """Each variant gets its own plugin classes, derived from that variant's Mitsuba classes."""
    import sys

    import mitsuba as mi
    import nidar_mi.plugins as plugins

    other = "llvm_ad_spectral_polarized"
    if other not in mi.variants():
        pytest.skip(f"Mitsuba built without {other}")
    mine = plugins.plugin_module("lidar")
    try:
        mi.set_variant(other)
        plugins.register_all()
        theirs = plugins.plugin_module("lidar", other)
        assert theirs is not mine and theirs.VARIANT == other
        assert issubclass(theirs.LidarSensor, mi.Sensor)
        assert not issubclass(mine.LidarSensor, mi.Sensor)
        s = mi.load_dict({"type": "scene", "l": {"type": "lidar", "preset": "hdl32e"}})
        assert isinstance(s.sensors()[0], theirs.LidarSensor)
        assert sys.modules["nidar_mi.plugins.lidar"] is theirs
    finally:
        backend.set_variant(variant)
    assert plugins.plugin_module("lidar") is mine is sys.modules["nidar_mi.plugins.lidar"]
    assert plugins.plugin_module("lidar", other) is theirs  # executed once per variant


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "[parser.cpp:1718] At string (line 3, col 5): failed to instantiate sensor plugin of "
            'type "lidar": Traceback (most recent call last):\n  File "x.py", line 9, in __init__'
            "\nnidar_mi.errors.NidarError: lidar 'top': parameter 'gain' must be > 0 (got 0)",
            "lidar 'top': parameter 'gain' must be > 0 (got 0)",
        ),
        ("[parser.cpp:12] unreferenced property 'wavelenght'", None),
    ],
)
def test_parameter_error_reads_the_plugin_message(text, message):
    from nidar_mi.plugins import parameter_error

    from nidar_mi.errors import NidarError

    assert parameter_error(RuntimeError(text)) == message
    assert parameter_error(NidarError("x: parameter 'y' bad")) == "x: parameter 'y' bad"


def test_signals_wait_until_the_extensions_are_loaded():
    """A SIGTERM that arrives while the variant starts is handled when it has started."""
    import os
    import signal
    import time

    order = []
    old = signal.signal(signal.SIGTERM, lambda *a: order.append("handled"))
    try:
        with backend.signals_deferred():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.05)
            order.append("block ended")
        time.sleep(0.05)
    finally:
        signal.signal(signal.SIGTERM, old)
    assert order == ["block ended", "handled"]
