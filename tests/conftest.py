"""Shared fixtures: the Mitsuba variant and small scene builders."""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if REPO not in sys.path:
    sys.path.insert(0, REPO)

# derived caches (KITTI frames, fitted profiles) go to a throw-away folder, not ~/.cache
if "NIDAR_MI_CACHE" not in os.environ:
    _CACHE = tempfile.mkdtemp(prefix="nidar_mi_test_cache-")
    os.environ["NIDAR_MI_CACHE"] = _CACHE
    atexit.register(shutil.rmtree, _CACHE, True)

#: The Mitsuba variant of the test session: NIDAR_MI_TEST_VARIANT, else the CPU one. Commands the
#: tests start as child processes choose the same one (NIDAR_VARIANT, read by default_variant).
TEST_VARIANT = os.environ.get("NIDAR_MI_TEST_VARIANT") or "llvm_ad_spectral"
os.environ["NIDAR_VARIANT"] = TEST_VARIANT


@pytest.fixture(scope="session")
def variant() -> str:
    """Activate the session's variant (NIDAR_MI_TEST_VARIANT, default llvm_ad_spectral) once."""
    from nidar_mi.backend import set_variant
    from nidar_mi.errors import NidarError

    try:
        return set_variant(TEST_VARIANT)
    except NidarError as e:
        pytest.exit(f"NIDAR_MI_TEST_VARIANT={TEST_VARIANT}: {e}", returncode=4)


@pytest.fixture()
def write_scene(tmp_path):
    """Write an XML body into a complete scene file and return its path."""

    def _write(body: str, name: str = "scene.xml") -> str:
        path = tmp_path / name
        path.write_text(f'<?xml version="1.0"?>\n<scene version="3.0.0">\n{body}\n</scene>\n')
        return str(path)

    return _write
