"""Non-repetitive (rosette) scan patterns of Risley-prism LiDARs (Livox Mid-40 style).

One laser looks along +x through two wedge prisms that turn about the x axis at different,
incommensurable rates; the beam leaving them sweeps a rosette that never closes, so the area
it covers grows with the integration time instead of repeating every sweep.

Each prism is a wedge of apex angle ``α`` and refractive index ``n``: the beam enters through its
inclined face, whose normal is tilted by ``α`` from the axis towards the prism's current angle
``φ(t) = 2π f t`` (``(cos α, sin α cos φ, sin α sin φ)``), and leaves through its flat face
(normal +x). Each of the four faces refracts the beam by Snell's law in vector form
(``t = η i + (η cos θ_i - cos θ_t) N``, ``η = n_1 / n_2``); no paraxial approximation. With the
Mid-40's prisms (below) both aligned, the beam leaves 19.16° off the axis: a 38.32° circular
field of view, the datasheet's 38.4°; with them opposed, 0.01° (the petals pass through the
centre).

:class:`nidar_mi.lidar.pattern.RisleyPattern` makes a sweep of these beams. Shots are evenly
spaced in time: column ``j`` of a sweep of ``C`` columns at ``rotation_rate``
sweeps per second fires at ``t_j = j / (C · rotation_rate)`` after the sweep's start, so
``C · rotation_rate`` is the point rate (the Mid-40's 100,000 points/s: 10,000 columns at 10 Hz,
or 100,000 at 1 Hz for a one-second integration). Every sweep starts with the prisms at angle 0:
a longer integration time is a slower ``rotation_rate`` with more columns.

Prism parameters of the ``livox_mid40`` preset, from the Livox Mid-40 scanner of HELIOS++
(3dgeo-heidelberg/helios @ fd94d1ff5d9e8bfe3089b936bd5b4d935dbfed63,
``python/pyhelios/data/scanners_tls.xml``, scanner ``livox_mid-40``; last changed in
cbb28ba2b003ac11173319dc69a0685e8640cbf1): wedge angles 18.7481° and 17.9634°, refractive index
1.51 (both), rotation rates -121.5657 Hz and 77.7430 Hz (-7294 and 4665 rpm). The Risley-prism
model of the Mid-40: Brazeal, Wilkinson and Hochmair, "A Rigorous Observation Model for the
Risley Prism-Based Livox Mid-40 Lidar Sensor", Sensors 21(14):4722, 2021.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RisleyPrisms", "MID40_PRISMS"]


def _refract(incident: np.ndarray, normal: np.ndarray, eta: float) -> np.ndarray:
    """(n, 3) directions refracted at surfaces of (n, 3) unit ``normal`` (either side), from
    index ``n_1`` into ``n_2`` with ``eta = n_1 / n_2``. Total internal reflection does not
    occur for the wedges here (the caller checks the result is finite)."""
    side = np.sign(np.sum(normal * incident, axis=-1, keepdims=True))
    n = -normal * np.where(side == 0.0, 1.0, side)
    cos_i = -np.sum(n * incident, axis=-1, keepdims=True)
    cos_t = np.sqrt(1.0 - eta**2 * (1.0 - cos_i**2))
    return eta * incident + (eta * cos_i - cos_t) * n


@dataclass(frozen=True)
class RisleyPrisms:
    """Two wedge prisms turning about +x in front of one laser (module docstring).

    Attributes:
        wedge_deg: apex angle of each prism, degrees (the first is nearer the laser).
        refractive_index: of each prism's glass.
        rotation_hz: each prism's rotation rate, turns per second (signed: + turns its tilt
            from +y towards +z).
        source: where the parameters come from.
    """

    wedge_deg: tuple[float, float]
    refractive_index: tuple[float, float]
    rotation_hz: tuple[float, float]
    source: str

    def directions(self, t: np.ndarray) -> np.ndarray:
        """(n, 3) float64 unit beam directions at times ``t`` (s; (n,)), in the sensor frame."""
        t = np.asarray(t, dtype=np.float64)
        axis = np.zeros((t.size, 3))
        axis[:, 0] = 1.0
        d = axis.copy()
        for alpha, n, f in zip(self.wedge_deg, self.refractive_index, self.rotation_hz):
            a, phi = np.radians(alpha), 2.0 * np.pi * f * t
            tilted = np.stack(
                [np.full_like(phi, np.cos(a)), np.sin(a) * np.cos(phi), np.sin(a) * np.sin(phi)],
                axis=-1,
            )
            d = _refract(d, tilted, 1.0 / n)  # into the glass through the inclined face
            d = _refract(d, axis, n)  # out through the flat face
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def half_angle_deg(self) -> float:
        """Largest angle of the beam from the axis (both prisms aligned), degrees."""
        d = RisleyPrisms(self.wedge_deg, self.refractive_index, (0.0, 0.0), self.source)
        return float(np.degrees(np.arccos(d.directions(np.zeros(1))[0, 0])))


MID40_PRISMS = RisleyPrisms(
    wedge_deg=(18.7481, 17.9634),
    refractive_index=(1.51, 1.51),
    rotation_hz=(-121.5657, 77.7430),
    source="HELIOS++ scanners_tls.xml livox_mid-40 (3dgeo-heidelberg/helios @ fd94d1f)",
)
