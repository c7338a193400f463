"""Fog, rain and snow media against closed forms and published values.

Independent references: the Rayleigh limit of small spheres (Bohren & Huffman 1983, eqs. 5.8 and
5.14 with x -> 0), the extinction paradox with Nussenzveig & Wiscombe's edge term for large
ones, the WMO definition of the meteorological optical range, the geometric-optics extinction of
exponential (Marshall-Palmer, Gunn-Marshall) distributions integrated by hand, and the data
files' own rows.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.weather import Weather, check_weather, mie
from nidar_mi.weather.media import (
    VISIBLE_NM,
    bulk_optics,
    medium_optics,
    snow_reflectance,
)
from nidar_mi.weather.particles import (
    FOG_TYPES,
    fog_distribution,
    gunn_marshall,
    marshall_palmer,
    sekhon_srivastava,
)
from nidar_mi.weather.refractive_index import ice_index, water_index

LN20 = math.log(20.0)


# ------------------------------------------------------------------ Mie


def test_rayleigh_limit_of_the_series():
    """x << 1: Q_sca = 8/3 x⁴ |K|², Q_back = 4 x⁴ |K|², Q_abs = 4 x Im(-K), K = (m²-1)/(m²+2)."""
    m, x = complex(1.33, -0.01), 0.01
    k = (m * m - 1) / (m * m + 2)
    q = mie.series_efficiencies(m, [x])
    assert q.qsca[0] == pytest.approx(8.0 / 3.0 * x**4 * abs(k) ** 2, rel=1e-3)
    assert q.qback[0] == pytest.approx(4.0 * x**4 * abs(k) ** 2, rel=1e-3)
    assert q.qext[0] - q.qsca[0] == pytest.approx(-4.0 * x * k.imag, rel=1e-3)
    assert abs(q.g[0]) < 1e-3


def test_large_spheres_extinguish_twice_their_cross_section():
    water = complex(water_index(905.0))
    series = mie.series_efficiencies(water, np.linspace(950.0, 1050.0, 21)).qext
    edge = 2.0 + 1.9924 * 1000.0 ** (-2.0 / 3.0)  # Nussenzveig & Wiscombe 1980
    assert series.mean() == pytest.approx(edge, abs=0.01)
    assert series.mean() == pytest.approx(2.0, abs=0.03)
    geometric = mie.efficiencies(water, np.array([1e4, 1e5]), 905.0)
    np.testing.assert_allclose(geometric.qext, 2.0, atol=0.005)
    # the seam is continuous for the absorbing drop at 1550 nm too
    w1550 = complex(water_index(1550.0))
    below = mie.efficiencies(w1550, np.linspace(900, 1000, 11), 1550.0).qext.mean()
    above = mie.efficiencies(w1550, np.linspace(1001, 1100, 11), 1550.0).qext.mean()
    assert above == pytest.approx(below, rel=0.01)


def test_large_drops_backscatter_their_front_face():
    """Beyond the series' range a drop returns the Fresnel reflection of its face,
    |(m-1)/(m+1)|² ≈ 0.02 for water (the glory of perfect spheres is not kept: falling drops
    that large are flattened); below it the series' glory stays, far above it."""
    for wavelength in (905.0, 1550.0):
        m = complex(water_index(wavelength))
        r0 = ((m.real - 1) / (m.real + 1)) ** 2
        x = np.pi * np.array([1e-3, 3e-3]) / (wavelength * 1e-9)
        np.testing.assert_allclose(mie.efficiencies(m, x, wavelength).qback, r0, rtol=1e-3)
        assert 0.017 < r0 < 0.021
    small = mie.mean_backscatter(complex(water_index(905.0)), [300.0], 905.0)[0]
    assert small > 20 * r0


def test_phase_function_is_normalised_and_forward():
    mu = np.linspace(-1.0, 1.0, 20001)
    p = mie.phase_function(complex(1.335, -1e-9), [5.0, 40.0], mu)
    np.testing.assert_allclose(2 * np.pi * np.trapezoid(p, mu, axis=1), 1.0, rtol=2e-3)
    assert np.all(p[:, -1] > 100 * p[:, 0])


