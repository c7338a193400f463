"""The distance_quantile form: distance encoding, its map, calibration.json I/O."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.profiles import DistanceQuantileMap, QuantileMap, fit
from nidar_mi.profiles.distance_quantile import distance_encode


def _fit(values, range_m, intensity, **options):
    return fit("distance_quantile", values, range_m, intensity, **options)


ENC = {"d_min": 10.0, "d_max": 50.0, "tau": 0.8, "r_retro": 0.6}


# --- distance encoding ------------------------------------------------------------------


def test_distance_encode_hand_values():
    i = np.array([0.5, 0.5, 0.5, 0.9, 0.9, 0.8, 0.5, 0.9, 1.2, -0.1])
    d = np.array([10.0, 30.0, 50.0, 30.0, 50.0, 30.0, 5.0, 90.0, 10.0, 10.0])
    # t = 0, .5, 1, .5, 1, .5, clamp 0, clamp 1, 0, 0
    expected = [
        0.5,  # t = 0: unchanged
        0.25,  # diffuse: 0.5 + (0 - 0.5) * 0.5
        0.0,  # diffuse at d_max
        0.75,  # retro: 0.9 + (0.6 - 0.9) * 0.5
        0.6,  # retro at d_max: r_retro
        0.4,  # i == tau counts as diffuse
        0.5,  # closer than d_min: t clamped to 0
        0.6,  # farther than d_max: t clamped to 1
        1.0,  # clipped to [0, 1]
        0.0,
    ]
    np.testing.assert_allclose(distance_encode(i, d, **ENC), expected, rtol=0, atol=1e-15)


def test_distance_encode_broadcasts_and_rejects_bad_range():
    out = distance_encode(np.full((2, 3), 0.4), 30.0, **ENC)
    assert out.shape == (2, 3)
    np.testing.assert_allclose(out, 0.2)
    with pytest.raises(NidarError, match="d_max > d_min"):
        distance_encode(0.5, 1.0, d_min=5.0, d_max=5.0, tau=0.8, r_retro=0.8)
    with pytest.raises(NidarError, match="finite"):
        distance_encode(0.5, 1.0, d_min=0.0, d_max=5.0, tau=np.nan, r_retro=0.8)


# --- quantile map -----------------------------------------------------------------------


# --- the map -----------------------------------------------------------------------------


def _halving_calibration() -> DistanceQuantileMap:
    qm = QuantileMap(levels=[0.0, 1.0], q_source=[0.0, 1.0], q_reference=[0.0, 0.5])
    return DistanceQuantileMap(quantile_map=qm, **ENC)


def test_map_hand_values():
    cal = _halving_calibration()
    values = np.array([0.5, 0.9, 0.5, np.nan])
    dist = np.array([30.0, 30.0, 10.0, 20.0])
    out = cal(values, dist, ring=np.zeros(4), elevation_deg=np.zeros(4))  # neither is read
    assert out.dtype == np.float64
    # encoded: 0.25, 0.75, 0.5; halved by the map; NaN stays NaN (a profile refuses it)
    np.testing.assert_allclose(out[:3], [0.125, 0.375, 0.25], rtol=0, atol=1e-12)
    assert np.isnan(out[3])
    with pytest.raises(NidarError, match="distances"):
        cal(values, dist[:3])


def test_calibration_json_round_trip(tmp_path):
    rng = np.random.default_rng(4)
    cal = _fit(rng.uniform(size=500), rng.uniform(2, 60, 500), rng.beta(2, 3, 500), K=21)
    path = tmp_path / "calibration.json"
    cal.save_json(path)
    assert [p.name for p in tmp_path.iterdir()] == ["calibration.json"]
    back = DistanceQuantileMap.load_json(path)
    assert (back.d_min, back.d_max, back.tau, back.r_retro, back.branch) == (
        cal.d_min,
        cal.d_max,
        cal.tau,
        cal.r_retro,
        "R",
    )
    v, d = rng.uniform(size=50), rng.uniform(0, 80, 50)
    np.testing.assert_array_equal(back(v, d), cal(v, d))


def test_calibration_load_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    for path in (bad, tmp_path / "missing.json"):
        with pytest.raises(NidarError) as info:
            DistanceQuantileMap.load_json(path)
        assert "\n" not in str(info.value) and str(path) in str(info.value)
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"schema": "nidar_mi.calibration/1", "distance_encoding": {}}))
    with pytest.raises(NidarError, match="d_min"):
        DistanceQuantileMap.load_json(wrong)


def test_fit_calibration_matches_reference_quantiles():
    # range_quantiles (0, 1) and N - 1 = 10000 with levels k/100: the calibrated training
    # values are a monotone image of order statistics, so their quantiles equal Q_r.
    rng = np.random.default_rng(5)
    n = 10001
    pred = rng.uniform(0.05, 0.95, n)
    dist = rng.uniform(3.0, 70.0, n)
    ref = rng.beta(1.5, 4.0, 7000)
    cal = _fit(pred, dist, ref, range_quantiles=(0.0, 1.0), K=101)
    assert cal.d_min == dist.min() and cal.d_max == dist.max()
    out = cal(pred, dist)
    levels = cal.quantile_map.levels
    np.testing.assert_allclose(np.quantile(out, levels), np.quantile(ref, levels), atol=1e-6)


def test_fit_calibration_default_range_and_errors():
    rng = np.random.default_rng(6)
    dist = rng.uniform(0.0, 100.0, 1000)
    cal = _fit(rng.uniform(size=1000), dist, rng.uniform(size=1000))
    assert cal.d_min == pytest.approx(np.quantile(dist, 0.01))
    assert cal.d_max == pytest.approx(np.quantile(dist, 0.99))
    with pytest.raises(NidarError, match="distances"):
        _fit(np.zeros(3), np.zeros(4), np.zeros(3))
    with pytest.raises(NidarError, match="range"):
        _fit(np.linspace(0, 1, 5), np.full(5, 7.0), np.linspace(0, 1, 5))
    with pytest.warns(UserWarning, match="outside"):
        _fit(np.linspace(0, 1, 5), np.arange(5.0), np.linspace(0, 255, 5))
