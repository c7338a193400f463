"""The link budget of the presets' detection numbers: closed forms, the catalog's road
roughness, the receiver-noise detection model, and scans against them."""

import math

import numpy as np
import pytest
from scipy.stats import norm

from nidar_mi.lidar.link_budget import (
    FALSE_ALARM_PROBABILITY,
    HDL64E_DATASHEET,
    KITTI_SENSOR_HEIGHT_M,
    ground_detection_probability,
    ground_reach,
    ground_return,
    noise_for,
    sigma_for_reach,
    target_reach,
    threshold_for,
    threshold_to_noise,
)
from nidar_mi.lidar.pattern import PRESETS
from nidar_mi.lidar.return_model import detection_probability

T64 = PRESETS["hdl64e"].detection_threshold
NOISE64 = PRESETS["hdl64e"].receiver_noise_std


def _binomial_tol(p: float, n: int, sigmas: float = 4.5) -> float:
    """``sigmas`` binomial deviations of a fraction of ``n`` independent draws (at least 1/n)."""
    return sigmas * math.sqrt(max(p * (1.0 - p), 1.0 / n) / n)


def test_threshold_is_the_datasheets_pavement_figure():
    rho, d = HDL64E_DATASHEET["pavement"]
    assert threshold_for(rho, d) == pytest.approx(4e-5, rel=1e-12)
    assert T64 == pytest.approx(threshold_for(rho, d))
    # 80 % targets then reach sqrt(0.8 / 4e-5) = 141.4 m, past the datasheet's 120 m
    rho80, d80 = HDL64E_DATASHEET["cars_and_foliage"]
    assert target_reach(rho80, 4e-5) == pytest.approx(math.sqrt(2e4), rel=1e-12)
    assert target_reach(rho80, 4e-5) > d80


def test_receiver_noise_is_set_by_the_false_alarm_probability():
    # Q^-1(1e-4) = 3.7190 (standard normal table)
    assert threshold_to_noise(1e-4) == pytest.approx(3.71902, abs=1e-5)
    assert FALSE_ALARM_PROBABILITY == 1e-4
    assert NOISE64 == pytest.approx(noise_for(T64), rel=1e-12)
    # noise alone crosses the threshold with P_FA = Q(T / sigma_n)
    assert norm.sf(T64 / NOISE64) == pytest.approx(1e-4, rel=1e-9)
    with pytest.raises(ValueError, match="false-alarm probability"):
        threshold_to_noise(0.6)


def test_datasheet_targets_are_detected_with_probability_at_least_one_half():
    """ "Detected to d" = P_D >= 0.5 at d: exactly 0.5 for 10 % at 50 m (E = T), above it for
    every nearer range, and 0.93 for 80 % at 120 m."""
    k = threshold_to_noise()
    for refl, spec in HDL64E_DATASHEET.values():
        p = detection_probability(refl / spec**2, T64, NOISE64)
        assert p == pytest.approx(norm.cdf(k * (refl / spec**2 / T64 - 1.0)), rel=1e-9)
        assert p >= 0.5 - 1e-12
        assert detection_probability(refl / (0.99 * spec) ** 2, T64, NOISE64) > 0.5
    assert detection_probability(0.10 / 50.0**2, T64, NOISE64) == pytest.approx(0.5, abs=1e-9)
    assert detection_probability(0.80 / 120.0**2, T64, NOISE64) == pytest.approx(
        norm.cdf(k * (0.8 / 0.1 * (50.0 / 120.0) ** 2 - 1.0)), rel=1e-9
    )
    assert 0.92 < detection_probability(0.80 / 120.0**2, T64, NOISE64) < 0.93
    # where the 10 % target fades: P_D = 0.9 at 50 / sqrt(1 + 1.2816 / k) m, 0.1 beyond 50 m
    d90 = 50.0 / math.sqrt(1.0 + norm.ppf(0.9) / k)
    assert detection_probability(0.10 / d90**2, T64, NOISE64) == pytest.approx(0.9, abs=1e-9)
    # arrays: Φ((E - T) / σ_n) element by element, and sigma_n = 0 is the old step
    e = np.array([0.5, 1.0, 1.5]) * T64
    np.testing.assert_allclose(
        detection_probability(e, T64, NOISE64), norm.cdf((e - T64) / NOISE64), rtol=1e-12
    )
    np.testing.assert_array_equal(detection_probability(e, T64, 0.0), [0.0, 1.0, 1.0])


def test_lambertian_ground_falls_as_h_over_d_cubed():
    for d in (5.0, 17.0, 40.0):
        assert ground_return(0.2, 0.0, 0.0, 1.73, d) == pytest.approx(0.2 * 1.73 / d**3)
    # the observation: Lambertian asphalt_old (rho 0.129) with 5e-5 ends at ~16 m
    assert ground_reach(0.129, 0.0, 0.0, 1.73, 5e-5) == pytest.approx(
        (0.129 * 1.73 / 5e-5) ** (1 / 3), rel=1e-3
    )


