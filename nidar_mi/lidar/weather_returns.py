"""Weather in the LiDAR return model: the hard target's two-way transmission, the soft return of
the medium's own backscatter, drops and flakes in the beam, and the range jitter of a weaker
return. The media's optics come from :mod:`nidar_mi.weather.media`; everything here runs on
NumPy or Dr.Jit arrays alike (one implementation for the scan's kernel and for real clouds).

Returns in the ``raw`` mode's unit (gain g, 1/m²) unless said otherwise; ``compensated`` values
are the raw ones times the range² at which they are reported.

**Hard target.** The medium's extinction α_w adds to the sensor's clear-air α: a surface at
``d`` returns ``g ρ T² cos θ exp(-2 (α + α_w) d) / d²`` (:mod:`.return_model`).

**Soft return** (Rasshofer et al., Adv. Radio Sci. 9, 49, 2011; Hahner et al., ICCV 2021). The
receiver sees the medium's backscatter along the beam, convolved with the pulse:

    E_s(R) = g ∫₀^d π β ξ(r) exp(-2 α_w r) / r² · s(R - r) dr

with β the medium's backscatter coefficient (1/(m sr); a slab of thickness Δ with π β Δ = ρ
returns like a surface of reflectance ρ: the hard target's ``g ρ / d²`` is ``g π f_r / d²``
with the same gain ``g``), ``s(x) = cos²(π x / (c τ_H))`` for ``|x| <= c τ_H / 2`` the pulse in
range (peak 1 at the echo's range, half-power width τ_H in time, ``∫ s = c τ_H / 2``), ``ξ(r)``
the receiver's near-field response (:func:`overlap`) and ``d`` the hard target's range (the
medium behind it is hidden). Its peak (range ``R_s``, value ``E_s``) is tabulated once per scan
against ``d`` (:class:`SoftReturnTable`) and read by every beam: a candidate echo like the
hard one.

**The receiver's near field** (:class:`ReceiverOptics`, :func:`receiver_optics`). A sensor
reports nothing before its minimum range R1 (``overlap_start``). Beyond it, the ``defocus``
response (the default) is that of a receiver whose full sensitivity starts at ``F``
(``overlap_full``): ``ξ(r) = min(1, (r / F)²)``. A point nearer than the range the receiver is
focused for images as a blur circle whose diameter grows as ``1/r``; the detector collects
``(r / F)²`` of it, so ``ξ / r²`` stays at ``1 / F²`` up to ``F`` and falls as ``1 / r²``
beyond. It is also the largest response under which no target returns more than at ``F``
(``ξ(r)/r² <= ξ(F)/F²``): Velodyne calibrates each HDL-64E laser's "focal distance", its
"maximum intensity distance" (HDL-64E S3 manual, 63-HDL64ES3 rev. K, p. 10), and the default
``F`` is the median of the 64 lasers of the S2.1 unit whose table the ``hdl64e`` preset uses.
The ``linear`` response is Rasshofer et al.'s biaxial ramp (0 at R1, 1 at R2; their eqs. 11,
12), for optics given as such. The hard target keeps the clear model (no ``ξ``): its link
budget is what the threshold was set on, and a target of reflectance ``ρ >= T F²`` (0.26 % for
the ``hdl64e`` preset) is detected near the sensor either way.

**Drops and flakes** (:class:`ParticleTable`). The particles of the precipitation that a beam
could detect are sampled per beam: a Poisson number in the cone of the beam (a disk of radius
``k w(r) + a`` around the axis, ``w = θ_w r`` the footprint's 1/e² radius, ``k`` =
:data:`LATERAL_EXTENT`, ``a`` the particle's radius; a line for an ideal beam), each with its
diameter from the size distribution, its range and its offset ``ρ`` from the axis. A particle
intercepts the fraction ``f = (1 - exp(-2 a²/w²)) exp(-2 ρ²/w²)`` of the Gaussian beam (exact
on the axis, ``2 a²/w² exp(-2ρ²/w²)`` for small particles; 1 for an ideal beam) and returns
``g ρ_p f ξ(r) exp(-2 α_w r) / r²`` with ``ρ_p = Q_back/4`` its reflectance as a disk
(:func:`nidar_mi.weather.media.particle_reflectance`). The hard target behind it keeps
``(1 - f)²`` of its return (out and back). Particles that could not reach ``T - 2 σ_n`` anywhere
(detection probability < 2.3 %) are not sampled: their effect is the mean extinction α_w.
Sampling per beam keeps at most :data:`MAX_SLOTS` particles.

**Range jitter.** A return of energy ``E`` in receiver noise ``σ_n`` is timed to within
``σ_R = c τ_H σ_n / (π E)`` (noise over the pulse's steepest slope ``π E / (c τ_H)``); the
sensor's ``noise_range_std`` holds its clear-weather jitter, so weather adds
``c τ_H σ_n / π · sqrt(1/E² - 1/E_clear²)`` (all of it for particles and soft returns), at most
``c τ_H / 2``.

Detection stays :func:`.return_model.detect`: every candidate (hard, soft, each particle) with its
own receiver noise; the return mode picks among those detected (strongest, first or last).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, NamedTuple

import numpy as np

from ..weather.conditions import Weather
from ..weather.media import (
    SCATTERERS,
    MediumOptics,
    medium_optics,
    particle_reflectance,
    precipitation_distribution,
)
from .return_model import array_module, detect, received

__all__ = [
    "SPEED_OF_LIGHT",
    "LATERAL_EXTENT",
    "MAX_SLOTS",
    "HDL64E_PULSE_WIDTH",
    "HDL64E_FOCAL_DISTANCE",
    "OVERLAP_SHAPES",
    "ReceiverOptics",
    "receiver_optics",
    "SoftReturnTable",
    "ParticleTable",
    "WeatherModel",
    "SensorTerms",
    "overlap",
    "soft_waveform",
    "soft_return_table",
    "particle_table",
    "intercepted_fraction",
    "weather_model",
    "Candidates",
    "candidates",
    "choose",
    "range_jitter",
    "detect_candidates",
    "device_tables",
]

SPEED_OF_LIGHT = 299_792_458.0
#: Radius of the sampled disk around the beam axis, in footprint radii w (1 % of the peak
#: irradiance at its edge).
LATERAL_EXTENT = 1.5
#: Most particles sampled in one beam.
MAX_SLOTS = 16
#: Particles whose best return stays below ``T - DETECTION_MARGIN · σ_n`` are not sampled.
DETECTION_MARGIN = 2.0
#: Quantile nodes of the particle tables.
_QUANTILES = 257


#: The HDL-64E's pulse: "a short duration (typically 4 nanoseconds)" (Velodyne, "HDL-64E:
#: Concept", velodyne.com/lidar/technology/concept.aspx), read as the half-power width τ_H, s.
HDL64E_PULSE_WIDTH = 4e-9
#: The median "focal distance" (maximum intensity distance) of the 64 lasers of the HDL-64E S2.1
#: unit of the ``hdl64e`` preset's table (ros-drivers/velodyne ``64e_s2.1-sztaki.xml``,
#: ``focalDistance_`` in cm: 1.5 to 20 m), m.
HDL64E_FOCAL_DISTANCE = 8.0
#: Near-field responses of :class:`ReceiverOptics`.
OVERLAP_SHAPES = ("defocus", "linear")


@dataclass(frozen=True)
class ReceiverOptics:
    """What of the sensor's receiver and pulse the weather needs (module docstring).

    The defaults are the HDL-64E's documented figures (:data:`HDL64E_PULSE_WIDTH`,
    :data:`HDL64E_FOCAL_DISTANCE`, its manual's minimum return distance "approximately 3 feet
    (0.9 meters)"); :func:`receiver_optics` gives a sensor its own minimum range. Rasshofer et
    al.'s biaxial ramp with the optics Hahner et al.'s fog simulation states (apertures 10 mm
    apart by D = 0.1 m, beam 2°, receiver field of view 3.5°; their eqs. 11 and 12) is
    ``ReceiverOptics(10e-9, 1.67, 7.64, "linear")``; Hahner et al. then simulate a nearly
    coaxial ``ReceiverOptics(20e-9, 0.9, 1.0, "linear")``.

    Attributes:
        pulse_width: half-power pulse width τ_H, s.
        overlap_start: range R1 before which the receiver reports nothing, m.
        overlap_full: range where the receiver reaches full sensitivity (``F`` of the
            ``defocus`` response, R2 of the ``linear`` one), m (>= ``overlap_start``).
        overlap_shape: ``defocus`` (``ξ = (r / F)²`` from R1) or ``linear`` (0 at R1 to 1 at R2).
    """

    pulse_width: float = HDL64E_PULSE_WIDTH
    overlap_start: float = 0.9
    overlap_full: float = HDL64E_FOCAL_DISTANCE
    overlap_shape: str = "defocus"

    def __post_init__(self) -> None:
        if self.overlap_shape not in OVERLAP_SHAPES:
            raise ValueError(f"unknown overlap shape '{self.overlap_shape}'")
        if not (self.pulse_width > 0 and 0 <= self.overlap_start <= self.overlap_full):
            raise ValueError(f"inconsistent receiver optics {self}")

    @property
    def pulse_length(self) -> float:
        """``c τ_H``: the pulse's extent in range, m (the support of ``s``)."""
        return SPEED_OF_LIGHT * self.pulse_width


