"""The LiDAR in weather against closed forms: the hard target's two-way transmission, the soft
return's integral far from the sensor, a particle's share of a Gaussian beam, the number of
drops on an ideal beam's line; and whole scans (fog near the sensor, drops, determinism, clear
weather unchanged, no NaN at any rate)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nidar_mi.lidar.weather_returns import (
    ReceiverOptics,
    SensorTerms,
    candidates,
    device_tables,
    intercepted_fraction,
    soft_return_table,
    soft_waveform,
    weather_model,
)
from nidar_mi.weather import Weather
from nidar_mi.weather.media import medium_optics
from nidar_mi.weather.particles import marshall_palmer

SHORT = ReceiverOptics(pulse_width=10e-9, overlap_start=0.5, overlap_full=0.5)


# ------------------------------------------------------------------ closed forms


@pytest.mark.parametrize("alpha", [0.0, 0.01])
def test_soft_return_far_from_the_sensor(alpha):
    """Far beyond the pulse length L the 1/r² factor is flat over the pulse:
    E_s(R) = π β exp(-2αR) ∫ cos²(πx/L) dx / R² = π β exp(-2αR) L / (2 R²)."""
    beta, R, L = 2e-3, 60.0, SHORT.pulse_length
    e = soft_waveform(np.array([R]), alpha, beta, SHORT)[0]
    closed = math.pi * beta * math.exp(-2 * alpha * R) * L / (2 * R * R)
    assert e == pytest.approx(closed, rel=5e-3)
    # the medium behind a hard target at R does not return: half the pulse is left (to first
    # order in L/R, the nearer half weighs 1 + 2<x>/R more)
    half = soft_waveform(np.array([R]), alpha, beta, SHORT, limit=R)[0]
    assert half / e == pytest.approx(0.5, rel=0.03)


def test_soft_return_table_holds_the_waveform_peaks():
    """The per-scan table against the waveform formed directly; a target just past the overlap
    leaves few 2-cm cells of fog, so there a cell's worth (5 %) is allowed."""
    o = medium_optics(Weather(fog=60.0), 905.0)
    optics = ReceiverOptics()
    table = soft_return_table(o.alpha, o.backscatter, optics, 120.0)
    r = np.arange(0.0, 30.0, 0.01)
    for limit in (2.5, 4.0, 6.0, 50.0):
        w = soft_waveform(r, o.alpha, o.backscatter, optics, limit=limit)
        value = np.interp(limit, table.limits, table.peak_value)
        where = np.interp(limit, table.limits, table.peak_range)
        assert value == pytest.approx(w.max(), rel=0.05 if limit < 5 else 0.005)
        assert where == pytest.approx(r[np.argmax(w)], abs=0.05)
    assert table.peak_value[0] == 0.0  # a target before the overlap hides all the fog


def test_intercepted_fraction_against_quadrature():
    """A disk of radius a at offset ρ in a Gaussian beam exp(-2 r²/w²) (normalised over the
    plane): the closed form is exact on the axis and for small disks anywhere."""
    w = 1.0
    for a, rho in ((0.02, 0.0), (0.02, 0.7), (0.05, 1.2), (0.6, 0.0), (2.0, 0.0)):
        xs = np.linspace(rho - a, rho + a, 801)
        ys = np.linspace(-a, a, 801)
        X, Y = np.meshgrid(xs, ys)
        inside = (X - rho) ** 2 + Y**2 <= a * a
        g = np.where(inside, np.exp(-2 * (X * X + Y * Y) / w**2), 0.0) * 2 / (np.pi * w**2)
        exact = np.trapezoid(np.trapezoid(g, xs, axis=1), ys)
        assert intercepted_fraction(a, rho, w) == pytest.approx(exact, rel=0.02, abs=1e-6)
    assert intercepted_fraction(0.3, 0.1, 0.0) == 1.0  # an ideal beam: the line is covered


