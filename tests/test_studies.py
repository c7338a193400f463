"""Controlled LiDAR experiments: panel scenes scanned through the real lidar plugin."""

import math

import numpy as np
import pytest

from nidar_mi.errors import NidarError


def _lambert_w(x: float) -> float:
    """Principal branch of Lambert's W for x >= 0 by Newton's method (w·e^w = x)."""
    w = math.log1p(x)
    for _ in range(100):
        step = (w * math.exp(w) - x) / (math.exp(w) * (w + 1.0))
        w -= step
        if abs(step) < 1e-15 * max(1.0, abs(w)):
            break
    return w


def _closed_form_range(g_rho: float, threshold: float, alpha: float) -> float:
    """Root of g·ρ·exp(-2αd)/d² = T: d·exp(αd) = K with K = sqrt(gρ/T), so d = W(αK)/α."""
    k = math.sqrt(g_rho / threshold)
    return k if alpha == 0.0 else _lambert_w(alpha * k) / alpha


# ---------------------------------------------------------------- layout and XML (no Mitsuba)


def test_layout_puts_each_panel_on_a_column_centre():
    from nidar_mi.studies import panel_layout

    lay = panel_layout(10.0, [0.0, 30.0, 60.0, 85.0], cols=360)
    np.testing.assert_array_equal(lay.columns, [0, 90, 180, 270])
    np.testing.assert_allclose(lay.azimuths_deg, [0.5, 90.5, 180.5, 270.5])
    np.testing.assert_allclose(lay.distances_m, 10.0)
    # a partial spread is centred on +x (azimuth 0 = column 0 = 360)
    part = panel_layout(10.0, [0.0, 0.0, 0.0], cols=360, spread_deg=60.0)
    np.testing.assert_array_equal(part.columns, [340, 0, 20])


@pytest.mark.parametrize(
    "kwargs",
    [
        {"distance_m": 0.5},  # inside the panel
        {"incidence_deg": 90.0},
        {"incidence_deg": -1.0},
        {"distance_m": [2.0] * 12},  # 1 m panels at 2 m shadow each other 30 deg apart
        {"distance_m": [10.0] * 3, "cols": 4},
        {"spread_deg": 0.0},
        {"distance_m": [], "incidence_deg": []},
    ],
)
def test_layout_rejects_bad_values(kwargs):
    from nidar_mi.studies import panel_layout

    with pytest.raises(NidarError):
        panel_layout(**kwargs)


def test_scene_xml_checks_the_material_count():
    from nidar_mi.studies import panel_scene_xml

    with pytest.raises(NidarError, match="different panel counts"):
        panel_scene_xml(["grass", "concrete"], incidence_deg=[0.0, 10.0, 20.0])


def test_scene_xml_names_an_unknown_material():
    from nidar_mi.studies import panel_scene_xml

    with pytest.raises(NidarError, match="unknown material 'gras'.*grass"):
        panel_scene_xml("gras")
    with pytest.raises(NidarError, match="unknown material"):
        panel_scene_xml("grass", backdrop="no_such_wall")
    with pytest.raises(NidarError, match="intensity_mode"):
        panel_scene_xml("grass", intensity_mode="linear")


def test_extinction_from_visibility_hand_values():
    from nidar_mi.studies import extinction_from_visibility

    # 3.91/V·(λ/550)^-q per km; q = 1.3 for 6 < V <= 50 km, 0.16V + 0.34 for 1 < V <= 6 km
    assert extinction_from_visibility(23.0, 550.0) == pytest.approx(3.91 / 23.0e3, rel=1e-12)
    assert extinction_from_visibility(23.0, 1550.0) == pytest.approx(4.42068e-5, rel=1e-5)
    assert extinction_from_visibility(3.0, 905.0) == pytest.approx(8.66365e-4, rel=1e-5)
    # dense fog (V <= 0.5 km): q = 0, no wavelength dependence
    assert extinction_from_visibility(0.4, 905.0) == pytest.approx(9.775e-3, rel=1e-12)
    assert extinction_from_visibility(0.4, 1550.0) == pytest.approx(9.775e-3, rel=1e-12)
    with pytest.raises(NidarError):
        extinction_from_visibility(0.0, 905.0)


@pytest.mark.parametrize("alpha", [0.0, 1e-3, 2e-2])
def test_detection_range_matches_the_closed_form(alpha):
    from nidar_mi.studies import detection_range

    d = detection_range(0.5, 1e-5, gain=2.0, alpha_per_m=alpha, cos_incidence=0.8)
    ref = _closed_form_range(2.0 * 0.5 * 0.8, 1e-5, alpha)
    assert d == pytest.approx(ref, rel=1e-9)
    # the return model evaluated there sits on the threshold
    assert 0.8 * math.exp(-2 * alpha * d) / d**2 == pytest.approx(1e-5, rel=1e-8)


def test_detection_range_rejects_bad_values():
    from nidar_mi.studies import detection_range

    for kwargs in ({"rho": 0.0}, {"threshold": 0.0}, {"alpha_per_m": -1.0}):
        args = {"rho": 0.5, "threshold": 1e-4, **kwargs}
        with pytest.raises(NidarError):
            detection_range(args.pop("rho"), args.pop("threshold"), **args)