def test_catalog_road_roughness_reproduces_the_50_m_pavement_reach():
    from nidar_mi.materials import get_material, reflectance

    rho = float(reflectance("asphalt_old", np.array([905.0]))[0])
    m = get_material("asphalt_old")
    sigma = sigma_for_reach(rho, m.params["opposition_amplitude"], KITTI_SENSOR_HEIGHT_M, 50.0, T64)
    assert m.params["sigma"] == pytest.approx(sigma, abs=0.05)
    reach = ground_reach(rho, m.params["sigma"], m.params["opposition_amplitude"], 1.73, T64)
    assert reach == pytest.approx(50.0, abs=0.2)
    # with the receiver noise, the road is seen half the time at its reach, and fades from
    # 0.9 to 0.1 between ~43 and ~62 m (E ~ 1/d^2 at grazing incidence)
    args = (rho, m.params["sigma"], m.params["opposition_amplitude"], 1.73)
    assert ground_detection_probability(*args, reach, T64, NOISE64) == pytest.approx(0.5, abs=1e-3)
    assert ground_detection_probability(*args, 43.0, T64, NOISE64) == pytest.approx(0.9, abs=0.02)
    assert ground_detection_probability(*args, 62.0, T64, NOISE64) == pytest.approx(0.1, abs=0.02)
    with pytest.raises(ValueError, match="no roughness reaches 200 m"):
        sigma_for_reach(rho, 1.0, 1.73, 200.0, T64)


def test_scanned_target_reach_matches_the_datasheet(variant):
    """Without receiver noise the threshold is a step at E = T (P_D = 0.5 with noise)."""
    from nidar_mi.studies.ground_coverage import target_reach_scanned

    assert target_reach_scanned(0.10, T64) == pytest.approx(50.0, abs=0.1)
    assert target_reach_scanned(0.80, T64) == pytest.approx(141.4, abs=0.2)


def test_scanned_targets_are_detected_as_the_noise_model_says(variant):
    """The fraction of 4000 beams on a target at normal incidence, against P_D = Φ((E - T)/σ_n)."""
    from nidar_mi.studies.ground_coverage import target_detection_scanned

    n = 4000
    for refl, d in ((0.10, 40.0), (0.10, 45.0), (0.10, 50.0), (0.10, 56.0), (0.80, 120.0)):
        expect = detection_probability(refl / d**2, T64, NOISE64)
        got = target_detection_scanned(refl, d, T64, NOISE64, beams=n, seed=3)
        assert got == pytest.approx(expect, abs=_binomial_tol(expect, n)), (refl, d)
    # diverging beams: one receiver draw per echo, the same P_D (the footprint is on the panel)
    for d in (45.0, 50.0):
        expect = detection_probability(0.10 / d**2, T64, NOISE64)
        got = target_detection_scanned(0.10, d, T64, NOISE64, beams=n, beam_divergence=3.0)
        assert got == pytest.approx(expect, abs=_binomial_tol(expect, n)), d
    # the datasheet: detected (P >= 0.5) to 50 m and 120 m
    assert target_detection_scanned(0.10, 50.0, T64, NOISE64, beams=n) >= 0.5 - _binomial_tol(
        0.5, n
    )
    assert target_detection_scanned(0.80, 120.0, T64, NOISE64, beams=n) > 0.9


def test_scanned_flat_road_follows_the_closed_form_detection(variant):
    """Every ring of a level sweep over asphalt_old is reported with the closed-form P_D at its
    flat-ground range (uniform rings: the range is h / sin(-θ)); without receiver noise the
    Lambertian road is a step at the closed-form reach."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.materials import get_material, reflectance
    from nidar_mi.scene import load_scene_text
    from nidar_mi.studies.ground_coverage import (
        LAMBERTIAN_ASPHALT,
        ROUGH_ASPHALT,
        flat_road_scene_xml,
    )

    rho = float(reflectance("asphalt_old", np.array([905.0]))[0])
    p = get_material("asphalt_old").params
    args = (rho, p["sigma"], p["opposition_amplitude"], 1.73)
    cols = 2048
    loaded = load_scene_text(
        flat_road_scene_xml("hdl64e", ROUGH_ASPHALT, layout="uniform", cols=cols)
    )
    r = scan(loaded.scene, loaded.lidars[0], seed=5)
    el = np.radians(r.config.elevations)
    below = el < 0
    flat = 1.73 / np.sin(-el[below])
    got = r.valid[below].mean(axis=1)
    expect = np.array([ground_detection_probability(*args, d, T64, NOISE64) for d in flat])
    assert np.sum((expect > 0.05) & (expect < 0.95)) >= 2  # rings inside the fall-off
    for g, e, d in zip(got, expect, flat):
        assert g == pytest.approx(e, abs=_binomial_tol(e, cols)), d
    # the reported intensity is the receiver's output: at least the threshold
    assert r.intensity[r.valid].min() >= T64 * (1 - 1e-6)

    reach = ground_reach(rho, 0.0, 0.0, 1.73, 5e-5)
    loaded = load_scene_text(
        flat_road_scene_xml(
            "hdl64e", LAMBERTIAN_ASPHALT, layout="uniform", cols=64, threshold=5e-5, noise=0.0
        )
    )
    r = scan(loaded.scene, loaded.lidars[0])
    fraction = r.valid[below].mean(axis=1)
    near, far = flat < reach * 0.995, flat > reach * 1.005
    assert near.sum() > 10 and far.sum() > 0
    np.testing.assert_array_equal(fraction[near], 1.0)
    np.testing.assert_array_equal(fraction[far], 0.0)
    for k in np.flatnonzero(below)[near]:
        np.testing.assert_allclose(r.range[k][r.valid[k]], 1.73 / np.sin(-el[k]), rtol=1e-4)
