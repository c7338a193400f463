"""The weather in the camera: the same medium as the LiDAR's, as a Mitsuba participating medium.

* **Medium**: Mitsuba's ``homogeneous`` medium with the extinction ``sigma_t`` and the
  single-scattering ``albedo`` of :func:`nidar_mi.weather.media.medium_optics` as spectra over
  the visible (450, 550, 650 nm) and every LiDAR wavelength of the render (flat beyond them):
  the RGB and NIR images of a frame see the α their bands see, the LiDAR's at its wavelength
  (Mitsuba's spectra are 0 outside their range: they are extended flat to 300 and 2500 nm).
* **Phase function**: fog scatters with the Mie phase function of its droplets at 550 nm,
  averaged over the size distribution (weights ``Q_sca σ n``), as Mitsuba 3's tabulated phase
  function (``tabphase``, :data:`PHASE_NODES` values evenly spaced in cos θ, each the average
  of the phase function over its bin: the diffraction peak, narrower than a bin, keeps its
  energy). Mitsuba's tabulated phase function is one table for all wavelengths; fog droplets
  are large enough (x >> 1) that its shape barely changes from 450 to 1550 nm. Rain and snow
  scatter with a Henyey-Greenstein function of their asymmetry ``g``; fog with rain or snow
  blend the two (``blendphase``) by their scattering coefficients.
* **Extent**: the medium fills a box (``null`` BSDF, the medium inside) around the scene's
  bounding box and the cameras, :data:`MARGIN_M` wider and up to :data:`FOG_TOP_M` above the
  scene's top: light from the sky and the sun enters through its faces (an unbounded medium
  would extinguish them completely). The cameras sit in the medium.
* **Integrator**: ``volpath`` (volumetric path tracing with next-event estimation),
  :data:`MAX_DEPTH` bounces. A forward-peaked phase function under a directional sun makes the
  in-scattered light noisy: figures of dense fog want a few hundred samples per pixel.

:func:`weather_scene` builds the scene's weather twin (its shapes and emitters, the box, the
integrator); the cameras' twins carry the medium (:mod:`nidar_mi.camera`).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, NamedTuple

import numpy as np

from .conditions import Weather
from .media import VISIBLE_NM, medium_optics, sphere_efficiencies
from .mie import X_MIE, phase_function
from .particles import fog_distribution
from .refractive_index import water_index

__all__ = [
    "PHASE_NODES",
    "MARGIN_M",
    "FOG_TOP_M",
    "MAX_DEPTH",
    "VISIBLE_BANDS_NM",
    "fog_phase_table",
    "medium_dict",
    "WeatherScene",
    "weather_scene",
]

#: Values of the tabulated phase function.
PHASE_NODES = 512
#: How much wider than the scene the medium's box is, m.
MARGIN_M = 5.0
#: How far the medium's box reaches above the scene's top, m.
FOG_TOP_M = 30.0
#: Bounces of the volumetric path tracer.
MAX_DEPTH = 12
#: The visible wavelengths the medium's spectra are given at, nm.
VISIBLE_BANDS_NM = (450.0, 550.0, 650.0)
#: Droplet sizes the fog's phase function averages over.
_PHASE_SIZES = 48


@lru_cache(maxsize=8)
def fog_phase_table(fog_type: str) -> np.ndarray:
    """(:data:`PHASE_NODES`,) the fog's phase function at 550 nm, 1/sr, at cos θ evenly spaced
    from -1 (back) to 1 (forward): the average of ``p`` over each node's bin (module
    docstring); ``2π ∫ p dμ = 1``."""
    m = complex(water_index(VISIBLE_NM))
    dist = fog_distribution(fog_type)
    grid, q = sphere_efficiencies("water", VISIBLE_NM)
    x = np.pi * grid / (VISIBLE_NM * 1e-9)
    weight = dist.density(grid) * q.qsca * grid**3  # n σ Q_sca per d(ln D)
    keep = (weight > weight.max() * 1e-4) & (x <= X_MIE)
    lnd = np.linspace(np.log(grid[keep][0]), np.log(grid[keep][-1]), _PHASE_SIZES)
    w = np.interp(lnd, np.log(grid), weight)
    # a scattering-angle grid dense near the forward peak, cumulated over μ
    theta = np.concatenate([[0.0], np.geomspace(1e-5, np.pi, 3000)])
    mu = np.cos(theta)
    p = phase_function(m, np.pi * np.exp(lnd) / (VISIBLE_NM * 1e-9), mu)
    p = (w[:, None] * p).sum(axis=0) / w.sum()
    order = np.argsort(mu)
    mu, p = mu[order], p[order]
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(mu))])
    nodes = np.linspace(-1.0, 1.0, PHASE_NODES)
    half = 1.0 / (PHASE_NODES - 1)
    lo, hi = np.clip(nodes - half, -1.0, 1.0), np.clip(nodes + half, -1.0, 1.0)
    table = (np.interp(hi, mu, cdf) - np.interp(lo, mu, cdf)) / (hi - lo)
    return table / (2.0 * np.pi * np.trapezoid(table, nodes))


#: The spectra's outer ends, nm: a Mitsuba spectrum is 0 outside its range.
_SPECTRUM_ENDS = (300.0, 2500.0)


def _spectrum(wavelengths: list[float], values: list[float]) -> dict:
    """A Mitsuba spectrum through the values, flat from the first and the last to
    :data:`_SPECTRUM_ENDS` (a medium of σ_t = 0 somewhere would divide by zero)."""
    lo, hi = _SPECTRUM_ENDS
    points = [(lo, values[0]), *zip(wavelengths, values), (hi, values[-1])]
    return {"type": "spectrum", "value": [(float(w), float(v)) for w, v in points]}


def medium_dict(weather: Weather, nir_wavelengths=()) -> dict:
    """The Mitsuba ``homogeneous`` medium of ``weather`` (module docstring), for
    :func:`mitsuba.load_dict`; spectra at the visible bands and ``nir_wavelengths`` (nm)."""
    wavelengths = sorted({*VISIBLE_BANDS_NM, *map(float, nir_wavelengths)})
    optics = [medium_optics(weather, w) for w in wavelengths]
    medium = {
        "type": "homogeneous",
        "sigma_t": _spectrum(wavelengths, [o.alpha for o in optics]),
        "albedo": _spectrum(wavelengths, [min(o.albedo, 1.0) for o in optics]),
        "phase": _phase(weather),
    }
    return medium


def _phase(weather: Weather) -> dict:
    visible = medium_optics(weather, VISIBLE_NM)
    precipitation = {k: v for k, v in visible.components.items() if k != "fog"}
    hg = None
    if precipitation:
        (bulk,) = precipitation.values()
        hg = {"type": "hg", "g": float(np.clip(bulk.g, -0.99, 0.99))}
    if not weather.fog:
        return hg
    fog = {
        "type": "tabphase",
        "values": ", ".join(f"{v:.8g}" for v in fog_phase_table(weather.fog_type)),
    }
    if hg is None:
        return fog
    share = bulk.scattering / (bulk.scattering + visible.components["fog"].scattering)
    return {"type": "blendphase", "weight": float(share), "phase1": fog, "phase2": hg}


class WeatherScene(NamedTuple):
    """A scene's weather twin: ``scene`` (its shapes and emitters in the medium's box),
    ``medium`` (the loaded medium, for the cameras) and ``integrator``."""

    scene: Any
    medium: Any
    integrator: Any


def weather_scene(scene, weather: Weather, nir_wavelengths=(), cameras=()) -> WeatherScene:
    """The weather twin of a loaded ``scene`` (module docstring), in the active variant.

    Args:
        scene: a ``mi.Scene``.
        weather: not clear.
        nir_wavelengths: the NIR bands rendered, nm.
        cameras: world positions (3,) the box must hold besides the scene.
    """
    import mitsuba as mi

    medium = mi.load_dict(medium_dict(weather, nir_wavelengths))
    bbox = scene.bbox()
    lo = np.array([float(v) for v in bbox.min], dtype=np.float64)
    hi = np.array([float(v) for v in bbox.max], dtype=np.float64)
    for c in cameras:
        lo, hi = np.minimum(lo, c), np.maximum(hi, c)
    lo, hi = lo - MARGIN_M, hi + MARGIN_M
    hi[2] += FOG_TOP_M - MARGIN_M
    centre, half = (lo + hi) / 2.0, (hi - lo) / 2.0
    box = {
        "type": "cube",
        "bsdf": {"type": "null"},
        "interior": medium,
        "to_world": mi.ScalarTransform4f().translate(centre.tolist()).scale(half.tolist()),
    }
    objects: dict[str, Any] = {f"shape_{i}": s for i, s in enumerate(scene.shapes())}
    for i, e in enumerate(scene.emitters()):
        if not (int(e.flags()) & int(mi.EmitterFlags.Surface)):  # area lights come with shapes
            objects[f"emitter_{i}"] = e
    twin = mi.load_dict({"type": "scene", **objects, "weather_box": box})
    integrator = mi.load_dict({"type": "volpath", "max_depth": MAX_DEPTH})
    return WeatherScene(twin, medium, integrator)
