"""The quantile map shared by the distance_quantile and range_ring forms."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.profiles.quantile_map import DEFAULT_K, QuantileMap


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
