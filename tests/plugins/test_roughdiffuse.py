"""Tests of the ``roughdiffuse`` BSDF: Oren–Nayar in the paper's angular form, the opposition
surge, reciprocity, Lambert's limit, sampling, and the LiDAR return of a rough plane."""

import math

import numpy as np
import pytest

from nidar_mi.materials.oren_nayar import brdf, coefficients, oren_nayar_monostatic

RHO = 0.3


@pytest.fixture(scope="module")
def mi(variant):
    import mitsuba

    return mitsuba


def make(mi, sigma=30.0, amplitude=0.0, width=5.0, rho=RHO):
    return mi.load_dict(
        {
            "type": "roughdiffuse",
            "reflectance": {
                "type": "irregular",
                "wavelengths": "360, 1700",
                "values": f"{rho}, {rho}",
            },
            "sigma": sigma,
            "opposition_amplitude": amplitude,
            "opposition_width": width,
        }
    )


def direction(theta_deg, phi_deg=0.0):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def eval_f(mi, bsdf, wi, wo):
    """f(wi, wo) in 1/sr from Mitsuba's eval (which returns f · cos theta_o)."""
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.wi = mi.Vector3f(*map(float, wi))
    si.wavelengths = mi.UnpolarizedSpectrum(905.0)
    wo_mi = mi.Vector3f(*map(float, wo))
    return float(np.array(bsdf.eval(mi.BSDFContext(), si, wo_mi))[0, 0]) / wo[2]


def oren_nayar_paper(rho, sigma_deg, ti, pi_, to, po):
    """Oren & Nayar (SIGGRAPH 1994) eq. 30 written with the angles themselves."""
    s2 = math.radians(sigma_deg) ** 2
    a = 1 - 0.5 * s2 / (s2 + 0.33)
    b = 0.45 * s2 / (s2 + 0.09)
    alpha, beta = max(ti, to), min(ti, to)
    return rho / math.pi * (a + b * max(0.0, math.cos(pi_ - po)) * math.sin(alpha) * math.tan(beta))


def test_coefficients_hand_values():
    # sigma = 30 deg = 0.5236 rad: s2 = 0.27416; A = 1 - 0.13708/0.60416, B = 0.12337/0.36416
    a, b = coefficients(30.0)
    assert a == pytest.approx(0.773108, rel=1e-5) and b == pytest.approx(0.338785, rel=1e-5)
    assert coefficients(0.0) == (1.0, 0.0)


@pytest.mark.parametrize(
    "ti, pi_, to, po", [(10, 0, 50, 20), (60, 30, 20, 10), (80, 0, 80, 0), (45, 0, 45, 180)]
)
def test_eval_matches_the_paper_form(mi, ti, pi_, to, po):
    bsdf = make(mi, sigma=30.0)
    wi, wo = direction(ti, pi_), direction(to, po)
    want = oren_nayar_paper(RHO, 30.0, *map(math.radians, (ti, pi_, to, po)))
    assert eval_f(mi, bsdf, wi, wo) == pytest.approx(want, rel=2e-5)
    assert float(brdf(wi, wo, RHO, 30.0)) == pytest.approx(want, rel=1e-12)


def test_lambert_limit_reciprocity_and_surge(mi):
    flat = make(mi, sigma=0.0)
    assert eval_f(mi, flat, direction(70, 10), direction(20, 200)) == pytest.approx(
        RHO / math.pi, rel=1e-5
    )
    bsdf = make(mi, sigma=40.0, amplitude=0.8, width=5.0)
    a, b = direction(65, 15), direction(30, 40)
    assert eval_f(mi, bsdf, a, b) == pytest.approx(eval_f(mi, bsdf, b, a) * 1.0, rel=1e-5)
    # at phase angle 0 the surge multiplies by 1 + B0; at g = the half width by 1 + B0/2
    wi = direction(50)
    on = oren_nayar_paper(RHO, 40.0, *map(math.radians, (50, 0, 50, 0)))
    assert eval_f(mi, bsdf, wi, wi) == pytest.approx(on * 1.8, rel=1e-5)
    wo = direction(55)  # 5 degrees away in the plane of incidence
    on_g = oren_nayar_paper(RHO, 40.0, *map(math.radians, (50, 0, 55, 0)))
    assert eval_f(mi, bsdf, wi, wo) == pytest.approx(on_g * 1.4, rel=1e-4)