def receiver_optics(cfg) -> ReceiverOptics:
    """The receiver of a sensor (anything with a ``range_min``, m): the HDL-64E's documented
    pulse and near field (:class:`ReceiverOptics`), its own minimum range. The other presets'
    datasheets publish neither a pulse width nor a near-field response."""
    r1 = max(float(cfg.range_min), 0.0)
    return ReceiverOptics(overlap_start=r1, overlap_full=max(HDL64E_FOCAL_DISTANCE, r1))


def overlap(r, optics: ReceiverOptics):
    """ξ(r), the receiver's near-field response (module docstring); NumPy or Dr.Jit."""
    xp = array_module(r)
    r1, full = optics.overlap_start, optics.overlap_full
    if optics.overlap_shape == "linear":
        span = max(full - r1, 1e-9)
        return xp.minimum(xp.maximum((r - r1) / span, 0.0), 1.0)
    inv = 1.0 / max(full * full, 1e-18)
    return _where(xp, r >= r1, xp.minimum(r * r * inv, 1.0), 0.0)


# ---------------------------------------------------------------- soft return


def _soft_grid(alpha: float, beta: float, optics: ReceiverOptics, far: float):
    """Ranges ``r`` (m) and the integrand's weights ``π β ξ exp(-2αr)/r² dr`` on them."""
    step = min(0.02, optics.pulse_length / 100.0)
    r = np.arange(optics.overlap_start + step / 2.0, far, step)
    w = np.pi * beta * overlap(r, optics) * np.exp(-2.0 * alpha * r) / (r * r) * step
    return r, w


