"""Shared fixtures: the Mitsuba variant and small scene builders."""

from __future__ import annotations

import os
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if REPO not in sys.path:
    sys.path.insert(0, REPO)


@pytest.fixture(scope="session")
def variant() -> str:
    """Activate the CPU spectral variant once per session."""
    from nidar_mi.backend import set_variant

    return set_variant("llvm_ad_spectral")


@pytest.fixture()
def write_scene(tmp_path):
    """Write an XML body into a complete scene file and return its path."""

    def _write(body: str, name: str = "scene.xml") -> str:
        path = tmp_path / name
        path.write_text(f'<?xml version="1.0"?>\n<scene version="3.0.0">\n{body}\n</scene>\n')
        return str(path)

    return _write
