"""Tests of the ``retroreflector`` BSDF: lobe shape, energy conservation, sampling consistency."""

import math

import numpy as np
import pytest

from nidar_mi.materials.vmf import lobe_concentration, monostatic_gain

RHO = 0.8


@pytest.fixture(scope="module")
def mi(variant):
    import mitsuba

    return mitsuba


def make(mi, lobe_width=2.0, diffuse_fraction=0.0, rho=RHO):
    return mi.load_dict(
        {
            "type": "retroreflector",
            "reflectance": {
                "type": "irregular",
                "wavelengths": "360, 1700",
                "values": f"{rho}, {rho}",
            },
            "lobe_width": lobe_width,
            "diffuse_fraction": diffuse_fraction,
        }
    )


def direction(theta_deg, phi_deg=0.0):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return (math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


def interaction(mi, wi, n=1):
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*wi)
    si.wavelengths = mi.UnpolarizedSpectrum(905.0)
    return si


def eval_at(mi, bsdf, wi, wo):
    si = interaction(mi, wi)
    return float(np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*wo)))[0, 0])


def test_concentration_and_gain_hand_values():
    # kappa = ln 2 / (1 - cos 2 deg) = 0.693147 / 6.0917e-4
    assert lobe_concentration(2.0) == pytest.approx(1137.85, rel=1e-4)
    assert monostatic_gain(2.0) == pytest.approx(1137.85 / 2.0, rel=1e-4)
    assert monostatic_gain(2.0, 1.0) == pytest.approx(1.0)
    with pytest.raises(ValueError):
        lobe_concentration(0.0)


@pytest.mark.parametrize("theta", [0.0, 30.0, 60.0])
def test_monostatic_value_is_rho_times_the_documented_gain(mi, theta):
    bsdf = make(mi, diffuse_fraction=0.1)
    wi = direction(theta)
    rho_eff = math.pi * eval_at(mi, bsdf, wi, wi) / wi[2]
    assert rho_eff == pytest.approx(RHO * monostatic_gain(2.0, 0.1), rel=1e-4)


def test_lobe_falls_to_half_at_the_lobe_width(mi):
    bsdf = make(mi, lobe_width=2.0)
    wi = direction(20.0)
    peak = eval_at(mi, bsdf, wi, wi) / wi[2]
    kappa = lobe_concentration(2.0)
    for off, want in ((2.0, 0.5), (4.0, math.exp(kappa * (math.cos(math.radians(4.0)) - 1.0)))):
        wo = direction(20.0 + off)
        ratio = eval_at(mi, bsdf, wi, wo) / wo[2] / peak
        assert ratio == pytest.approx(want, rel=2e-3)
    # far off the incident direction only the (here absent) diffuse base remains
    assert eval_at(mi, bsdf, wi, direction(-20.0)) < 1e-12


def test_reciprocal(mi):
    bsdf = make(mi, lobe_width=5.0, diffuse_fraction=0.2)
    a, b = direction(30.0), direction(33.0, 10.0)
    assert eval_at(mi, bsdf, a, b) / b[2] == pytest.approx(eval_at(mi, bsdf, b, a) / a[2], rel=1e-4)


def _sample(mi, bsdf, wi, n=1 << 18, seed=0):
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, n)
    si = interaction(mi, wi, n)
    bs, weight = bsdf.sample(mi.BSDFContext(), si, sampler.next_1d(), sampler.next_2d())
    return si, bs, np.array(weight)[0]


def test_albedo_at_normal_incidence_matches_the_vmf_mean_cosine(mi):
    bsdf = make(mi, lobe_width=2.0)
    _, _, w = _sample(mi, bsdf, (0.0, 0.0, 1.0))
    kappa = lobe_concentration(2.0)
    want = RHO * (1.0 / math.tanh(kappa) - 1.0 / kappa)
    assert w.mean() == pytest.approx(want, abs=1e-4)
    assert w.mean() <= RHO


@pytest.mark.parametrize(
    "lobe_width, d, theta", [(2.0, 0.0, 60.0), (30.0, 0.0, 45.0), (10.0, 0.5, 80.0)]
)
def test_no_energy_gain(mi, lobe_width, d, theta):
    bsdf = make(mi, lobe_width=lobe_width, diffuse_fraction=d)
    _, _, w = _sample(mi, bsdf, direction(theta))
    assert w.mean() <= RHO + 3.0 * w.std() / math.sqrt(w.size)