def soft_waveform(ranges, alpha: float, beta: float, optics: ReceiverOptics, limit=np.inf):
    """The soft return ``E_s(R) / g`` at ``ranges`` (module docstring), raw mode, gain 1.

    Args:
        ranges: (M,) ranges R, m.
        alpha: the medium's extinction, 1/m.
        beta: its backscatter coefficient, 1/(m sr).
        optics: pulse and overlap.
        limit: the hard target's range d (the medium behind it does not return), m.

    Returns:
        (M,) float64, 1/m².
    """
    ranges = np.asarray(ranges, dtype=np.float64)
    far = min(float(limit), float(ranges.max(initial=0.0)) + optics.pulse_length)
    if beta <= 0 or far <= optics.overlap_start:
        return np.zeros(ranges.shape)
    r, w = _soft_grid(alpha, beta, optics, far)
    w = np.where(r <= limit, w, 0.0)
    x = ranges[:, None] - r[None, :]
    s = np.where(
        np.abs(x) <= optics.pulse_length / 2.0, np.cos(np.pi * x / optics.pulse_length) ** 2, 0.0
    )
    return s @ w


class SoftReturnTable(NamedTuple):
    """The soft return's peak against the hard target's range d, gain 1, raw mode.

    Attributes:
        limits: (M,) hard-target ranges d, m, evenly spaced from 0; beyond the last one the
            peak no longer depends on d.
        peak_range: (M,) the peak's range R_s, m.
        peak_value: (M,) its value E_s / g, 1/m².
    """

    limits: np.ndarray
    peak_range: np.ndarray
    peak_value: np.ndarray


