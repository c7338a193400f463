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
"""

from __future__ import annotations

import dataclasses
import math
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
    "hahner_fog_points",
    "REFERENCES",
]

STREET = Path(__file__).resolve().parents[2] / "scenes" / "street.xml"

#: The published values the coefficients are checked against (docs/WEATHER.md cites them).
REFERENCES = {
    "mor": "WMO: α(550 nm) = ln 20 / MOR (5 % contrast)",
    "hahner": "Hahner et al. 2021 (after Rasshofer et al. 2011): β = 0.046 / MOR (0.023-0.092)",
    "oconnor": "O'Connor et al. 2004: lidar ratio of liquid water clouds α/β = 18.8 sr",
    "kim": "Kim et al. 2001: α(λ) ∝ λ^-q, q = 0 below 500 m visibility (α(1550) = α(905))",
    "mp": "geometric optics of Marshall-Palmer drops: α = π N0 / Λ³",
}


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
        "assumed: a 10 % target detected to 40 m nine times in ten (OS1 gen-1 figure)",
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
    """

    weather: Weather
    lost: float
    false: float
    fog: float
    drop: float
    flake: float


def street_lidar(sensor: SensorSpec, wavelength: float, cols: int):
    """The street (loaded in the active variant) and its LiDAR set to the sensor at
    ``wavelength`` (one sub-ray per beam: the footprint matters for the particles only)."""
    from ..scene import load_scene

    loaded = load_scene(str(STREET), params={"cols": str(cols)})
    lidar = loaded.lidars[0]
    from ..lidar.config import LidarConfig

    base = LidarConfig.from_mapping(
        "lidar_top",
        {
            "preset": sensor.preset,
            "horizontal_resolution": cols,
            "wavelength": wavelength,
            "range_max": 120.0,
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
        out.append(
            SweepPoint(
                weather=w,
                lost=1.0 - kept.sum() / n,
                false=float(kinds[1:].sum()),
                fog=float(kinds[1]),
                drop=float(kinds[2]),
                flake=float(kinds[3]),
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