def test_mean_backscatter_follows_the_series_between_its_anchors():
    """A drop's backscatter without resonances (anchors interpolated) against the series averaged
    over 301 sizes within ±25 % at sizes between the anchors; within 30 % (the local mean
    itself moves by that much between neighbouring windows)."""
    for wavelength in (905.0, 1550.0):
        m = complex(water_index(wavelength))
        x = np.array([3.3, 26.0, 65.0, 240.0, 550.0])
        reference = [
            mie.series_efficiencies(m, xx * np.linspace(0.75, 1.25, 301)).qback.mean() for xx in x
        ]
        np.testing.assert_allclose(mie.mean_backscatter(m, x, wavelength), reference, rtol=0.3)


# ------------------------------------------------------------------ indices and particles


def test_refractive_indices_at_table_rows():
    """The tables' own rows come back (Segelstein 1981 at 1.549 um; Warren & Brandt 2008 at 0.9
    um), and both interpolate between rows."""
    assert complex(water_index(1549.0)) == pytest.approx(complex(1.310923, -1.348e-4), rel=1e-4)
    assert complex(ice_index(900.0)) == pytest.approx(complex(1.3032, -4.20e-7), rel=1e-6)
    assert 1.30 < water_index(905.0).real < 1.33
    with pytest.raises(ValueError):
        water_index(250.0)


def test_distributions_hold_their_number_and_shape():
    fog = fog_distribution("advection", 20e6)  # 20 droplets per cm³
    assert fog.number() == pytest.approx(20e6, rel=1e-3)
    d = np.geomspace(1e-7, 2e-4, 4001)
    n = fog.density(d)
    assert d[np.argmax(n)] / 2.0 == pytest.approx(10e-6, rel=0.01)  # the mode radius r_c
    rad = FOG_TYPES["radiation"]
    assert d[np.argmax(rad.density(d))] / 2.0 == pytest.approx(2e-6, rel=0.02)
    rain = marshall_palmer(10.0)  # N0 = 8000 m⁻³ mm⁻¹, Λ = 4.1 R^-0.21 mm⁻¹
    assert rain.density(np.array([1e-3]))[0] == pytest.approx(8e6 * math.exp(-4.1 * 10**-0.21))
    gm, ss = gunn_marshall(1.0), sekhon_srivastava(1.0)
    k = gm.size_ratio  # a flake is (ρw/ρs)^(1/3) its melted diameter
    assert gm.density(np.array([k * 1e-3]))[0] * k == pytest.approx(3.8e6 * math.exp(-2.55))
    assert ss.density(np.array([k * 1e-3]))[0] * k == pytest.approx(2.5e6 * math.exp(-2.29))


# ------------------------------------------------------------------ media


@pytest.mark.parametrize(("wavelength", "tolerance"), [(905.0, 0.10), (1550.0, 0.25)])
def test_default_fog_extinction_follows_its_visibility(wavelength, tolerance):
    """α(550 nm) = ln 20 / MOR by construction; the droplets give α at the LiDAR's wavelength
    within 10 % (905 nm) and 25 % (1550 nm) of it."""
    for mor in (30.0, 200.0, 1000.0):
        w = Weather(fog=mor)
        assert medium_optics(w, VISIBLE_NM).alpha == pytest.approx(LN20 / mor, rel=1e-9)
        assert medium_optics(w, wavelength).alpha == pytest.approx(LN20 / mor, rel=tolerance)


def test_fog_lidar_ratio_is_that_of_water_clouds():
    """Extinction over backscatter of fog droplets: 18.8 sr measured for liquid water clouds
    (O'Connor, Illingworth & Hogan, J. Atmos. Oceanic Technol. 21, 777, 2004); within 25 %."""
    o = medium_optics(Weather(fog=100.0), 905.0)
    assert o.alpha / o.backscatter == pytest.approx(18.8, rel=0.25)
    assert 0.99 < o.albedo <= 1.0 and 0.8 < o.g < 0.9


