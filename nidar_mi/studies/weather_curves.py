"""Weather studies behind ``notebooks/06_weather.ipynb`` and ``docs/WEATHER.md``.

* :func:`coefficient_rows`: α and β of fog, rain and snow at the visible and the LiDAR
  wavelengths (:func:`nidar_mi.weather.media.medium_optics`), beside the values they are checked
  against.
* :func:`street_sweep`: the demo street (``scenes/street.xml``) scanned in clear air and in
  weather by an HDL-64E-like and an OS1-like sensor (:data:`SENSORS`) at 905 or 1550 nm: per
  condition, the share of the clear scan's surface returns lost and the false returns (fog,
  drops, flakes) per clear return.
* :func:`hahner_fog_points`: the share of a clear scan's returns that Hahner et al.'s fog
  simulation on real clouds (ICCV 2021; their published code's constants) turns into fog
  points: the published model beside ours on the same scan.
* :func:`stf_fog`: what Bijelic et al.'s fog-chamber fit for the HDL64-S3D (the Seeing Through
  Fog code, CVPR 2020) does to the same clear scan: the measured counterpart of the points lost
  and of the fog points on beams that returned in clear air; :func:`stf_max_viewing_distance`
  beside :func:`max_viewing_distance`, the model's.
* :func:`sky_fog_probability`: how often a beam that meets no surface returns the fog.
* :func:`panel_sweep`: the calibration panels of ``scenes/target.xml`` in clear air and in
  weather: per panel the share of its points kept and the change of their intensity, the
  measure of the weather-tunnel studies that count points on targets
  (``benchmarks/weather_panels.py`` puts them beside those studies' statements).

The measured and published values are in ``docs/data/weather_references.csv``.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..weather import Weather
from ..weather.media import VISIBLE_NM, medium_optics

__all__ = [
    "SensorSpec",
    "SENSORS",
    "coefficient_rows",
    "SweepPoint",
    "street_lidar",
    "street_sweep",
    "scene_lidar",
    "PanelPoint",
    "panel_sweep",
    "hahner_fog_points",
    "STF_FIT",
    "stf_max_viewing_distance",
    "stf_fog",
    "max_viewing_distance",
    "sky_fog_probability",
    "RAIN_RANGE_VARIATION",
    "REFERENCES",
]

STREET = Path(__file__).resolve().parents[2] / "scenes" / "street.xml"
TARGET = STREET.with_name("target.xml")

#: The published values the coefficients are checked against (docs/WEATHER.md cites them).
REFERENCES = {
    "mor": "WMO: α(550 nm) = ln 20 / MOR (5 % contrast)",
    "hahner": "Hahner et al. 2021 (after Rasshofer et al. 2011): β = 0.046 / MOR (0.023-0.092)",
    "oconnor": "O'Connor et al. 2004: lidar ratio of liquid water clouds α/β = 18.8 sr",
    "kim": "Kim et al. 2001: α(λ) ∝ λ^-q, q = 0 below 500 m visibility (α(1550) = α(905))",
    "mp": "geometric optics of Marshall-Palmer drops: α = π N0 / Λ³",
    "stf": "Bijelic et al. 2020 (SeeingThroughFog code): fog-chamber fit of the HDL64-S3D",
    "pierce": "Pierce et al. 2001: fog attenuation κ/V dB/km, 8.5 < κ < 17 dB, ∝ λ⁰",
    "filgueira": "Filgueira et al. 2017: in rain, range variations always below 20 cm",
}

#: Bijelic et al.'s fog-chamber fit (``lidar_foggification.py``): a point of intensity ``i``
#: (0-1) stays visible to ``ln((i + g)/n) / (2 α)``; ``n``, ``g`` per sensor, ``d_min`` its
#: minimal detectable distance (m), ``scatter`` the share of the points left that also scatter
#: a point between ``d_min`` and themselves ("found empirically").
STF_FIT = {
    "HDL64-S3D": {"n": 0.04, "g": 0.45, "d_min": 2.0, "scatter": 0.05},
    "HDL64-S2": {"n": 0.05, "g": 0.35, "d_min": 2.0, "scatter": 0.05},
}
#: Filgueira et al. 2017 (VLP-16 in natural rain): range variations always below this, m.
RAIN_RANGE_VARIATION = 0.20


@dataclass(frozen=True)
class SensorSpec:
    """A LiDAR of the studies: a preset with a link budget (raw mode, gain 1).

    Attributes:
        name: how plots name it.
        preset: the ``lidar`` preset (rings, range window).
        threshold: detection threshold T, 1/m².
        noise: receiver noise σ_n, 1/m².
        divergence: beam divergence, mrad.
        source: where T and σ_n come from.
    """

    name: str
    preset: str
    threshold: float
    noise: float
    divergence: float
    source: str


#: The Q⁻¹(1e-4) of both sensors' false-alarm rate (the OS1 datasheet's 1/10,000).
_K = 3.719016485455709
SENSORS = {
    "HDL-64E-like": SensorSpec(
        "HDL-64E-like",
        "hdl64e",
        4.0e-5,
        4.0e-5 / _K,
        2.0,
        "hdl64e preset: the datasheet's 10 % target detected to 50 m half the time",
    ),
    "OS1-like": SensorSpec(
        "OS1-like",
        "os1_64",
        0.1 / 40.0**2 / (1.0 + 1.2816 / _K),
        0.1 / 40.0**2 / (1.0 + 1.2816 / _K) / _K,
        2.0,
        "OS1 datasheet (early revision): a 10 % target to 40 m, read as nine times in ten",
    ),
}


def coefficient_rows(wavelengths=(550.0, 905.0, 1550.0)) -> list[dict]:
    """α (1/m) and β (1/(m sr)) of the studied conditions at ``wavelengths``, with what they are
    checked against (``reference``: the value, ``check``: which of :data:`REFERENCES`)."""
    rows = []
    for mor in (50.0, 200.0):
        for fog_type in ("advection", "radiation"):
            w = Weather(fog=mor, fog_type=fog_type)
            for wl in wavelengths:
                o = medium_optics(w, wl)
                rows.append(_row(w, wl, o, math.log(20.0) / mor, 0.046 / mor))
    for rate in (1.0, 10.0, 50.0):
        w = Weather(rain=rate)
        lam = 4.1 * rate**-0.21 * 1e3
        for wl in wavelengths:
            rows.append(_row(w, wl, medium_optics(w, wl), math.pi * 8e6 / lam**3, None))
    for rate in (0.5, 2.0):
        w = Weather(snow=rate)
        for wl in wavelengths:
            rows.append(_row(w, wl, medium_optics(w, wl), None, None))
    return rows


def _row(w: Weather, wl: float, o, alpha_ref, beta_ref) -> dict:
    return {
        "condition": w.describe(),
        "wavelength_nm": wl,
        "alpha_per_m": o.alpha,
        "alpha_reference": alpha_ref,
        "beta_per_m_sr": o.backscatter,
        "beta_reference": beta_ref if wl != VISIBLE_NM else None,
        "lidar_ratio_sr": o.alpha / o.backscatter if o.backscatter > 0 else math.inf,
    }


@dataclass(frozen=True)
class SweepPoint:
    """One condition of :func:`street_sweep`.

    Attributes:
        weather: the condition.
        lost: share of the clear scan's surface returns not returned from a surface.
        false: returns from fog, drops or flakes per clear surface return.
        fog, drop, flake: those false returns by scatterer, per clear surface return.
        false_on_returns: the false returns of the beams that returned a surface in clear air,
            per clear surface return (what a simulation on recorded clouds can produce).
        range_rms: root mean square change of range of the surface returns kept, m.
    """

    weather: Weather
    lost: float
    false: float
    fog: float
    drop: float
    flake: float
    false_on_returns: float = 0.0
    range_rms: float = 0.0


def street_lidar(sensor: SensorSpec, wavelength: float, cols: int):
    """The street (loaded in the active variant) and its LiDAR set to the sensor at
    ``wavelength`` (one sub-ray per beam: the footprint matters for the particles only)."""
    return scene_lidar(STREET, sensor, wavelength, cols)


def scene_lidar(path, sensor: SensorSpec, wavelength: float, cols: int, range_max=120.0):
    """A scene of one LiDAR (loaded in the active variant, ``cols`` given as its ``cols``
    parameter) and that LiDAR set to the sensor at ``wavelength``, range window up to
    ``range_max`` m, seed 0, one sub-ray per beam."""
    from ..scene import load_scene

    loaded = load_scene(str(path), params={"cols": str(cols)})
    lidar = loaded.lidars[0]
    from ..lidar.config import LidarConfig

    base = LidarConfig.from_mapping(
        "lidar_top",
        {
            "preset": sensor.preset,
            "horizontal_resolution": cols,
            "wavelength": wavelength,
            "range_max": range_max,
            "detection_threshold": sensor.threshold,
            "receiver_noise_std": sensor.noise,
            "beam_divergence": sensor.divergence,
            "beam_sample_quality": 1,  # one sub-ray: the footprint matters for the particles
        },
    )
    lidar.config = dataclasses.replace(base, seed=0)
    return loaded, lidar


def street_sweep(
    sensor: SensorSpec, wavelength: float, conditions: list[Weather], cols: int = 1024
) -> list[SweepPoint]:
    """The street scanned in clear air and in each condition (module docstring)."""
    from ..lidar.scan import scan

    loaded, lidar = street_lidar(sensor, wavelength, cols)
    clear = scan(loaded.scene, lidar, weather=Weather())
    surface = clear.valid
    n = max(int(surface.sum()), 1)
    out = []
    for w in conditions:
        r = scan(loaded.scene, lidar, weather=w)
        kinds = np.bincount(r.scatterer[r.valid], minlength=4) / n
        kept = surface & r.valid & (r.scatterer == 0)
        shift = r.range[kept] - clear.range[kept]
        out.append(
            SweepPoint(
                weather=w,
                lost=1.0 - kept.sum() / n,
                false=float(kinds[1:].sum()),
                fog=float(kinds[1]),
                drop=float(kinds[2]),
                flake=float(kinds[3]),
                false_on_returns=float((surface & r.valid & (r.scatterer > 0)).sum() / n),
                range_rms=float(np.sqrt(np.mean(shift**2))) if shift.size else 0.0,
            )
        )
    return out


@dataclass(frozen=True)
class PanelPoint:
    """One calibration panel of ``scenes/target.xml`` in one condition of :func:`panel_sweep`.

    Attributes:
        panel: the panel's shape id (``panel_NN_<material>_<d>m_<tilt>deg``).
        material: ``white_95``, ``grey_50``, ``black_05`` or ``ramp``.
        distance: m; incidence: degrees (from the id).
        weather: the condition.
        npc_clear: the panel's points in clear air.
        npc_ratio: its surface points in the condition per point in clear air.
        intensity_ratio: mean intensity of the beams that return the panel in both scans, in
            the condition over clear air (NaN where none does).
    """

    panel: str
    material: str
    distance: float
    incidence: float
    weather: Weather
    npc_clear: int
    npc_ratio: float
    intensity_ratio: float


_PANEL = re.compile(r"panel_\d+_(?P<material>[a-z]+(?:_\d+)?)_(?P<d>[\d.]+)m_(?P<tilt>\d+)deg$")


def panel_sweep(
    sensor: SensorSpec, wavelength: float, conditions: list[Weather], cols: int = 2048
) -> list[PanelPoint]:
    """The panels of ``scenes/target.xml`` (white 95 %, grey 50 %, black 5 % at 5, 10 and 20
    m, normal incidence and tilted) scanned in clear air and in each condition: per panel, the
    share of its clear points still returned from it and the change of their intensity (the
    measure of the fog-chamber and weather-tunnel tests that count points on a target)."""
    from ..lidar.scan import scan

    loaded, lidar = scene_lidar(TARGET, sensor, wavelength, cols, range_max=40.0)
    clear = scan(loaded.scene, lidar, weather=Weather())
    panels = [(i, _PANEL.match(n)) for i, n in enumerate(clear.shape_names)]
    panels = [(i, m) for i, m in panels if m]
    out = []
    for w in conditions:
        r = scan(loaded.scene, lidar, weather=w)
        kept_any = r.valid & (r.scatterer == 0)
        for i, m in panels:
            before = clear.valid & (clear.shape_index == i)
            kept = before & kept_any & (r.shape_index == i)
            n = int(before.sum())
            both = float(clear.intensity[kept].mean()) if kept.any() else math.nan
            out.append(
                PanelPoint(
                    panel=clear.shape_names[i],
                    material=m["material"],
                    distance=float(m["d"]),
                    incidence=float(m["tilt"]),
                    weather=w,
                    npc_clear=n,
                    npc_ratio=float(kept.sum() / max(n, 1)),
                    intensity_ratio=float(r.intensity[kept].mean() / both)
                    if kept.any()
                    else math.nan,
                )
            )
    return out


def hahner_fog_points(range_m: np.ndarray, intensity: np.ndarray, mor: float) -> float:
    """The share of returns that Hahner et al.'s fog simulation turns into fog points.

    Their published code (github.com/MartinHahner/LiDAR_fog_sim, ``fog_simulation.py``): α =
    ln 20 / MOR, β = 0.046 / MOR, the hard return attenuated by exp(-2αd), the soft return the
    integral of the pulse (τ_H = 20 ns, sin² shape) over the fog with the overlap R1 = 0.9 m,
    R2 = 1.0 m, scaled by ``i · d² · β / β0`` with β0 = Γ/π, Γ = 1e-6; a point becomes a fog
    point where that exceeds its attenuated intensity.

    Args:
        range_m: (N,) the clear returns' ranges, m.
        intensity: (N,) their intensities, compensated (ρ cos θ, KITTI's unit).
        mor: the fog's meteorological optical range, m.
    """
    from scipy.constants import c

    alpha, beta, tau = math.log(20.0) / mor, 0.046 / mor, 2e-8
    beta0 = 1e-6 / math.pi
    t = np.linspace(0.0, 2 * tau, 400)
    R = np.linspace(0.0, 40.0, 400)[:, None]  # the fog's peak lies within a few metres
    r = R - c * t[None, :] / 2
    xi = np.clip((r - 0.9) / 0.1, 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.sin(np.pi * t / (2 * tau)) ** 2 * np.exp(-2 * alpha * r) * xi / r**2
    f = np.where(r > 0.9, f, 0.0)
    grid = np.arange(0.0, 200.0, 0.5)
    # their lookup table: the peak over R of the integral over t, the fog cut at each d
    peaks = np.array([np.trapezoid(np.where(r <= r0, f, 0.0), t, axis=1).max() for r0 in grid])
    soft = np.interp(range_m, grid, peaks) * intensity * range_m**2 * beta / beta0
    hard = intensity * np.exp(-2 * alpha * range_m)
    return float(np.mean(soft > hard))


def stf_max_viewing_distance(intensity, mor: float, sensor: str = "HDL64-S3D"):
    """The fog-chamber fit's visibility of a point of intensity ``i`` (0-1) in fog of MOR
    ``mor`` (m): ``ln((i + g)/n) / (2 α)``, α = ln 20 / MOR (:data:`STF_FIT`), m."""
    fit = STF_FIT[sensor]
    alpha = math.log(20.0) / mor
    return np.log((np.asarray(intensity, dtype=np.float64) + fit["g"]) / fit["n"]) / (2 * alpha)


def stf_fog(range_m, intensity, mor: float, sensor: str = "HDL64-S3D") -> tuple[float, float]:
    """What the fog-chamber fit does to a clear scan's returns (its ``haze_point_cloud``,
    expected values, no draws): the share lost (beyond :func:`stf_max_viewing_distance`) and the
    fog points per return: those lost points whose fog echo the fit keeps (probability
    ``exp(-α d_max)``, placed at ``ln 2 / α``: counted where that lies within the point's
    range and past ``d_min``), and the ``scatter`` share of the points left, scattered nearer.

    Args:
        range_m: (N,) the clear returns' ranges, m.
        intensity: (N,) their intensities, 0-1 (the HDL64's 8-bit intensity / 255; here the
            compensated ρ cos θ).
        mor: the fog's MOR, m.
        sensor: a key of :data:`STF_FIT`.

    Returns:
        ``(lost, fog_points)``, both per clear return.
    """
    fit = STF_FIT[sensor]
    d = np.asarray(range_m, dtype=np.float64)
    alpha = math.log(20.0) / mor
    d_max = stf_max_viewing_distance(intensity, mor, sensor)
    lost = d > d_max
    cloud = lost & (math.log(2.0) / alpha < d) & (math.log(2.0) / alpha > fit["d_min"])
    kept_fog = np.exp(-alpha * d_max)  # the fit's 1 - P(lost)
    near = (~lost) & (np.minimum(d_max, d) > fit["d_min"])
    fog_points = (cloud * kept_fog).sum() + fit["scatter"] * (near * kept_fog).sum()
    return float(lost.mean()), float(fog_points / max(d.size, 1))


def max_viewing_distance(spec: SensorSpec, rho: float, mor: float, wavelength: float) -> float:
    """Where the model detects a target of reflectance ``rho`` at normal incidence half the
    time in fog of MOR ``mor`` (m): ``ρ exp(-2 α d) / d² = T``, α the fog's at ``wavelength``;
    ``inf`` beyond 1 km."""
    from scipy.optimize import brentq

    alpha = medium_optics(Weather(fog=mor), wavelength).alpha

    def excess(d):
        return math.log(rho) - 2 * alpha * d - 2 * math.log(d) - math.log(spec.threshold)

    return brentq(excess, 1e-3, 1e3) if excess(1e3) < 0 else math.inf


def sky_fog_probability(spec: SensorSpec, mor: float, wavelength: float) -> float:
    """The probability that a beam meeting no surface returns the fog: its soft return's
    peak ``E_s`` (the sensor's receiver, :func:`nidar_mi.lidar.weather_returns.receiver_optics`)
    detected in receiver noise, ``Φ((E_s - T) / σ_n)``."""
    from scipy.stats import norm

    from ..lidar.pattern import PRESETS
    from ..lidar.weather_returns import SensorTerms, weather_model

    terms = SensorTerms(
        wavelength,
        1.0,
        "raw",
        spec.threshold,
        spec.noise,
        spec.divergence,
        120.0,
        PRESETS[spec.preset].range_min,
    )
    peak = weather_model(Weather(fog=mor), terms).soft.peak_value[-1]
    return float(norm.sf((spec.threshold - peak) / spec.noise))
