"""The range_ring form: a simulated sensor with a known range response and ring gains."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.profiles import RangeRingMap, fit
from nidar_mi.profiles.range_ring import range_bins, ring_gains

GAINS = np.linspace(0.6, 1.4, 16)


def sensor(n, seed):
    """Returns of a 16-ring sensor: I = clip(g_ring · ρ · exp(-d / 40), 0, 1)."""
    rng = np.random.default_rng(seed)
    rho = rng.uniform(0.05, 0.9, n)
    d = rng.uniform(2.0, 60.0, n)
    ring = rng.integers(0, 16, n)
    el = -1.0 * ring + rng.normal(0, 0.05, n)  # ring r sits at -r degrees
    I = np.clip(GAINS[ring] * rho * np.exp(-d / 40.0), 0.0, 1.0)
    return rho, d, ring, el, I


def test_a_perfect_model_value_recovers_the_sensor():
    rho, d, ring, el, I = sensor(200_000, 0)
    m = fit("range_ring", rho, d, I, ring=ring, elevation_deg=el)
    # gains up to the common factor (count-weighted mean 1)
    np.testing.assert_allclose(m.gains / m.gains.mean(), GAINS / GAINS.mean(), rtol=0.02)
    np.testing.assert_allclose(m.ring_elevation_deg, -np.arange(16.0), atol=0.01)
    rho2, d2, ring2, el2, I2 = sensor(20_000, 1)  # fresh returns
    pred = m(rho2, d2, ring=ring2, elevation_deg=el2)
    assert np.sqrt(np.mean((pred - I2) ** 2)) < 0.01
    # the paper's form cannot express ring gains: an order of magnitude worse here
    cal = fit("distance_quantile", rho, d, I)
    paper = cal.quantile_map(cal.encode(rho2, d2))
    assert np.sqrt(np.mean((paper - I2) ** 2)) > 5 * np.sqrt(np.mean((pred - I2) ** 2))


def test_returns_without_a_ring_take_the_ring_of_nearest_elevation():
    rho, d, ring, el, I = sensor(100_000, 2)
    m = fit("range_ring", rho, d, I, ring=ring, elevation_deg=el)
    rho2, d2, ring2, el2, _ = sensor(2000, 3)
    np.testing.assert_array_equal(
        m(rho2, d2, elevation_deg=el2), m(rho2, d2, ring=ring2, elevation_deg=el2)
    )
    # neither ring nor elevation: gain 1
    no_ring = m(rho2, d2)
    g = m.gains[ring2]
    ratio = m(rho2, d2, ring=ring2) / np.maximum(no_ring, 1e-9)
    ok = (no_ring > 1e-3) & (no_ring * g < 1)
    np.testing.assert_allclose(ratio[ok], g[ok], rtol=1e-9)


def test_monotone_in_the_value_within_range_and_ring():
    rho, d, ring, el, I = sensor(50_000, 4)
    m = fit("range_ring", rho, d, I, ring=ring, elevation_deg=el)
    v = np.linspace(0, 1, 500)
    for dist in (3.0, 17.5, 44.0):
        out = m(v, np.full(500, dist), ring=np.full(500, 5))
        assert np.all(np.diff(out) >= -1e-12)


def test_bins_hold_enough_returns_and_ring_gains_need_enough_returns():
    d = np.random.default_rng(5).exponential(15.0, 30_000)
    edges = range_bins(d, width=2.0, min_points=2000)
    assert edges[0] == 0 and edges[-1] == np.inf and np.all(np.diff(edges) > 0)
    counts = np.histogram(d, edges)[0]
    assert counts.min() >= 2000 and counts.sum() == d.size
    assert np.all(np.diff(edges[:-1]) % 2.0 == 0)  # multiples of the width
    y = np.ones(1000)
    g = ring_gains(y, np.zeros(1000, int), np.r_[np.zeros(990, int), np.ones(10, int)], 1, 3, 500)
    assert g[1] == 1.0 and g[2] == 1.0  # too few returns / none: gain 1


def test_round_trip_and_validation():
    rho, d, ring, el, I = sensor(20_000, 6)
    m = fit(
        "range_ring", rho, d, I, ring=ring, elevation_deg=el, n_rings=20
    )  # rings 16..19 never seen
    assert np.isnan(m.ring_elevation_deg[16:]).all() and (m.gains[16:] == 1).all()
    back = RangeRingMap.from_dict(m.to_dict())
    np.testing.assert_array_equal(
        back(rho[:500], d[:500], ring=ring[:500]), m(rho[:500], d[:500], ring=ring[:500])
    )
    with pytest.raises(NidarError, match="edges_m must increase"):
        RangeRingMap.from_dict(m.to_dict() | {"edges_m": [0.0, 5.0]})
    with pytest.raises(NidarError, match="one increasing centre per bin"):
        RangeRingMap.from_dict(m.to_dict() | {"centres_m": m.centres_m[::-1].tolist()})
    with pytest.raises(NidarError, match="missing"):
        RangeRingMap.from_dict({"edges_m": []})
    with pytest.raises(NidarError, match="finite"):
        fit("range_ring", np.r_[rho[:10], np.nan], d[:11], I[:11])