def test_rain_and_snow_extinction_against_the_geometric_closed_form():
    """All drops geometric (Q_ext = 2): α = 2 ∫ π D²/4 N0 e^{-ΛD} dD = π N0 / Λ³ (the tails
    beyond the distribution's range removed); flakes k times their melted diameter: k² as
    much. The edge term and the small drops keep the computed α within 3 %."""
    for rate in (1.0, 10.0, 50.0):
        rain = marshall_palmer(rate)
        closed = math.pi * rain.n0 / rain.slope**3 * _tail(rain.slope, rain.d_min, rain.d_max)
        assert bulk_optics(rain, 905.0).alpha == pytest.approx(closed, rel=0.03)
    for rate in (0.5, 3.0):
        snow = gunn_marshall(rate)
        k = snow.size_ratio
        lo, hi = snow.d_min / k, snow.d_max / k
        closed = math.pi * k * k * snow.n0 / snow.slope**3 * _tail(snow.slope, lo, hi)
        assert bulk_optics(snow, 1550.0).alpha == pytest.approx(closed, rel=0.03)
    # 10 mm/h: 1.56 /km at 905 nm, hardly another value at 1550 nm (geometric)
    a905 = medium_optics(Weather(rain=10.0), 905.0).alpha
    assert a905 == pytest.approx(1.56e-3, rel=0.02)
    assert medium_optics(Weather(rain=10.0), 1550.0).alpha == pytest.approx(a905, rel=0.01)


def _tail(slope: float, lo: float, hi: float) -> float:
    """∫_lo^hi x² e^{-Λx} dx over ∫_0^∞ (= 2/Λ³)."""
    from scipy.special import gammainc

    return float(gammainc(3, slope * hi) - gammainc(3, slope * lo))


def test_snow_is_bright_at_905_and_dark_at_1550():
    """Ice absorbs at 1550 nm (k = 4e-4): a snowflake reflects 0.88 at 905 nm, 0.05 at 1550 nm
    (the asymptotic albedo exp(-3.6 sqrt(γ d)), d = 0.2 mm); white in the visible."""
    assert snow_reflectance(905.0) == pytest.approx(0.88, abs=0.01)
    assert snow_reflectance(1550.0) == pytest.approx(0.051, abs=0.005)
    assert snow_reflectance(550.0) > 0.98


def test_fog_and_precipitation_add():
    fog, rain = medium_optics(Weather(fog=200.0), 905.0), medium_optics(Weather(rain=5.0), 905.0)
    both = medium_optics(Weather(fog=200.0, rain=5.0), 905.0)
    assert both.alpha == pytest.approx(fog.alpha + rain.alpha)
    assert both.backscatter == pytest.approx(fog.backscatter + rain.backscatter)
    assert both.volume_scatterer == 1  # fog backscatters far more than the rain


# ------------------------------------------------------------------ conditions


@pytest.mark.parametrize(
    ("weather", "names"),
    [
        (Weather(fog=0.0), "`fog`"),
        (Weather(fog=-50.0), "`fog`"),
        (Weather(fog=1.0), "`fog`"),
        (Weather(rain=-1.0), "`rain`"),
        (Weather(rain=1e4), "`rain`"),
        (Weather(snow=80.0), "`snow`"),
        (Weather(fog=50.0, fog_type="sea"), "`fog_type`"),
        (Weather(rain=2.0, snow=1.0), "`rain`"),
        (Weather(rain=float("nan")), "`rain`"),
    ],
)
def test_impossible_weather_is_refused(weather, names):
    with pytest.raises(NidarError, match=names):
        check_weather(weather)


def test_weather_from_xml_values():
    assert Weather.from_mapping({}) is None
    assert Weather.from_mapping({"rain": "0"}) is None
    w = Weather.from_mapping({"fog": "80", "fog_type": " Radiation "})
    assert (w.fog, w.fog_type, w.describe()) == (80.0, "radiation", "fog 80 m (radiation)")
    with pytest.raises(NidarError, match="`snow` must be a number"):
        Weather.from_mapping({"snow": "heavy"})
