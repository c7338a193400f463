"""Weather on real point clouds: fog, rain and snow added to scans recorded in clear air, as
the fog and snowfall simulations on real clouds do (Hahner et al., ICCV 2021 and CVPR 2022;
LISA, Kilic et al. 2021), with the simulator's own physics (:mod:`nidar_mi.lidar.weather_returns`).

A cloud holds the returns of a sensor in its own frame: each point ``p`` with its clear-air
intensity ``i``. What the weather needs of the sensor is a :class:`CloudSensor`: its wavelength,
what its intensity means (``compensated``: ``i = s ρ cos θ``, KITTI's reflectance in [0, 1]
with ``s = 1``; ``raw``: ``i = s ρ cos θ / d²``), its detection threshold ``T`` and receiver
noise ``σ_n`` (in raw units of gain 1: the link budget of :mod:`nidar_mi.lidar.link_budget`;
the ``hdl64e`` preset's 4e-5 and 1.08e-5 by default), its beam divergence and range window.

Per point, at range ``d`` along its beam:

* the clear return ``E_c`` (raw, gain 1) follows from ``i``;
* the hard return ``E_h = E_c exp(-2 α d) Π(1-f)²`` (the medium's extinction, the particles
  sampled in the beam in front of it);
* the soft return of the medium and the sampled drops or flakes are candidates beside it
  (:func:`nidar_mi.lidar.weather_returns.candidates`), each detected in its own receiver noise;
* the hard return was detected in clear air, so its receiver noise ``n`` is drawn *given* that
  (``E_c + σ_n n >= T``: a normal truncated below at ``(T - E_c)/σ_n``) and it is detected in
  weather when ``E_h + σ_n n >= T``: weather only ever removes a return the attenuation
  explains, never one the clear scan had by luck;
* the return mode picks among the detected candidates; a point none of them returns is lost;
  the reported range gets the weather's range jitter; the intensity is given back in the
  cloud's unit (at most the cloud's own largest intensity: the sensor's saturation).

Beams that returned nothing in clear air (the sky) are not in a cloud: their fog and particle
returns cannot be added. Deterministic given a seed: the draws come from one NumPy generator
seeded per file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .errors import NidarError
from .lidar.pattern import PRESETS
from .lidar.weather_returns import (
    Candidates,
    SensorTerms,
    candidates,
    choose,
    detect_candidates,
    device_tables,
    range_jitter,
    weather_model,
)
from .weather.media import SCATTERERS

__all__ = [
    "CloudSensor",
    "cloud_sensor",
    "INTENSITY_MODES",
    "RETURN_MODES",
    "DEFAULT_DIVERGENCE_MRAD",
    "add_weather",
]

#: What a cloud's intensity is (module docstring).
INTENSITY_MODES = ("compensated", "raw")
#: Returns a sensor reports, among the detected echoes of a beam.
RETURN_MODES = ("strongest", "first", "last")
#: Beam divergence assumed for a preset (full angle at 1/e², mrad): the datasheets of the
#: presets' sensors give none; 2 mrad is a typical spinning LiDAR's.
DEFAULT_DIVERGENCE_MRAD = 2.0


@dataclass(frozen=True)
class CloudSensor:
    """The sensor that recorded a cloud, as the weather needs it (module docstring).

    Attributes:
        name: how messages name it.
        wavelength: nm.
        intensity_mode: ``compensated`` or ``raw``.
        intensity_scale: ``s``: the intensity of ``ρ cos θ = 1`` (compensated) or of it at 1 m
            (raw).
        detection_threshold: ``T``, raw, gain 1 (1/m²).
        receiver_noise_std: ``σ_n``, the unit of ``T``.
        beam_divergence: full angle at 1/e², mrad.
        range_min, range_max: the range window, m.
        return_mode: ``strongest``, ``first`` or ``last``.
    """

    name: str
    wavelength: float = 905.0
    intensity_mode: str = "compensated"
    intensity_scale: float = 1.0
    detection_threshold: float = 0.0
    receiver_noise_std: float = 0.0
    beam_divergence: float = DEFAULT_DIVERGENCE_MRAD
    range_min: float = 0.0
    range_max: float = 120.0
    return_mode: str = "strongest"

    def terms(self) -> SensorTerms:
        """The sensor as :mod:`nidar_mi.lidar.weather_returns` reads it (raw, gain 1)."""
        return SensorTerms(
            self.wavelength,
            1.0,
            "raw",
            self.detection_threshold,
            self.receiver_noise_std,
            self.beam_divergence,
            self.range_max,
        )


def cloud_sensor(preset: str = "hdl64e", **changes) -> CloudSensor:
    """The :class:`CloudSensor` of a LiDAR preset (its range window and, where the preset has
    them, its threshold and receiver noise), with ``changes`` (None values ignored).

    Raises:
        NidarError: an unknown preset, a preset without a threshold and none given, or a value
            out of range (named in backticks).
    """
    if preset not in PRESETS:
        raise NidarError(f"`sensor` must be one of {', '.join(PRESETS)} (got '{preset}')")
    p = PRESETS[preset]
    sensor = CloudSensor(
        name=preset,
        detection_threshold=p.detection_threshold,
        receiver_noise_std=p.receiver_noise_std,
        range_min=p.range_min,
        range_max=p.range_max,
    )
    sensor = replace(sensor, **{k: v for k, v in changes.items() if v is not None})
    if sensor.detection_threshold <= 0 and changes.get("detection_threshold") is None:
        raise NidarError(
            f"the {preset} preset has no published detection threshold: give `threshold` "
            "(and `noise`), in raw units of gain 1 (1/m²)"
        )
    _check_sensor(sensor)
    return sensor


def _check_sensor(s: CloudSensor) -> None:
    checks = (
        ("wavelength", s.wavelength, 360.0 <= s.wavelength <= 1700.0, "in [360, 1700] nm"),
        ("threshold", s.detection_threshold, s.detection_threshold >= 0.0, ">= 0"),
        ("noise", s.receiver_noise_std, s.receiver_noise_std >= 0.0, ">= 0"),
        ("divergence", s.beam_divergence, 0.0 <= s.beam_divergence <= 100.0, "in [0, 100] mrad"),
        ("intensity_scale", s.intensity_scale, s.intensity_scale > 0.0, "> 0"),
    )
    for name, value, ok, why in checks:
        if not ok or not math.isfinite(value):
            raise NidarError(f"`{name}` must be {why} (got {value:g})")
    if s.intensity_mode not in INTENSITY_MODES:
        raise NidarError(f"`intensity_mode` must be one of {', '.join(INTENSITY_MODES)}")
    if s.return_mode not in RETURN_MODES:
        raise NidarError(f"`return_mode` must be one of {', '.join(RETURN_MODES)}")


def _conditioned_normals(clear, threshold: float, noise: float, u):
    """Standard normals truncated below at ``(T - E_c) / σ_n``: the receiver noise of returns
    known to have passed the threshold (inverse transform of ``u``)."""
    from scipy.special import ndtr, ndtri

    lo = ndtr((threshold - clear) / noise)
    return ndtri(np.clip(lo + u * (1.0 - lo), 1e-16, 1.0 - 1e-16))


def add_weather(points: dict, weather, sensor: CloudSensor, rng: np.random.Generator) -> dict:
    """The cloud in ``weather`` (module docstring).

    Args:
        points: a points dict (:mod:`nidar_mi.io.points`) with ``xyz`` (N, 3), in the sensor's
            frame, and ``intensity`` (N,); its other per-point columns are kept for the
            points that stay.
        weather: a :class:`nidar_mi.weather.Weather`, not clear.
        sensor: the sensor that recorded it.
        rng: the draws.

    Returns:
        The points that stay or moved, their ``intensity`` and ``xyz`` in weather, and
        ``scatterer`` (uint8, :data:`nidar_mi.weather.media.SCATTERERS`) with
        ``scatterer_names``.

    Raises:
        NidarError: no ``intensity`` column.
    """
    if "intensity" not in points:
        raise NidarError("the cloud has no intensity: the weather needs each return's strength")
    xyz = np.asarray(points["xyz"], dtype=np.float64)
    n = len(xyz)
    d = np.maximum(np.linalg.norm(xyz, axis=1), 1e-6)
    given = np.asarray(points["intensity"], dtype=np.float64)
    clear = (
        given / sensor.intensity_scale / (d * d if sensor.intensity_mode == "compensated" else 1.0)
    )
    model = weather_model(weather, sensor.terms())
    cands = candidates(model, d, device_tables(model, np), lambda: rng.random(n))
    hard, valid, output = _hard(clear, d, cands, model, sensor, rng)
    noise = sensor.receiver_noise_std
    normals = (lambda: rng.standard_normal(n)) if noise > 0 else (lambda: 0.0)
    gates = {"threshold": sensor.detection_threshold, "noise": noise}
    gates |= {"range_min": sensor.range_min, "range_max": sensor.range_max}
    more_valid, more_output = detect_candidates(cands, normals=normals, **gates)
    ranges = [d, *cands.range_m]
    pick = choose(sensor.return_mode, [valid, *more_valid], [output, *more_output], ranges)
    keep = pick >= 0
    rows = np.flatnonzero(keep)
    sel = pick[keep]

    def picked(values):
        return np.stack([np.broadcast_to(v, (n,)) for v in values], axis=1)[rows, sel]

    energy = picked([hard, *cands.energy])
    jitter = range_jitter(model, energy, np.where(sel == 0, clear[rows], np.inf))
    r = np.maximum(picked(ranges) + jitter * rng.standard_normal(rows.size), 0.0)
    out_i = picked([output, *more_output]) * sensor.intensity_scale
    if sensor.intensity_mode == "compensated":
        out_i = out_i * r * r
    ceiling = float(given.max(initial=0.0)) if n else 0.0
    out = {k: v[keep] for k, v in points.items() if _per_point(v, n)}
    out["xyz"] = (xyz[rows] * (r / d[rows])[:, None]).astype(np.float32)
    out["intensity"] = np.clip(out_i, 0.0, ceiling).astype(np.float32)
    out["scatterer"] = picked([0, *cands.scatterer]).astype(np.uint8)
    out |= {k: v for k, v in points.items() if not _per_point(v, n)}
    out["scatterer_names"] = np.asarray(SCATTERERS, dtype=np.str_)
    return out


def _hard(clear, d, cands: Candidates, model, sensor: CloudSensor, rng):
    """The points' own returns in weather: energy, detection (given their clear detection)
    and the receiver's output."""
    T, noise = sensor.detection_threshold, sensor.receiver_noise_std
    hard = clear * np.exp(-2.0 * model.alpha * d) * cands.occlusion
    if noise > 0:
        normal = _conditioned_normals(clear, T, noise, rng.random(len(d)))
        output = hard + noise * normal
        valid = output >= T
    else:  # detected in clear air: it was at least T
        hard = np.maximum(clear, T) * np.exp(-2.0 * model.alpha * d) * cands.occlusion
        output = hard
        valid = hard >= T
    return hard, valid & (d >= sensor.range_min) & (d <= sensor.range_max), output


def _per_point(value, n: int) -> bool:
    a = np.asarray(value)
    return a.ndim >= 1 and a.shape[0] == n and a.dtype.kind in "biuf"