def test_monostatic_reflectance_closed_form(mi):
    bsdf = make(mi, sigma=45.0, amplitude=0.5)
    for theta in (0.0, 40.0, 85.0, 88.0):
        wi = direction(theta, 33.0)
        got = math.pi * eval_f(mi, bsdf, wi, wi)
        want = oren_nayar_monostatic(RHO, math.cos(math.radians(theta)), 45.0, 0.5)
        assert got == pytest.approx(float(want), rel=5e-5)
    # the received rho_eff cos(theta) tends to rho B (1 + B0) at grazing incidence
    _, b = coefficients(45.0)
    grazing = oren_nayar_monostatic(RHO, 1e-4, 45.0, 0.5) * 1e-4
    assert float(grazing) == pytest.approx(RHO * b * 1.5, rel=1e-3)


def test_sampling_weight_is_eval_over_pdf(mi):
    import drjit as dr

    bsdf = make(mi, sigma=35.0, amplitude=0.6)
    n = 4096
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*map(float, direction(60.0, 0.0)))
    si.wavelengths = mi.UnpolarizedSpectrum(905.0)
    rng = np.random.default_rng(0)
    u = rng.random((3, n))
    bs, weight = bsdf.sample(mi.BSDFContext(), si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    value, pdf = bsdf.eval_pdf(mi.BSDFContext(), si, bs.wo)
    w = np.array(weight)[0]
    np.testing.assert_allclose(w, np.array(value)[0] / np.array(pdf), rtol=1e-5)
    # the directional albedo (mean weight) of a rough surface stays below rho (1 + B0)
    assert 0.0 < w.mean() < RHO * 1.6


@pytest.mark.parametrize(
    "param, value, message",
    [
        ("sigma", "90", "'sigma' must be in [0, 90)"),
        ("sigma", "-1", "'sigma' must be in [0, 90)"),
        ("opposition_amplitude", "1.5", "'opposition_amplitude' must be in [0, 1]"),
        ("opposition_width", "0", "'opposition_width' must be in (0, 90]"),
    ],
)
def test_bad_parameters_fail_the_load_with_one_line(variant, write_scene, param, value, message):
    from nidar_mi.errors import NidarError
    from nidar_mi.scene import load_scene

    body = (
        '<sensor type="lidar" id="l"/><shape type="rectangle">'
        f'<bsdf type="roughdiffuse" id="road"><float name="{param}" value="{value}"/></bsdf></shape>'
    )
    with pytest.raises(NidarError) as err:
        load_scene(write_scene(body))
    text = str(err.value)
    assert f"roughdiffuse 'road': parameter {message}" in text and "\n" not in text


def test_lidar_return_of_a_rough_plane(variant, write_scene):
    """A flat roughdiffuse ground under a LiDAR at 2 m: I = rho (A cos θ + B sin² θ)(1 + B0) / d²
    with d = 2 / sin(-elevation) and cos θ = sin(-elevation)."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    elevations = [-2.0, -5.0, -15.0, -45.0]
    body = f"""
    <sensor type="lidar" id="l">
        <string name="elevation_angles" value="{", ".join(map(str, elevations))}"/>
        <integer name="horizontal_resolution" value="16"/><float name="range_max" value="200"/>
        <transform name="to_world"><translate z="2"/></transform>
    </sensor>
    <shape type="rectangle"><transform name="to_world"><scale value="1000"/></transform>
        <bsdf type="roughdiffuse"><spectrum name="reflectance" value="0.2"/>
        <float name="sigma" value="40"/><float name="opposition_amplitude" value="0.7"/></bsdf>
    </shape>"""
    loaded = load_scene(write_scene(body))
    r = scan(loaded.scene, loaded.lidars[0])
    a, b = coefficients(40.0)
    for ring, el in enumerate(sorted(elevations, reverse=True)):
        c = math.sin(math.radians(-el))
        d = 2.0 / c
        want = 0.2 * (a * c + b * (1 - c * c)) * 1.7 / d**2
        np.testing.assert_allclose(r.range[ring], d, rtol=1e-4)
        np.testing.assert_allclose(r.intensity[ring], want, rtol=2e-4)
