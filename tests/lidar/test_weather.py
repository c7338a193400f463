"""The LiDAR in weather against closed forms: the hard target's two-way transmission, the soft
return's integral far from the sensor, a particle's share of a Gaussian beam, the number of
drops on an ideal beam's line; and whole scans (fog near the sensor, drops, determinism, clear
weather unchanged, no NaN at any rate)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nidar_mi.lidar.weather_returns import (
    HDL64E_FOCAL_DISTANCE,
    HDL64E_PULSE_WIDTH,
    ReceiverOptics,
    SensorTerms,
    candidates,
    device_tables,
    intercepted_fraction,
    receiver_optics,
    soft_return_table,
    soft_waveform,
    weather_model,
)
from nidar_mi.weather import Weather
from nidar_mi.weather.media import medium_optics
from nidar_mi.weather.particles import marshall_palmer

SHORT = ReceiverOptics(
    pulse_width=10e-9, overlap_start=0.5, overlap_full=0.5, overlap_shape="linear"
)
C = 299_792_458.0


def _soft_by_quadrature(R: float, alpha: float, beta: float, optics, limit=np.inf) -> float:
    """E_s(R)/g = ∫ π β ξ(r) exp(-2αr)/r² cos²(π(R-r)/L) dr over the pulse's support, by
    adaptive quadrature of the defining integral (ξ written out here, not the module's)."""
    from scipy.integrate import quad

    L, r1, full = optics.pulse_length, optics.overlap_start, optics.overlap_full

    def xi(r):
        if r < r1:
            return 0.0
        if optics.overlap_shape == "linear":
            return min((r - r1) / max(full - r1, 1e-12), 1.0)
        return min((r / full) ** 2, 1.0)

    def f(r):
        s = math.cos(math.pi * (R - r) / L) ** 2
        return math.pi * beta * xi(r) * math.exp(-2 * alpha * r) / (r * r) * s

    lo, hi = max(R - L / 2, r1, 1e-9), min(R + L / 2, limit)
    if hi <= lo:
        return 0.0
    inner = [x for x in (r1, full) if lo < x < hi]
    return quad(f, lo, hi, points=inner or None, limit=200, epsabs=0.0, epsrel=1e-9)[0]


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


@pytest.mark.parametrize(
    "optics",
    [
        ReceiverOptics(),  # defocus: the HDL-64E's pulse and near field
        ReceiverOptics(10e-9, 1.67, 7.64, "linear"),  # Rasshofer's ramp, Hahner et al.'s optics
        ReceiverOptics(20e-9, 0.9, 1.0, "linear"),  # Hahner et al.'s simulated receiver
    ],
)
@pytest.mark.parametrize("mor", [20.0, 200.0])
def test_soft_return_against_quadrature(optics, mor):
    """The tabulated waveform and its peak against an independent adaptive quadrature of the
    defining integral, fog behind the sensor's whole range and cut by a target at 5 m."""
    from scipy.optimize import minimize_scalar

    o = medium_optics(Weather(fog=mor), 905.0)
    a, b = o.alpha, o.backscatter
    for R in (1.0, 1.5, 3.0, 7.9, 12.0, 40.0):
        e = soft_waveform(np.array([R]), a, b, optics)[0]
        assert e == pytest.approx(_soft_by_quadrature(R, a, b, optics), rel=2e-3, abs=1e-12)
    table = soft_return_table(a, b, optics, 120.0)
    for limit in (5.0, 120.0):
        best = minimize_scalar(
            lambda R, lim=limit: -_soft_by_quadrature(R, a, b, optics, lim),
            bounds=(optics.overlap_start, min(limit, 30.0) + optics.pulse_length / 2),
            method="bounded",
            options={"xatol": 1e-4},
        )
        assert np.interp(limit, table.limits, table.peak_value) == pytest.approx(
            -best.fun, rel=3e-3
        )
        assert np.interp(limit, table.limits, table.peak_range) == pytest.approx(best.x, abs=0.03)


def test_defocus_near_field_is_flat_to_the_focal_distance():
    """With ξ = (r/F)², the 1/r² of the lidar equation cancels up to F: where the whole pulse
    lies in [R1, F] the clear-medium (α = 0) soft return is π β (c τ_H / 2) / F², the same at
    every range, and a target there returns g ρ / F² at most (the documented maximum-intensity
    distance)."""
    optics = ReceiverOptics()
    beta, L, F = 1e-3, optics.pulse_length, optics.overlap_full
    plateau = math.pi * beta * (L / 2) / F**2
    R = np.linspace(optics.overlap_start + L / 2 + 0.05, F - L / 2 - 0.05, 7)
    np.testing.assert_allclose(soft_waveform(R, 0.0, beta, optics), plateau, rtol=2e-3)
    far = 60.0  # beyond F: π β (L/2) / R², as for a receiver at full overlap
    e = soft_waveform(np.array([far]), 0.0, beta, optics)[0]
    assert e == pytest.approx(math.pi * beta * (L / 2) / far**2, rel=5e-3)


def test_the_receiver_is_the_documented_hdl64e_one():
    """Pulse 4 ns (Velodyne), full sensitivity at the median focal distance of the preset's
    S2.1 unit, the sensor's own minimum range; the values the references table cites."""
    import csv
    from pathlib import Path

    refs = Path(__file__).resolve().parents[2] / "docs" / "data" / "weather_references.csv"
    with open(refs, encoding="utf-8") as f:
        rows = {r["quantity"]: r for r in csv.DictReader(f) if r["condition"] == "hdl64e"}
    assert float(rows["pulse_half_power_width"]["value"]) * 1e-9 == pytest.approx(
        HDL64E_PULSE_WIDTH
    )
    assert float(rows["focal_distance_median"]["value"]) == HDL64E_FOCAL_DISTANCE
    assert float(rows["minimum_return_distance"]["value"]) == ReceiverOptics().overlap_start
    terms = SensorTerms(905.0, 1.0, "raw", 4e-5, 1e-5, 2.0, 120.0, range_min=0.9)
    optics = receiver_optics(terms)
    assert optics == ReceiverOptics()
    assert weather_model(Weather(fog=50.0), terms).receiver == optics
    assert optics.pulse_length == pytest.approx(C * 4e-9)


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


def test_device_candidates_read_only_inside_their_tables(variant, capfd):
    """On the Dr.Jit backend the soft return and the particles are read from the tables by
    linear interpolation; at and beyond the soft table's last range (the sky beams, whose
    limit is ``range_max`` plus a pulse) the read must stay inside the table and give the
    NumPy path's value (np.interp). Dr.Jit's debug mode reports any out-of-bounds gather on
    stderr: none may appear."""
    import drjit as dr
    import mitsuba as mi

    cfg = SensorTerms(905.0, 1.0, "raw", 0.0, 0.0, 0.0, 120.0)
    model = weather_model(Weather(rain=10.0, fog=40.0), cfg)
    end = float(model.soft.limits[-1])
    assert model.soft.limits.size > 16  # float32 cannot hold size - 1 - 1e-6 apart from size - 1
    limit = np.tile([0.0, 0.37 * end, end * (1 - 1e-7), end, end + 5.0, 1e6], 200)
    rng = np.random.default_rng(3)
    draws = [rng.random(limit.size).astype(np.float32) for _ in range(64)]
    host = candidates(model, limit, device_tables(model, np), iter(draws).__next__)
    previous = dr.flag(dr.JitFlag.Debug)
    dr.set_flag(dr.JitFlag.Debug, True)
    try:
        it = iter(draws)
        dev = candidates(
            model, mi.Float(limit), device_tables(model, mi.Float), lambda: mi.Float(next(it))
        )
        got = [np.asarray(e.numpy(), dtype=np.float64) for e in dev.energy]
        ranges = [np.asarray(r.numpy(), dtype=np.float64) for r in dev.range_m]
    finally:
        dr.set_flag(dr.JitFlag.Debug, previous)
    assert "out-of-bounds" not in capfd.readouterr().err
    for a, b in zip(got, host.energy, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-12)
    # the soft return's range everywhere; a particle's where it is present (the device reads
    # only those lanes)
    np.testing.assert_allclose(ranges[0], host.range_m[0], rtol=1e-5, atol=1e-4)
    for a, b, e in zip(ranges[1:], host.range_m[1:], host.energy[1:], strict=True):
        np.testing.assert_allclose(a[e > 0], b[e > 0], rtol=1e-4, atol=1e-4)
    assert any((e > 0).any() for e in host.energy[1:])  # some drop was met


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


def test_offsets_apply_in_weather_as_in_clear_air(variant, write_scene):
    """The reported intensity is max(output - b - b_r, 0) in fog as in clear air: the wall's
    foggy returns with ``intensity_offset`` 0.01 and per-laser offsets 0 / 0.005 / 0.02 are the
    foggy returns without them, less those offsets."""
    offsets = np.array([0.0, 0.005, 0.02])
    extra = '<float name="intensity_offset" value="0.01"/><string name="laser_offsets" value="0, 0.005, 0.02"/>'
    fog = Weather(fog=2000.0)
    gain = '<float name="gain" value="100"/>'
    plain = _scan(_wall_scene(write_scene, gain), fog)
    shifted = _scan(_wall_scene(write_scene, gain + extra), fog)
    wall = plain.valid & (plain.shape_index >= 0)
    assert wall.sum() > 50 and (plain.intensity[wall] > 0.05).all()
    ring = np.repeat(np.arange(3)[:, None], plain.valid.shape[1], axis=1)[wall]
    np.testing.assert_allclose(
        shifted.intensity[wall], plain.intensity[wall] - 0.01 - offsets[ring], atol=1e-6
    )


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


def test_sky_beams_return_the_fog_with_the_closed_form_probability(variant, write_scene):
    """Beams that meet nothing in fog of MOR 500 m: the HDL-64E receiver (ξ = (r/F)² from R1)
    makes the soft return's peak the pulse wholly past R1, E = π β/F² e^(-2αR1) ∫ e^(-2αx)
    cos²(π(x - L/2)/L) dx over [0, L] = π β/F² e^(-2α(R1 + L/2)) sinh(αL) ω²/(2α(4α² + ω²)),
    ω = 2π/L, L = c τ_H; with the threshold near that E and σ_n = E/4, P = Φ((E - T)/σ_n) of
    the beams report the fog (a closed form, not the module's table)."""
    from scipy.stats import norm

    fog = Weather(fog=500.0)
    o = medium_optics(fog, 905.0)
    a, b, r1 = o.alpha, o.backscatter, 0.9
    L, F = C * 4e-9, 8.0
    w = 2 * math.pi / L
    peak = math.pi * b / F**2 * math.exp(-2 * a * (r1 + L / 2))
    peak *= math.sinh(a * L) * w * w / (2 * a * (4 * a * a + w * w))
    threshold = peak * 0.98  # Φ(0.08) = 0.53: the slope's middle, where P is most sensitive
    path = write_scene(f"""
    <sensor type="lidar" id="lidar">
        <string name="elevation_angles" value="{", ".join(str(e) for e in range(5, 85, 4))}"/>
        <integer name="horizontal_resolution" value="720"/>
        <float name="range_min" value="{r1}"/>
        <float name="range_max" value="120"/>
        <float name="detection_threshold" value="{threshold}"/>
        <float name="receiver_noise_std" value="{peak / 4}"/>
    </sensor>
    """)
    r = _scan(path, fog, seed=5)
    assert (r.shape_index < 0).all()
    expected = norm.sf((threshold - peak) / (peak / 4))
    assert r.valid.mean() == pytest.approx(expected, abs=0.02)
    assert np.all(r.scatterer[r.valid] == 1)
    # at the peak's range: a pulse's leading edge cut by δ before R1 loses ∝ δ³ (2π²δ³/(3L³) of
    # its integral) while its fog is nearer by δ (gain 2αδ): the peak lies δ = √(αL³)/π before
    # R1 + L/2; timed to c τ_H σ_n / (π E) (the noise over the pulse's steepest slope)
    peak_range = r1 + L / 2 - math.sqrt(a * L**3) / math.pi
    assert r.range[r.valid].mean() == pytest.approx(peak_range, abs=0.01)
    assert r.range[r.valid].std() == pytest.approx(L / (4 * math.pi), rel=0.1)


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


def _kernels_per_weather(path, conditions, divergence_free=True):
    """The kernel hashes each scan of ``path`` in ``conditions`` launched (after two warm-up
    scans in the first condition: the first scans of a scene build one-time state)."""
    import gc

    import drjit as dr

    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    L = load_scene(path)
    gc.collect()
    gc.disable()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for _ in range(2):
            scan(L.scene, L.lidars[0], weather=conditions[0], seed=3)
        hashes = []
        for w in conditions:
            dr.kernel_history()  # clear
            scan(L.scene, L.lidars[0], weather=w, seed=3)
            hashes.append({k["hash"] for k in dr.kernel_history() if "hash" in k})
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        gc.enable()
    return L.lidars[0].config, hashes


def test_other_weather_of_the_same_kind_compiles_nothing(variant, write_scene):
    """The weather's values enter the scan's kernels as data (opaque scalars, tables): a sweep
    over fog densities, or over rain rates whose particle counts take as many slots, launches
    only the kernels of its first condition."""
    extra = '<float name="detection_threshold" value="4e-5"/>'
    extra += '<float name="receiver_noise_std" value="1.08e-5"/>'
    path = _wall_scene(write_scene, extra)
    fogs = [Weather(fog=50.0), Weather(fog=200.0), Weather(fog=1000.0)]
    _, hashes = _kernels_per_weather(path, fogs)
    assert hashes[0] and hashes[1] <= hashes[0] and hashes[2] <= hashes[0]
    cfg, _ = _kernels_per_weather(path, [Weather(rain=40.0)])
    rains = [Weather(rain=40.0), Weather(rain=45.0)]
    slots = {weather_model(w, cfg).particles.slots for w in rains}
    assert len(slots) == 1  # the same structure: one more slot would be another kernel
    _, hashes = _kernels_per_weather(path, rains)
    assert hashes[0] and hashes[1] <= hashes[0]
