"""The physical form: the LiDAR equation in closed form, against the formula; its file; its fit."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.profiles import FORMS, PhysicalMap, SensorProfile, fit, load_profile


def _returns(n=5000, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-0.2, 1.3, n), rng.uniform(0.2, 80, n), rng.uniform(0, 1, n)


def test_raw_and_compensated_follow_the_formula():
    v, d, c = _returns()
    rho = np.clip(v, 0, 1)
    raw = PhysicalMap(gain=50.0, range_exponent=2.0)
    expected = np.clip(50.0 * rho * c / np.maximum(d, 1.0) ** 2, 0, 1)
    np.testing.assert_allclose(raw(v, d, cos_incidence=c), expected, rtol=1e-12)
    comp = PhysicalMap(gain=1.0)
    np.testing.assert_allclose(comp(v, d, cos_incidence=c), rho * c, rtol=1e-12)
    flat = PhysicalMap(gain=1.0, incidence=False)
    np.testing.assert_allclose(flat(v, d), rho, rtol=1e-12)
    assert raw.uses_incidence and not flat.uses_incidence and raw.uses_geometry
    assert not comp.uses_geometry
    # a 10 %-reflective target head-on at 10 m: 50 * 0.1 / 100
    assert raw([0.1], [10.0], cos_incidence=[1.0])[0] == pytest.approx(0.05)
    with pytest.raises(NidarError, match="reads the incidence"):
        raw(v, d)


def test_round_trip_through_a_profile_file(tmp_path):
    assert FORMS["physical"] is PhysicalMap
    m = PhysicalMap(gain=42.0, range_exponent=2.0, incidence=True, min_range_m=0.5)
    p = SensorProfile("raw-x", "a raw sensor", "physical", "nidar:R", m)
    p.save(tmp_path / "p.json")
    q = load_profile(tmp_path / "p.json")
    assert q.mapping == m and q.uses_incidence
    v, d, c = _returns(100)
    np.testing.assert_array_equal(q(v, d, cos_incidence=c), p(v, d, cos_incidence=c))


@pytest.mark.parametrize(
    ("mapping", "needle"),
    [
        ({}, "missing 'gain'"),
        ({"gain": 1, "x": 2}, "unknown field"),
        ({"gain": -1}, "'gain' must be positive"),
        ({"gain": 1, "range_exponent": 9}, "'range_exponent' must be"),
        ({"gain": 1, "incidence": "yes"}, "'incidence' must be true or false"),
    ],
)
def test_bad_mappings_are_one_line_errors(mapping, needle):
    with pytest.raises(NidarError, match=needle):
        PhysicalMap.from_dict(mapping)


def test_fit_recovers_gain_and_exponent():
    v, d, c = _returns(20_000, 1)
    v = np.clip(v, 0.05, 1)
    d = np.maximum(d, 2.0)
    y = np.clip(30.0 * v * c / d**2, 0, 1)
    m = fit("physical", v, d, y, cos_incidence=c)
    assert m.gain == pytest.approx(30.0, rel=1e-6) and m.range_exponent == pytest.approx(2.0)
    fixed = fit("physical", v, d, y * d**2 / 30.0 * 0.7, cos_incidence=c, range_exponent=0.0)
    assert fixed.range_exponent == 0.0 and fixed.uses_incidence
    with pytest.raises(NidarError, match="usable returns"):
        fit("physical", v[:5], d[:5], y[:5])
