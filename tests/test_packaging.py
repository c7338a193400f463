"""A regular (non-editable) install ships the plugins as nidar_mi.plugins."""

import os
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.slow
def test_wheel_install_ships_plugins(tmp_path):
    target = tmp_path / "site"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "--target",
            str(target),
            REPO,
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert (target / "nidar_mi" / "plugins" / "lidar.py").is_file()
    code = (
        "import nidar_mi, nidar_mi.plugins as p; print(nidar_mi.__file__); print(p.__file__);"
        "from nidar_mi.backend import set_variant; set_variant('llvm_ad_spectral');"
        "import mitsuba as mi;"
        "s = mi.load_dict({'type': 'scene', 'l': {'type': 'lidar', 'preset': 'vlp16'}});"
        "print(s.sensors()[0].config.rings)"
    )
    env = dict(os.environ, PYTHONPATH=str(target))
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=str(tmp_path),
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.split()
    assert lines[0].startswith(str(target)) and lines[1].startswith(str(target))
    assert lines[2] == "16"
