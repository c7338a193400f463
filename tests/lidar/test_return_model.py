"""The return model's pure functions: values, NumPy/Dr.Jit agreement, compensate as the inverse."""

import numpy as np
import pytest

from nidar_mi.lidar import return_model as rm

D = np.array([0.5, 2.0, 10.0, 45.0])
COS = np.array([1.0, 0.8, 0.3, 0.05])


def test_attenuation_closed_form():
    alpha = 0.02
    np.testing.assert_allclose(
        rm.attenuation(D, COS, alpha, "compensated"), COS * np.exp(-2 * alpha * D), rtol=1e-15
    )
    np.testing.assert_allclose(
        rm.attenuation(D, COS, alpha, "raw"), COS * np.exp(-2 * alpha * D) / D**2, rtol=1e-15
    )


def test_expected_intensity_scales_with_gain_rho_and_transmittance():
    base = rm.expected_intensity(1.0, 1.0, D, COS, 0.0)
    np.testing.assert_allclose(
        rm.expected_intensity(2.5, 0.4, D, COS, 0.0, two_way_transmittance=0.81),
        2.5 * 0.4 * 0.81 * base,
        rtol=1e-15,
    )


def test_unknown_mode_is_rejected():
    with pytest.raises(ValueError, match="unknown intensity mode 'linear'"):
        rm.attenuation(D, COS, 0.0, "linear")
    with pytest.raises(ValueError, match="unknown intensity mode 'linear'"):
        rm.compensate(D, D, "linear")


@pytest.mark.parametrize("mode", ["raw", "compensated"])
def test_compensate_inverts_the_raw_range_loss(mode):
    gain, rho, alpha = 1.7, np.array([0.1, 0.5, 0.9, 0.3]), 0.01
    reported = rm.expected_intensity(gain, rho, D, COS, alpha, mode).astype(np.float32)
    comp = rm.compensate(reported, D.astype(np.float32), mode)
    assert comp.dtype == np.float32
    np.testing.assert_allclose(
        comp, rm.expected_intensity(gain, rho, D, COS, alpha, "compensated"), rtol=1e-6
    )


def test_detect_every_condition():
    expected = np.array([1.0, 1.0, 1.0, 0.0, np.nan, 0.5, 1.0, 1.0])
    d = np.array([5.0, 0.1, 200.0, 5.0, 5.0, 5.0, 5.0, 5.0])
    hit = np.array([True, True, True, True, True, True, False, True])
    u = np.array([0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.05])
    got = rm.detect(
        expected, d, hit=hit, threshold=0.6, range_min=0.5, range_max=100.0, dropout=0.1, u=u
    )
    # ok, too near, too far, no energy, not finite, below threshold, no hit, dropped
    np.testing.assert_array_equal(got, [True, False, False, False, False, False, False, False])
    # a zero-energy return is never reported, even with a zero threshold
    assert not rm.detect(np.array([0.0]), np.array([5.0]))[0]


def test_add_noise_clips_at_zero():
    np.testing.assert_array_equal(
        rm.add_noise(np.array([1.0, 0.1]), 0.5, np.array([1.0, -1.0])), [1.5, 0.0]
    )


def test_box_muller_is_standard_normal():
    rng = np.random.default_rng(0)
    g = rm.box_muller(rng.random(200_000), rng.random(200_000))
    assert abs(g.mean()) < 0.01 and abs(g.std() - 1.0) < 0.01


def test_numpy_and_drjit_agree(variant):
    import drjit as dr
    import mitsuba as mi

    gain, alpha = 2.0, 0.03
    rho = np.array([0.2, 0.5, 0.9, 0.4])
    T2 = np.array([1.0, 0.9, 0.5, 1.0])
    u = np.array([0.9, 0.2, 0.6, 0.01])
    F = mi.Float
    for mode in ("raw", "compensated"):
        ref = rm.expected_intensity(gain, rho, D, COS, alpha, mode, T2)
        got = rm.expected_intensity(gain, F(rho), F(D), F(COS), dr.opaque(F, alpha), mode, F(T2))
        np.testing.assert_allclose(got.numpy(), ref, rtol=1e-5)
        kw = dict(threshold=1e-3, range_min=1.0, range_max=40.0, dropout=0.05)
        np.testing.assert_array_equal(
            rm.detect(got, F(D), hit=mi.Bool([True] * 4), u=F(u), **kw).numpy(),
            rm.detect(ref, D, hit=np.ones(4, bool), u=u, **kw),
        )
        np.testing.assert_allclose(
            rm.compensate(got, F(D), mode).numpy(), rm.compensate(ref, D, mode), rtol=1e-5
        )
    np.testing.assert_allclose(
        rm.box_muller(F(u), F(u[::-1])).numpy(), rm.box_muller(u, u[::-1]), rtol=1e-5
    )
    np.testing.assert_allclose(
        rm.add_noise(F(D), 0.5, F(COS - 0.5)).numpy(), rm.add_noise(D, 0.5, COS - 0.5)
    )
