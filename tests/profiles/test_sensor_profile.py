"""Sensor profiles: the file format, its validation, every form through one interface."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.profiles import PROFILE_SCHEMA, fit, load_profile
from tests.helpers.profiles import fitted_profile


def _data(n=20_000, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.uniform(0, 1, n)
    d = rng.uniform(2, 60, n)
    ring = rng.integers(0, 8, n)
    el = -2.0 * ring
    ref = np.clip(v * np.exp(-d / 30) * (0.8 + 0.05 * ring), 0, 1)
    return v, d, ring, el, ref


@pytest.mark.parametrize("form", ["distance_quantile", "range_ring", "gbm"])
def test_round_trip_through_a_file(tmp_path, form):
    v, d, ring, el, ref = _data()
    p = fitted_profile(
        v,
        d,
        ref,
        form=form,
        name="test-1",
        sensor="x",
        input="nidar:R",
        ring=ring,
        elevation_deg=el,
    )
    path = tmp_path / "p.json"
    p.save(path)
    data = json.loads(path.read_text())
    assert (
        data["schema"] == PROFILE_SCHEMA
        and data["form"] == form
        and "schema" not in data["mapping"]
    )
    q = load_profile(path)
    out = p(v[:1000], d[:1000], ring=ring[:1000], elevation_deg=el[:1000])
    assert out.dtype == np.float32 and ((out >= 0) & (out <= 1)).all()
    np.testing.assert_array_equal(
        q(v[:1000], d[:1000], ring=ring[:1000], elevation_deg=el[:1000]), out
    )
    assert q.branch == "R"


def test_distance_quantile_is_the_paper_calibration():
    v, d, _, _, ref = _data()
    p = fitted_profile(v, d, ref, form="distance_quantile", name="p", sensor="", input="nidar:R")
    cal = fit("distance_quantile", v, d, ref)
    np.testing.assert_allclose(p(v, d), cal.quantile_map(cal.encode(v, d)), rtol=1e-6)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d | {"schema": "other/1"}, "'schema' must be"),
        (lambda d: d | {"form": "cubic"}, "'form' must be one of"),
        (lambda d: {k: v for k, v in d.items() if k != "mapping"}, "missing field"),
        (lambda d: d | {"extra": 1}, "unknown field"),
        (lambda d: d | {"name": "has space"}, "profile name"),
        (lambda d: d | {"mapping": {"gains": [1]}}, "'mapping'"),
        (
            lambda d: (
                d | {"mapping": d["mapping"] | {"gains": [-1.0] * len(d["mapping"]["gains"])}}
            ),
            "gains",
        ),
        (lambda d: d | {"model": [1]}, "'model' must be"),
    ],
)
def test_invalid_files_are_one_line_errors(tmp_path, edit, message):
    v, d, ring, el, ref = _data(5000)
    good = fitted_profile(
        v,
        d,
        ref,
        form="range_ring",
        name="g",
        sensor="",
        input="nidar:R",
        ring=ring,
        elevation_deg=el,
    )
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(edit(good.to_dict())))
    with pytest.raises(NidarError, match=message) as info:
        load_profile(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_unreadable_files(tmp_path):
    with pytest.raises(NidarError, match="no such profile"):
        load_profile(tmp_path / "none.json")
    (tmp_path / "x.json").write_text("{not json")
    with pytest.raises(NidarError, match="not valid JSON"):
        load_profile(tmp_path / "x.json")


def test_non_finite_values_are_an_error_not_nan():
    v, d, _, _, ref = _data(5000)
    p = fitted_profile(v, d, ref, form="range_ring", name="p", sensor="", input="nidar:R")
    with pytest.raises(NidarError, match="finite"):
        p([0.5, np.nan], [10.0, 10.0])