def test_drops_on_an_ideal_beam():
    """A line through rain of length R meets N σ R drops: for Marshall-Palmer
    ∫ π D²/4 N0 e^{-ΛD} dD = π N0 / (2 Λ³); every drop on the line takes the whole beam, so a
    beam whose target is at d meets one with probability 1 - exp(-N σ d)."""
    rate, R = 20.0, 100.0
    cfg = SensorTerms(905.0, 1.0, "raw", 0.0, 0.0, 0.0, R)  # no threshold: every drop counts
    model = weather_model(Weather(rain=rate), cfg)
    rain = marshall_palmer(rate)
    sigma_n = math.pi * rain.n0 / (2 * rain.slope**3)
    assert model.particles.mean_count == pytest.approx(sigma_n * R, rel=0.03)
    rng = np.random.default_rng(5)
    n, d = 200_000, 40.0
    c = candidates(model, np.full(n, d), device_tables(model, np), lambda: rng.random(n))
    met = c.occlusion < 1.0
    expected = 1 - math.exp(-sigma_n * d)
    assert met.mean() == pytest.approx(expected, abs=4 * math.sqrt(expected / n))
    np.testing.assert_array_equal(c.occlusion[met], 0.0)  # fully covered: nothing behind
    # a drop returns unless it sits before the receiver sees the beam (overlap_start)
    seen = np.stack(c.energy[1:]).max(axis=0) > 0
    assert not (seen & ~met).any()
    share = (d - model.receiver.overlap_start) / d
    assert seen.sum() / met.sum() == pytest.approx(share, abs=0.02)


# ------------------------------------------------------------------ scans


def _wall_scene(write_scene, extra="", wavelength=905.0, divergence=0.0):
    """A ρ = 0.5 wall 10 m ahead (x = 10, ±3 m), sky elsewhere; one ring of 360 beams."""
    return write_scene(f"""
    <sensor type="lidar" id="lidar">
        <string name="elevation_angles" value="0, 10, 45"/>
        <integer name="horizontal_resolution" value="360"/>
        <float name="wavelength" value="{wavelength}"/>
        <float name="range_min" value="0.1"/>
        <float name="range_max" value="80"/>
        <float name="beam_divergence" value="{divergence}"/>
        {extra}
    </sensor>
    <bsdf type="diffuse" id="white"><spectrum name="reflectance" value="360:0.5, 1700:0.5"/></bsdf>
    <shape type="rectangle" id="wall"><transform name="to_world"><scale value="3"/>
        <rotate y="1" angle="-90"/><translate x="10"/></transform><ref id="white"/></shape>
    """)


def _scan(path, weather=None, seed=None):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    loaded = load_scene(path)
    return scan(loaded.scene, loaded.lidars[0], weather=weather, seed=seed)


@pytest.mark.parametrize("wavelength", [905.0, 1550.0])
def test_hard_return_follows_the_two_way_transmission(variant, write_scene, wavelength):
    """In fog the wall returns exp(-2 α d) of its clear return, α the fog's at the sensor's
    wavelength (fog light enough that the wall outshines the fog)."""
    path = _wall_scene(write_scene, wavelength=wavelength)
    clear = _scan(path)
    fog = Weather(fog=2000.0)
    foggy = _scan(path, fog)
    wall = clear.valid & (clear.shape_index >= 0)
    assert wall.sum() > 50
    alpha = medium_optics(fog, wavelength).alpha
    ratio = foggy.intensity[wall] / clear.intensity[wall]
    np.testing.assert_allclose(ratio, np.exp(-2 * alpha * clear.range[wall]), rtol=1e-5)
    np.testing.assert_array_equal(foggy.scatterer[wall], 0)  # surface
    np.testing.assert_array_equal(foggy.range[wall], clear.range[wall])  # no receiver noise


