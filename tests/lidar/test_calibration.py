"""The detection calibration: closed forms, the catalog's road roughness, and scans against them."""

import math

import numpy as np
import pytest

from nidar_mi.lidar.calibration import (
    HDL64E_DATASHEET,
    KITTI_SENSOR_HEIGHT_M,
    ground_reach,
    ground_return,
    sigma_for_reach,
    target_reach,
    threshold_for,
)
from nidar_mi.lidar.pattern import PRESETS


def test_threshold_is_the_datasheets_pavement_figure():
    rho, d = HDL64E_DATASHEET["pavement"]
    assert threshold_for(rho, d) == pytest.approx(4e-5, rel=1e-12)
    assert PRESETS["hdl64e"].detection_threshold == pytest.approx(threshold_for(rho, d))
    # 80 % targets then reach sqrt(0.8 / 4e-5) = 141.4 m, past the datasheet's 120 m
    rho80, d80 = HDL64E_DATASHEET["cars_and_foliage"]
    assert target_reach(rho80, 4e-5) == pytest.approx(math.sqrt(2e4), rel=1e-12)
    assert target_reach(rho80, 4e-5) > d80


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
    T = PRESETS["hdl64e"].detection_threshold
    sigma = sigma_for_reach(rho, m.params["opposition_amplitude"], KITTI_SENSOR_HEIGHT_M, 50.0, T)
    assert m.params["sigma"] == pytest.approx(sigma, abs=0.05)
    reach = ground_reach(rho, m.params["sigma"], m.params["opposition_amplitude"], 1.73, T)
    assert reach == pytest.approx(50.0, abs=0.2)
    with pytest.raises(ValueError, match="no roughness reaches 200 m"):
        sigma_for_reach(rho, 1.0, 1.73, 200.0, T)


def test_scanned_target_reach_matches_the_datasheet(variant):
    from nidar_mi.studies.ground_coverage import target_reach_scanned

    T = PRESETS["hdl64e"].detection_threshold
    assert target_reach_scanned(0.10, T) == pytest.approx(50.0, abs=0.1)
    assert target_reach_scanned(0.80, T) == pytest.approx(141.4, abs=0.2)


def test_scanned_flat_road_ends_at_the_closed_form_reach(variant):
    """Every ring meeting asphalt_old closer than the closed-form reach is reported in full,
    every ring beyond it not at all (no noise or dropout on the flat road)."""
    from nidar_mi.materials import get_material, reflectance
    from nidar_mi.studies.ground_coverage import (
        LAMBERTIAN_ASPHALT,
        ROUGH_ASPHALT,
        simulate_flat_road,
    )

    rho = float(reflectance("asphalt_old", np.array([905.0]))[0])
    p = get_material("asphalt_old").params
    for material, threshold, reach in (
        (ROUGH_ASPHALT, None, ground_reach(rho, p["sigma"], p["opposition_amplitude"], 1.73, 4e-5)),
        (LAMBERTIAN_ASPHALT, 5e-5, ground_reach(rho, 0.0, 0.0, 1.73, 5e-5)),
    ):
        cov = simulate_flat_road("hdl64e", material, cols=64, threshold=threshold)
        below = np.isfinite(cov.flat_range_m)
        near = below & (cov.flat_range_m < reach * 0.995)
        far = below & (cov.flat_range_m > reach * 1.005)
        assert near.sum() > 10 and far.sum() > 0
        np.testing.assert_array_equal(cov.p_detect[near], 1.0)
        np.testing.assert_array_equal(cov.p_detect[far], 0.0)
        for k in np.flatnonzero(near):
            np.testing.assert_allclose(cov.ranges[k], cov.flat_range_m[k], rtol=1e-4)