def soft_return_table(
    alpha: float, beta: float, optics: ReceiverOptics, range_max: float
) -> SoftReturnTable:
    """Tabulate the soft return's peak against the hard target's range (module docstring).

    The waveform is formed on a grid of step ``min(2 cm, c τ_H / 100)``; the truncations at
    every grid range come from one cumulative sum, so the table costs one (n, n) product.
    """
    L = optics.pulse_length
    if beta <= 0:
        z = np.zeros(2)
        return SoftReturnTable(np.array([0.0, range_max + L]), z, z)
    # beyond a few pulse lengths past full overlap the 1/r² fall-off has set the peak: the
    # truncation no longer moves it (checked below, extended while it still does)
    far = min(range_max + L, optics.overlap_full + 6.0 * L + 2.0)
    r, w = _soft_grid(alpha, beta, optics, far + L)
    x = r[:, None] - r[None, :]  # rows: the waveform's ranges R; columns: the medium's r
    s = np.where(np.abs(x) <= L / 2.0, np.cos(np.pi * x / L) ** 2, 0.0)
    cum = np.cumsum(s * w[None, :], axis=1)  # cum[j, k]: the medium up to r_k seen at R_j
    peak = cum.argmax(axis=0)
    limits = np.concatenate([[0.0], r])
    values = np.concatenate([[0.0], cum[peak, np.arange(r.size)]])
    ranges = np.concatenate([[0.0], r[peak]])
    return SoftReturnTable(limits, ranges, values)


# ---------------------------------------------------------------- particles


class ParticleTable(NamedTuple):
    """Per-scan tables of the precipitation's particles a beam may detect.

    Attributes:
        mean_count: mean number of sampled particles per beam (beam-independent).
        count_cdf: (K,) P(N <= k) of the Poisson count, k = 0..K-1 (K the slots).
        diameter: (Q,) particle diameter at evenly spaced quantiles, m.
        reach: (Q,) how far such a particle can be detected, m (its sampling depth).
        reflectance: (Q,) its reflectance ρ_p.
        half_angle: θ_w, rad (0: ideal beam).
        scatterer: code of the particles (:data:`nidar_mi.weather.media.SCATTERERS`).
    """

    mean_count: float
    count_cdf: np.ndarray
    diameter: np.ndarray
    reach: np.ndarray
    reflectance: np.ndarray
    half_angle: float
    scatterer: int

    @property
    def slots(self) -> int:
        return int(self.count_cdf.size)


def intercepted_fraction(radius, offset, footprint):
    """The fraction of a Gaussian beam of 1/e² radius ``footprint`` intercepted by a disk of
    ``radius`` whose centre lies ``offset`` from the axis (module docstring); 1 where the beam
    is a line (``footprint`` 0). NumPy or Dr.Jit."""
    xp = array_module(radius, offset, footprint)
    w2 = xp.maximum(footprint * footprint, 1e-30)
    f = (1.0 - xp.exp(-2.0 * radius * radius / w2)) * xp.exp(-2.0 * offset * offset / w2)
    return _where(xp, footprint > 0.0, f, 1.0)


def _floor(cfg) -> float:
    """The weakest particle return that counts: ``T - 2 σ_n``; a sensor without a threshold
    sees every particle, down to 1e-3 of a 10 % target's return at its maximum range."""
    raw = cfg.intensity_mode != "compensated"
    floor_min = 1e-3 * cfg.gain * 0.1 / (cfg.range_max**2 if raw else 1.0)
    return max(cfg.detection_threshold - DETECTION_MARGIN * cfg.receiver_noise_std, floor_min)


def _reach(rho_p, a, cfg, alpha: float, optics: ReceiverOptics) -> np.ndarray:
    """The farthest range (m) where particles of reflectances ``rho_p`` and radii ``a`` on the
    beam axis return :func:`_floor` or more (0: nowhere)."""
    r = np.geomspace(max(optics.overlap_start, 1e-3), cfg.range_max, 400)
    w = cfg.beam_divergence * 5e-4 * r
    f = intercepted_fraction(a[:, None], 0.0, w[None, :])
    e = cfg.gain * rho_p[:, None] * f * overlap(r, optics)[None, :] * np.exp(-2.0 * alpha * r)
    e = e if cfg.intensity_mode == "compensated" else e / (r * r)[None, :]
    above = e >= _floor(cfg)
    last = np.where(above.any(axis=1), above.shape[1] - 1 - np.argmax(above[:, ::-1], axis=1), -1)
    return np.where(last >= 0, r[np.maximum(last, 0)], 0.0)


