"""Lighting regimes: ``varied`` redraws sun and sky per scene and keeps everything else."""

from __future__ import annotations

import json

import pytest

from nidar_mi.errors import NidarError
from nidar_mi.scenegen.generate import generate, generate_scene
from nidar_mi.scenegen.lighting import relight


def test_varied_keeps_the_shapes_and_changes_the_light():
    base, _ = generate_scene(3, 0, "urban")
    lit, text = generate_scene(3, 0, "urban", lighting="varied")
    assert lit.shapes == base.shapes and lit.rig == base.rig
    assert (lit.sun, lit.sky) != (base.sun, base.sky)
    assert generate_scene(3, 0, "urban", lighting="varied")[1] == text  # deterministic
    assert relight(base, 3, 0) is base


def test_varied_draws_overcast_and_low_sun():
    layouts = [generate_scene(5, k, "urban", lighting="varied")[0] for k in range(24)]
    overcast = [lay for lay in layouts if lay.sun.scale < 0.1]
    assert 0 < len(overcast) < len(layouts)
    assert all(lay.sky.scale >= 2.0 for lay in overcast)
    elevations = [lay.sun.elevation_deg for lay in layouts]
    assert min(elevations) >= 6.0 and max(elevations) <= 80.0


def test_unknown_regime_is_an_error():
    with pytest.raises(NidarError, match="lighting must be one of"):
        generate_scene(0, 0, "urban", lighting="night")


def test_the_index_records_the_regime(tmp_path):
    generate(str(tmp_path), 1, 4, kind="urban", progress=False, lighting="varied")
    entry = json.loads((tmp_path / "index.json").read_text())["scenes"][0]
    assert entry["lighting"] == "varied"