def test_albedo_by_uniform_sampling_agrees_with_importance_sampling(mi):
    """Independent of sample(): integrate eval over the hemisphere with uniform directions."""
    import drjit as dr

    bsdf = make(mi, lobe_width=30.0, diffuse_fraction=0.2)
    wi = direction(40.0)
    n = 1 << 18
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(3, n)
    wo = mi.warp.square_to_uniform_hemisphere(sampler.next_2d())
    si = interaction(mi, wi, n)
    f = np.array(bsdf.eval(mi.BSDFContext(), si, wo))[0]
    uniform = f.mean() * 2.0 * math.pi
    _, _, w = _sample(mi, bsdf, wi, seed=4)
    assert uniform == pytest.approx(w.mean(), rel=0.01)
    assert dr.width(wo) == n


def test_sample_is_consistent_with_eval_and_pdf(mi):
    bsdf = make(mi, lobe_width=3.0, diffuse_fraction=0.25)
    si, bs, w = _sample(mi, bsdf, direction(35.0), n=4096)
    ctx = mi.BSDFContext()
    value, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
    value, pdf = np.array(value)[0], np.array(pdf)
    np.testing.assert_allclose(np.array(bs.pdf), pdf, rtol=1e-5)
    np.testing.assert_allclose(np.array(bsdf.pdf(ctx, si, bs.wo)), pdf, rtol=1e-6)
    ok = pdf > 0
    np.testing.assert_allclose(w[ok], value[ok] / pdf[ok], rtol=1e-4)


def test_half_the_lobe_samples_fall_within_the_lobe_width(mi):
    bsdf = make(mi, lobe_width=2.0)
    wi = (0.0, 0.0, 1.0)
    _, bs, _ = _sample(mi, bsdf, wi)
    cos_angle = np.array(bs.wo)[2]
    frac = np.mean(cos_angle >= math.cos(math.radians(2.0)))
    assert frac == pytest.approx(0.5, abs=0.005)


def test_pure_diffuse_fraction_is_lambertian(mi):
    bsdf = make(mi, diffuse_fraction=1.0)
    wi, wo = direction(10.0), direction(50.0, 90.0)
    assert eval_at(mi, bsdf, wi, wo) == pytest.approx(RHO / math.pi * wo[2], rel=1e-5)
    _, _, w = _sample(mi, bsdf, wi, n=1024)
    np.testing.assert_allclose(w, RHO, rtol=1e-5)


def test_below_the_surface_returns_nothing(mi):
    bsdf = make(mi, diffuse_fraction=0.3)
    below = (0.0, 0.3, -0.9539392)
    assert eval_at(mi, bsdf, below, below) == 0.0
    _, _, w = _sample(mi, bsdf, below, n=256)
    assert np.all(w == 0.0)


@pytest.mark.parametrize(
    "props, match",
    [
        ({"lobe_width": 0.0}, "parameter 'lobe_width' must be in"),
        ({"lobe_width": 95.0}, "parameter 'lobe_width' must be in"),
        ({"diffuse_fraction": 1.5}, "parameter 'diffuse_fraction' must be in"),
        ({"diffuse_fraction": -0.1}, "parameter 'diffuse_fraction' must be in"),
        ({"lobe_widht": 2.0}, "unreferenced property"),
    ],
)
def test_bad_parameters_are_rejected(mi, props, match):
    with pytest.raises(RuntimeError, match=match):
        mi.load_dict({"type": "retroreflector", **props})


@pytest.mark.parametrize(
    "prop, message",
    [
        (
            '<float name="lobe_width" value="0"/>',
            "retroreflector 'sheet': parameter 'lobe_width' must be in (0, 90] degrees (got 0)",
        ),
        (
            '<float name="diffuse_fraction" value="2"/>',
            "retroreflector 'sheet': parameter 'diffuse_fraction' must be in [0, 1] (got 2)",
        ),
        (
            '<string name="lobe_width" value="wide"/>',
            "retroreflector 'sheet': parameter 'lobe_width' must be a number (got 'wide')",
        ),
    ],
)
def test_invalid_parameter_in_a_scene_gives_one_line(variant, write_scene, prop, message):
    from nidar_mi.errors import NidarError
    from nidar_mi.scene import load_scene

    path = write_scene(
        f'<bsdf type="retroreflector" id="sheet">{prop}</bsdf>'
        '<shape type="rectangle"><ref id="sheet"/></shape>'
    )
    with pytest.raises(NidarError) as e:
        load_scene(path)
    assert str(e.value) == f"{path}: {message}"