def particle_table(
    weather: Weather, cfg, alpha: float, optics: ReceiverOptics
) -> ParticleTable | None:
    """The particle tables of the weather's precipitation for a sensor ``cfg`` (what
    :func:`weather_model` reads of it), or None without precipitation or when no particle can
    be detected (module docstring).

    Args:
        weather: the conditions.
        cfg: the sensor.
        alpha: the medium's extinction at the sensor's wavelength, 1/m.
        optics: pulse and overlap.
    """
    dist = precipitation_distribution(weather)
    if dist is None:
        return None
    d = np.geomspace(dist.d_min, dist.d_max, 600)
    rho_p = particle_reflectance(dist, d, cfg.wavelength)
    reach = _reach(rho_p, d / 2.0, cfg, alpha, optics)
    a = d / 2.0
    half_angle = cfg.beam_divergence * 5e-4
    k = LATERAL_EXTENT * half_angle
    if half_angle > 0:  # ∫₀^R π (k r + a)² dr
        volume = np.pi * ((k * reach + a) ** 3 - a**3) / (3.0 * k)
    else:
        volume = np.pi * a * a * reach
    density = dist.density(d) * volume * d  # per d(ln D)
    steps = 0.5 * (density[1:] + density[:-1]) * np.diff(np.log(d))
    cdf = np.concatenate([[0.0], np.cumsum(steps)])
    mean = float(cdf[-1])
    if mean <= 0:
        return None
    u = np.linspace(0.0, 1.0, _QUANTILES)
    dq = np.exp(np.interp(u * mean, cdf, np.log(d)))
    return ParticleTable(
        mean_count=mean,
        count_cdf=_poisson_cdf(mean),
        diameter=dq,
        reach=np.interp(np.log(dq), np.log(d), reach),
        reflectance=np.interp(np.log(dq), np.log(d), rho_p),
        half_angle=float(half_angle),
        scatterer=SCATTERERS.index("drop" if weather.rain else "flake"),
    )


def _poisson_cdf(mean: float) -> np.ndarray:
    """P(N <= k) for k = 0..K-1, K the slots that hold the count with probability 0.999
    (at most :data:`MAX_SLOTS`, at least 1)."""
    p, cdf, out = math.exp(-mean), 0.0, []
    for k in range(MAX_SLOTS):
        cdf += p
        out.append(cdf)
        if cdf >= 0.999:
            break
        p *= mean / (k + 1)
    return np.asarray(out, dtype=np.float64)


# ---------------------------------------------------------------- the per-scan model


@dataclass(frozen=True)
class WeatherModel:
    """The weather as one sensor sees it, built once per scan (:func:`weather_model`).

    Attributes:
        weather: the conditions.
        optics: the medium at the sensor's wavelength.
        receiver: pulse and overlap.
        soft: the soft return's table (gain 1, raw).
        particles: the precipitation's particle tables, or None.
        gain, mode, noise: the sensor's gain, intensity mode and receiver noise σ_n.
    """

    weather: Weather
    optics: MediumOptics
    receiver: ReceiverOptics
    soft: SoftReturnTable
    particles: ParticleTable | None
    gain: float
    mode: str
    noise: float

    @property
    def alpha(self) -> float:
        """The medium's extinction α_w at the sensor's wavelength, 1/m."""
        return self.optics.alpha

    @property
    def volume_scatterer(self) -> int:
        return self.optics.volume_scatterer


class SensorTerms(NamedTuple):
    """What of a sensor's parameters the weather reads (units of :class:`~.config.LidarConfig`;
    ``beam_divergence`` full angle in mrad)."""

    wavelength: float
    gain: float
    intensity_mode: str
    detection_threshold: float
    receiver_noise_std: float
    beam_divergence: float
    range_max: float
    range_min: float = 0.0

    @classmethod
    def of(cls, cfg) -> SensorTerms:
        return cls(*(getattr(cfg, name) for name in cls._fields))


def weather_model(weather: Weather, cfg, receiver: ReceiverOptics | None = None) -> WeatherModel:
    """The :class:`WeatherModel` of ``weather`` for a sensor ``cfg`` (a
    :class:`~.config.LidarConfig`, or anything with the fields of :class:`SensorTerms`), built
    once per weather, sensor and optics (cached: a sequence of scans builds it once); the
    receiver is the sensor's own (:func:`receiver_optics`) unless given."""
    terms = SensorTerms.of(cfg)
    return _weather_model(weather, terms, receiver or receiver_optics(terms))


