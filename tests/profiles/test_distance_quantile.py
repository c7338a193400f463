"""Tests for nidar_mi.nidar.calibration (distance encoding, quantile map, calibration I/O)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.nidar.calibration import (
    DEFAULT_K,
    Calibration,
    QuantileMap,
    distance_encode,
    fit_calibration,
)

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


def test_quantile_map_monotone_and_exact_on_knots():
    rng = np.random.default_rng(0)
    src = rng.beta(2.0, 5.0, 5000)
    ref = rng.gamma(2.0, 0.1, 3000).clip(0, 1)
    qm = QuantileMap.fit(src, ref, K=DEFAULT_K)
    assert np.all(np.diff(qm.q_source) > 0)
    assert np.all(np.diff(qm.levels) > 0)
    np.testing.assert_array_equal(qm(qm.q_source), np.clip(qm.q_reference, 0, 1))
    np.testing.assert_allclose(qm.q_reference, np.quantile(ref, qm.levels), rtol=0, atol=0)
    x = np.linspace(-0.5, 1.5, 20001)
    y = qm(x)
    assert np.all(np.diff(y) >= 0)
    assert y.min() >= 0.0 and y.max() <= 1.0
    # outside the knots the end values are held
    assert qm(-1.0) == qm.q_reference[0] and qm(2.0) == qm.q_reference[-1]


def test_quantile_map_identity_when_source_equals_reference():
    rng = np.random.default_rng(1)
    v = rng.uniform(0.0, 1.0, 2000)
    qm = QuantileMap.fit(v, v, K=51)
    x = np.linspace(v.min(), v.max(), 1000)
    np.testing.assert_allclose(qm(x), x, rtol=0, atol=1e-12)


def test_quantile_map_recovers_a_monotone_transform():
    # N - 1 = 10000 and levels k/100: every knot is an order statistic, so Q_r = Q_s**2.
    rng = np.random.default_rng(2)
    src = rng.uniform(0.0, 1.0, 10001)
    qm = QuantileMap.fit(src, src**2, K=101)
    np.testing.assert_allclose(qm.q_reference, qm.q_source**2, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(qm(qm.q_source), qm.q_source**2, rtol=1e-12, atol=1e-15)


def test_quantile_map_merges_tied_knots_at_mid_level():
    src = np.concatenate([np.zeros(500), np.linspace(0.1, 1.0, 501)])  # N = 1001
    ref = np.linspace(0.0, 1.0, 1001)
    levels = np.linspace(0.0, 1.0, 11)
    qm = QuantileMap.fit(src, ref, levels=levels)
    # Levels 0 .. 0.4 give source quantile 0 (order statistics 0..400 are zeros); level 0.5
    # is order statistic 500, the first non-zero value 0.1.
    assert qm.q_source[0] == 0.0
    assert qm.levels[0] == pytest.approx(0.2)  # middle of 0, .1, .2, .3, .4
    assert qm.q_reference[0] == pytest.approx(0.2)  # ref is uniform: quantile == level
    assert qm.levels.size == 7
    np.testing.assert_allclose(qm.levels[1:], levels[5:])
    assert np.all(np.diff(qm.q_source) > 0)


def test_quantile_map_constant_source_warns():
    with pytest.warns(UserWarning, match="constant"):
        qm = QuantileMap.fit(np.full(100, 0.3), np.linspace(0, 1, 100), K=5)
    assert qm.levels.tolist() == [0.5]
    assert qm(0.0) == pytest.approx(0.5)


def test_quantile_map_json_round_trip():
    rng = np.random.default_rng(3)
    qm = QuantileMap.fit(rng.uniform(size=300), rng.uniform(size=200), K=17)
    back = QuantileMap.from_dict(json.loads(json.dumps(qm.to_dict())))
    for name in ("levels", "q_source", "q_reference"):
        np.testing.assert_array_equal(getattr(back, name), getattr(qm, name))
    x = rng.uniform(-0.1, 1.1, 100)
    np.testing.assert_array_equal(back(x), qm(x))


def test_quantile_map_rejects_bad_knots_and_inputs():
    with pytest.raises(NidarError, match="strictly increasing"):
        QuantileMap(levels=[0.0, 1.0], q_source=[0.5, 0.5], q_reference=[0.0, 1.0])
    with pytest.raises(NidarError, match="non-decreasing"):
        QuantileMap(levels=[0.0, 1.0], q_source=[0.0, 1.0], q_reference=[1.0, 0.0])
    with pytest.raises(NidarError, match="length"):
        QuantileMap(levels=[0.0, 1.0], q_source=[0.0, 1.0], q_reference=[0.0])
    with pytest.raises(NidarError, match="missing"):
        QuantileMap.from_dict({"levels": [0.0, 1.0]})
    with pytest.raises(NidarError, match="NaN"):
        QuantileMap.fit([0.1, np.nan], [0.2, 0.3])
    with pytest.raises(NidarError, match="empty"):
        QuantileMap.fit([], [0.2, 0.3])
    with pytest.raises(NidarError, match="levels"):
        QuantileMap.fit([0.1, 0.2], [0.2, 0.3], levels=[0.5, 0.2])


def test_quantile_map_is_immutable():
    qm = QuantileMap(levels=[0.0, 1.0], q_source=[0.0, 1.0], q_reference=[0.0, 0.5])
    with pytest.raises(ValueError):
        qm.q_source[0] = 3.0


# --- calibration ------------------------------------------------------------------------


def _halving_calibration() -> Calibration:
    qm = QuantileMap(levels=[0.0, 1.0], q_source=[0.0, 1.0], q_reference=[0.0, 0.5])
    return Calibration(quantile_map=qm, **ENC)


def test_calibration_apply_hand_values_and_unobserved():
    cal = _halving_calibration()
    values = np.array([0.5, 0.9, 0.5, np.nan, 0.7])
    dist = np.array([30.0, 30.0, 10.0, 20.0, 20.0])
    observed = np.array([True, True, True, True, False])
    out, obs = cal.apply(values, dist, observed)
    assert out.dtype == np.float32 and obs.dtype == bool
    # encoded: 0.25, 0.75, 0.5; halved by the map. NaN -> unobserved; unobserved -> 0.
    np.testing.assert_allclose(out, [0.125, 0.375, 0.25, 0.0, 0.0], rtol=0, atol=1e-7)
    assert obs.tolist() == [True, True, True, False, False]
    out_all, obs_all = cal.apply(values[:3], dist[:3])
    assert obs_all.all()
    np.testing.assert_array_equal(out_all, out[:3])


def test_calibration_json_round_trip(tmp_path):
    rng = np.random.default_rng(4)
    cal = fit_calibration(rng.uniform(size=500), rng.uniform(2, 60, 500), rng.beta(2, 3, 500), K=21)
    path = tmp_path / "calibration.json"
    cal.save_json(path)
    assert [p.name for p in tmp_path.iterdir()] == ["calibration.json"]
    back = Calibration.load_json(path)
    assert (back.d_min, back.d_max, back.tau, back.r_retro, back.branch) == (
        cal.d_min,
        cal.d_max,
        cal.tau,
        cal.r_retro,
        "R",
    )
    v, d = rng.uniform(size=50), rng.uniform(0, 80, 50)
    np.testing.assert_array_equal(back.apply(v, d)[0], cal.apply(v, d)[0])


def test_calibration_load_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    for path in (bad, tmp_path / "missing.json"):
        with pytest.raises(NidarError) as info:
            Calibration.load_json(path)
        assert "\n" not in str(info.value) and str(path) in str(info.value)
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"schema": "nidar_mi.calibration/1", "distance_encoding": {}}))
    with pytest.raises(NidarError, match="d_min"):
        Calibration.load_json(wrong)


def test_fit_calibration_matches_reference_quantiles():
    # range_quantiles (0, 1) and N - 1 = 10000 with levels k/100: the calibrated training
    # values are a monotone image of order statistics, so their quantiles equal Q_r.
    rng = np.random.default_rng(5)
    n = 10001
    pred = rng.uniform(0.05, 0.95, n)
    dist = rng.uniform(3.0, 70.0, n)
    ref = rng.beta(1.5, 4.0, 7000)
    cal = fit_calibration(pred, dist, ref, range_quantiles=(0.0, 1.0), K=101)
    assert cal.d_min == dist.min() and cal.d_max == dist.max()
    out, obs = cal.apply(pred, dist)
    assert obs.all()
    levels = cal.quantile_map.levels
    np.testing.assert_allclose(np.quantile(out, levels), np.quantile(ref, levels), atol=1e-6)


def test_fit_calibration_default_range_and_errors():
    rng = np.random.default_rng(6)
    dist = rng.uniform(0.0, 100.0, 1000)
    cal = fit_calibration(rng.uniform(size=1000), dist, rng.uniform(size=1000))
    assert cal.d_min == pytest.approx(np.quantile(dist, 0.01))
    assert cal.d_max == pytest.approx(np.quantile(dist, 0.99))
    with pytest.raises(NidarError, match="distances"):
        fit_calibration(np.zeros(3), np.zeros(4), np.zeros(3))
    with pytest.raises(NidarError, match="range"):
        fit_calibration(np.linspace(0, 1, 5), np.full(5, 7.0), np.linspace(0, 1, 5))
    with pytest.warns(UserWarning, match="outside"):
        fit_calibration(np.linspace(0, 1, 5), np.arange(5.0), np.linspace(0, 255, 5))