def test_dense_fog_returns_from_the_fog_near_the_sensor(variant, write_scene):
    """MOR 30 m: the beams that see the sky return the fog itself, at the soft return's peak,
    with its intensity; the wall is still seen through it (strongest of the two)."""
    path = _wall_scene(write_scene)
    fog = Weather(fog=30.0)
    r = _scan(path, fog)
    model = weather_model(fog, r.config)
    sky = r.shape_index < 0
    assert np.all(r.valid[sky]) and np.all(r.scatterer[sky] == 1)
    np.testing.assert_allclose(r.range[sky], model.soft.peak_range[-1], rtol=1e-5)
    np.testing.assert_allclose(r.intensity[sky], model.soft.peak_value[-1], rtol=1e-4)
    pts = r.points()
    assert list(pts["scatterer_names"]) == ["surface", "fog", "drop", "flake"]
    assert set(np.unique(pts["scatterer"])) == {0, 1}


def test_rain_drops_in_the_beam_are_deterministic(variant, write_scene):
    extra = '<float name="detection_threshold" value="1e-4"/>'
    extra += '<float name="receiver_noise_std" value="2e-5"/>'
    path = _wall_scene(write_scene, extra)
    rain = Weather(rain=100.0)
    a, b, c = _scan(path, rain, seed=1), _scan(path, rain, seed=1), _scan(path, rain, seed=2)
    pa = a.points()
    drops = pa["scatterer"] == 2
    assert drops.any() and (~drops).any()
    model = weather_model(rain, a.config)
    assert pa["range"][drops].max() <= model.particles.reach.max() + 1.0
    for key in ("range", "intensity", "scatterer", "xyz"):
        np.testing.assert_array_equal(pa[key], b.points()[key])
    assert not np.array_equal(a.valid, c.valid) or not np.array_equal(a.range, c.range)


def test_clear_weather_is_the_scan_without_weather(variant, write_scene):
    path = _wall_scene(write_scene, '<float name="noise_range_std" value="0.02"/>')
    plain, clear = _scan(path), _scan(path, Weather())
    assert plain.scatterer is None and clear.scatterer is None
    p, q = plain.points(), clear.points()
    assert set(p) == set(q) and "scatterer" not in p
    for key in p:
        np.testing.assert_array_equal(p[key], q[key])


def test_weather_in_the_sensor_xml(variant, write_scene):
    from nidar_mi.errors import NidarError
    from nidar_mi.scene import load_scene

    r = _scan(_wall_scene(write_scene, '<float name="fog" value="30"/>'))
    assert r.weather == Weather(fog=30.0) and (r.scatterer == 1).any()
    bad = _wall_scene(write_scene, '<float name="rain" value="-3"/>', divergence=0.0)
    with pytest.raises(NidarError, match="lidar 'lidar': parameter 'rain' must be a rate"):
        load_scene(bad)


@pytest.mark.parametrize(
    ("weather", "divergence"),
    [
        (Weather(fog=5.0), 0.0),
        (Weather(rain=300.0), 0.0),
        (Weather(snow=50.0, fog=5.0), 0.0),
        (Weather(rain=300.0, fog=5.0), 3.0),
        (Weather(snow=50.0), 3.0),
    ],
)
def test_no_nan_at_the_extremes(variant, write_scene, weather, divergence):
    extra = '<float name="receiver_noise_std" value="1e-5"/>'
    mode = "dual" if divergence > 0 else "strongest"  # dual needs a beam of some width
    extra += (
        f'<float name="noise_range_std" value="0.02"/><string name="return_mode" value="{mode}"/>'
    )
    r = _scan(_wall_scene(write_scene, extra, divergence=divergence), weather)
    pts = r.points()
    for key, v in pts.items():
        if v.dtype.kind == "f":
            assert np.all(np.isfinite(v)), key
    assert (pts["range"] >= 0).all() and len(pts["range"]) > 0
    assert set(np.unique(pts["scatterer"])) <= {0, 1, 2, 3}