# ---------------------------------------------------------------- through the LiDAR


@pytest.mark.parametrize("wavelength", [905.0, 1550.0])
def test_lambertian_incidence_sweep_follows_the_cosine_law(variant, wavelength):
    from nidar_mi.studies import incidence_sweep

    angles = np.arange(0.0, 86.0, 5.0)
    s = incidence_sweep("white_panel_95", angles, wavelength, variant=variant)
    cos = np.cos(np.radians(angles))
    np.testing.assert_allclose(s.angles_deg, angles)
    np.testing.assert_allclose(s.cos_incidence, cos, rtol=1e-3)
    np.testing.assert_allclose(s.intensity / s.intensity[0], cos, rtol=1e-3)
    # compensated mode, gain 1: I = ρ·cosθ with the panel's albedo
    np.testing.assert_allclose(s.intensity, 0.95 * cos, rtol=1e-3)
    np.testing.assert_allclose(s.reflectance, 0.95, rtol=1e-4)


def test_range_sweep_follows_inverse_square_and_extinction(variant):
    from nidar_mi.studies import range_sweep

    d = np.array([3.0, 5.0, 8.0, 13.0, 21.0, 34.0, 55.0, 89.0, 144.0])
    alpha = 2e-3
    r = range_sweep("grey_panel_50", d, alpha, 905.0, variant=variant)
    assert r.valid.all()
    np.testing.assert_allclose(r.intensity, 0.5 * np.exp(-2 * alpha * d) / d**2, rtol=1e-4)
    np.testing.assert_allclose(r.range_m, d, rtol=1e-4)


def test_max_detection_range_of_a_white_panel(variant):
    from nidar_mi.studies import max_detection_range, range_sweep

    threshold, alpha = 1e-5, 1e-3
    d_max = max_detection_range(
        "white_panel_95", threshold, wavelength_nm=905.0, alpha_per_m=alpha, variant=variant
    )
    assert d_max == pytest.approx(_closed_form_range(0.95, threshold, alpha), rel=1e-3)
    # the scan agrees: a panel just inside is reported, one just beyond is dropped
    r = range_sweep(
        "white_panel_95",
        [0.99 * d_max, 1.01 * d_max],
        alpha,
        905.0,
        detection_threshold=threshold,
        variant=variant,
    )
    np.testing.assert_array_equal(r.valid, [True, False])


def test_max_detection_range_without_extinction_and_off_normal(variant):
    from nidar_mi.studies import max_detection_range

    d = max_detection_range("grey_panel_50", 1e-4, incidence_deg=60.0, gain=3.0, variant=variant)
    assert d == pytest.approx(math.sqrt(3.0 * 0.5 * 0.5 / 1e-4), rel=1e-3)


def test_retroreflective_sheeting_stays_far_above_lambertian(variant):
    from nidar_mi.materials import reflectance
    from nidar_mi.materials.vmf import monostatic_gain
    from nidar_mi.studies import incidence_sweep

    angles = np.arange(0.0, 81.0, 10.0)
    retro = incidence_sweep("retro_sheeting_white", angles, 905.0, variant=variant)
    white = incidence_sweep("white_panel_95", angles, 905.0, variant=variant)
    assert np.all(retro.intensity > 100.0 * white.intensity)
    # the library sheeting: lobe half width 2 deg, 5 % Lambertian base (docs/MATERIALS.md)
    rho_eff = float(reflectance("retro_sheeting_white", 905.0)) * monostatic_gain(2.0, 0.05)
    np.testing.assert_allclose(retro.reflectance, rho_eff, rtol=1e-3)


def test_glossy_paint_departs_from_the_cosine_law(variant):
    from nidar_mi.materials import reflectance
    from nidar_mi.studies import incidence_sweep

    s = incidence_sweep("car_paint_red", [0.0, 40.0], 905.0, variant=variant)
    pigment = float(reflectance("car_paint_red", 905.0))
    # the clear coat's specular peak lifts normal incidence above the pigment's albedo ...
    assert s.reflectance[0] > 1.5 * pigment
    # ... and off the peak the Fresnel-transmitted diffuse layer reads below it
    assert s.reflectance[1] < pigment


def test_blue_glass_passes_the_beam_to_the_backdrop(variant):
    from nidar_mi.materials import get_material
    from nidar_mi.studies import scan_panels

    s = scan_panels(
        ["glass_blue", "grey_panel_50"],
        distance_m=6.0,
        wavelength_nm=905.0,
        intensity_mode="compensated",
        backdrop="white_panel_95",
        variant=variant,
    )
    assert s.material == ["backdrop_white_panel_95", "grey_panel_50"]
    np.testing.assert_allclose(s.range_m, [9.0, 6.0], rtol=1e-4)
    # thin pane at normal incidence: T = t·(1 - R)/(1 + R), R = ((n - 1)/(n + 1))², two passes
    m = get_material("glass_blue")
    n, t = m.params["int_ior"], float(m.params["transmittance"](905.0))
    R = ((n - 1) / (n + 1)) ** 2
    np.testing.assert_allclose(s.intensity[0], 0.95 * (t * (1 - R) / (1 + R)) ** 2, rtol=1e-3)