@lru_cache(maxsize=16)
def _weather_model(weather: Weather, cfg: SensorTerms, receiver: ReceiverOptics) -> WeatherModel:
    optics = medium_optics(weather, cfg.wavelength)
    return WeatherModel(
        weather=weather,
        optics=optics,
        receiver=receiver,
        soft=soft_return_table(optics.alpha, optics.backscatter, receiver, cfg.range_max),
        particles=particle_table(weather, cfg, optics.alpha, receiver),
        gain=float(cfg.gain),
        mode=cfg.intensity_mode,
        noise=float(cfg.receiver_noise_std),
    )


# ---------------------------------------------------------------- per beam (NumPy or Dr.Jit)


def _lerp(table, pos, size: int, xp, active=True):
    """``table`` (a (size,) array) read at fractional positions ``pos`` in [0, size-1]; Dr.Jit
    reads only the ``active`` lanes (the others get 0)."""
    if xp is np:
        return np.interp(pos, np.arange(size, dtype=np.float64), table)
    import drjit as dr

    # The lower index is clamped as an integer: a float bound such as ``size - 1.000001``
    # rounds to ``size - 1`` in float32 (for size > ~16), and ``idx + 1`` would then read one
    # element past the table.
    p = dr.clip(pos, 0.0, size - 1.0)
    idx = dr.minimum(dr.uint32_array_t(type(p))(dr.floor(p)), max(size - 2, 0))
    t = p - type(p)(idx)
    lo = dr.gather(type(p), table, idx, active)
    hi = dr.gather(type(p), table, dr.minimum(idx + 1, size - 1), active)
    return lo + (hi - lo) * t


class Candidates(NamedTuple):
    """The echoes a beam may report besides its hard target, each a list over candidates
    (soft return first, then the particle slots): expected energy (the sensor's unit), range
    (m), reflectance; and the hard target's occlusion factor ``Π (1 - f)²``."""

    energy: list
    range_m: list
    reflectance: list
    scatterer: list
    occlusion: Any


def candidates(model: WeatherModel, limit, tables: dict, uniforms) -> Candidates:
    """The soft return and the sampled particles of a batch of beams.

    Args:
        model: the scan's weather.
        limit: per beam, the hard target's range (m), or the sensor's ``range_max`` plus a
            pulse where the beam hit nothing.
        tables: the model's tables and per-weather scalars as values of the backend
            (:func:`device_tables`).
        uniforms: a function ``u()`` returning one uniform draw in [0, 1) per beam (the
            backend's arrays); called in a fixed order.

    Returns:
        :class:`Candidates`.
    """
    xp = array_module(limit)
    soft = model.soft
    n_soft = soft.limits.size
    pos = limit / soft.limits[-1] * (n_soft - 1)
    e_soft = model.gain * _lerp(tables["soft_value"], pos, n_soft, xp)
    r_soft = _lerp(tables["soft_range"], pos, n_soft, xp)
    if model.mode == "compensated":
        e_soft = e_soft * r_soft * r_soft
    out = Candidates([e_soft], [r_soft], [0.0 * limit], [model.volume_scatterer], 1.0 + 0.0 * limit)
    p = model.particles
    if p is None:
        return out
    u_count = uniforms()
    q = _QUANTILES
    k = LATERAL_EXTENT * p.half_angle
    occlusion = 1.0 + 0.0 * limit
    alpha, count_cdf = tables["alpha"], tables["count_cdf"]
    for slot in range(p.slots):
        present = u_count > count_cdf[slot]  # the count N exceeds this slot
        qpos = uniforms() * (q - 1)
        diameter, reach, rho_p = (
            _lerp(tables[name], qpos, q, xp, present)
            for name in ("diameter", "reach", "reflectance")
        )
        a = 0.5 * diameter
        if p.half_angle > 0:  # invert ((k r + a)³ - a³) / ((k R + a)³ - a³)
            u_r, u_lat = uniforms(), uniforms()
            top = (k * reach + a) ** 3
            r = xp.maximum(((u_r * (top - a**3) + a**3) ** (1.0 / 3.0) - a) / k, 1e-3)
            f = intercepted_fraction(a, (k * r + a) * xp.sqrt(u_lat), p.half_angle * r)
        else:  # a line through the particle's disk: all of the beam
            r = xp.maximum(uniforms() * reach, 1e-3)
            f = 1.0
        f = _where(xp, present & (r < limit), f, 0.0)
        energy = model.gain * rho_p * f * overlap(r, model.receiver) * xp.exp(-2.0 * alpha * r)
        energy = energy if model.mode == "compensated" else energy / (r * r)
        out.energy.append(energy)
        out.range_m.append(r)
        out.reflectance.append(rho_p)
        out.scatterer.append(p.scatterer)
        occlusion = occlusion * (1.0 - f) * (1.0 - f)
    return out._replace(occlusion=occlusion)


def _where(xp, cond, a, b):
    if xp is np:
        return np.where(cond, a, b)
    import drjit as dr

    return dr.select(cond, a, b)


def device_tables(model: WeatherModel, backend) -> dict:
    """The model's tables as arrays of ``backend`` (``np`` or a Dr.Jit float array type), and
    the values that change with the weather (``alpha``, the extinction; ``count_cdf``, the
    particle count's slots) as scalars: opaque for Dr.Jit, so a scan in other weather of the
    same kind launches the kernels of the first (the tables' sizes and the number of particle
    slots are the only weather-dependent structure)."""
    t = {"soft_value": model.soft.peak_value, "soft_range": model.soft.peak_range}
    p = model.particles
    if p is not None:
        t |= {"diameter": p.diameter, "reach": p.reach, "reflectance": p.reflectance}
    cdf = [] if p is None else [float(c) for c in p.count_cdf]
    if backend is np:
        out = {k: np.asarray(v, dtype=np.float64) for k, v in t.items()}
        return out | {"alpha": float(model.alpha), "count_cdf": cdf}
    import drjit as dr

    out = {k: backend(np.asarray(v, dtype=np.float32)) for k, v in t.items()}
    scalars = {"alpha": dr.opaque(backend, model.alpha)}
    return out | scalars | {"count_cdf": [dr.opaque(backend, c) for c in cdf]}


def range_jitter(model: WeatherModel, energy, clear_energy):
    """The weather's extra range deviation (m) of a return of expected ``energy`` that would
    have returned ``clear_energy`` in clear air (inf: none), module docstring."""
    xp = array_module(energy, clear_energy)
    scale = model.receiver.pulse_length * model.noise / math.pi
    if scale <= 0:
        return 0.0 * energy
    e = xp.maximum(energy, 1e-30)
    inv = xp.maximum(1.0 / (e * e) - 1.0 / xp.maximum(clear_energy * clear_energy, 1e-60), 0.0)
    return xp.minimum(scale * xp.sqrt(inv), model.receiver.pulse_length / 2.0)


def choose(mode: str, valid: list, output: list, range_m: list):
    """Which candidate a beam reports: the index (into the lists) of the strongest detected
    output (``strongest``, ``dual``), the nearest (``first``) or the farthest (``last``); -1
    where none was detected. NumPy or Dr.Jit (int32)."""
    xp = array_module(*output)
    best = None
    best_out = best_rng = any_valid = None
    for i, (v, o, r) in enumerate(zip(valid, output, range_m)):
        if best is None:
            best, best_out, best_rng, any_valid = _where(xp, v, i, -1), o, r, v
            continue
        if mode == "first":
            better = v & (~any_valid | (r < best_rng))
        elif mode == "last":
            better = v & (~any_valid | (r > best_rng))
        else:
            better = v & (~any_valid | (o > best_out))
        best = _where(xp, better, i, best)
        best_out = _where(xp, better, o, best_out)
        best_rng = _where(xp, better, r, best_rng)
        any_valid = any_valid | v
    return best


def detect_candidates(cands: Candidates, *, threshold, range_min, range_max, noise, normals):
    """Detection (:func:`.return_model.detect`) and the receiver's output of each candidate,
    each with its own standard normal from ``normals()``."""
    valid, output = [], []
    for e, r in zip(cands.energy, cands.range_m):
        n = normals()
        valid.append(
            detect(
                e,
                r,
                threshold=threshold,
                range_min=range_min,
                range_max=range_max,
                noise=noise,
                normal=n,
            )
        )
        output.append(received(e, noise, n))
    return valid, output
