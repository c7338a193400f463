"""Lighting regimes of generated scenes: the layout's own sun and sky, or a wider draw.

``default`` keeps the sun and sky that the layout drew (:func:`.layout.sample_light`). ``varied``
redraws them from a stream of their own, ``SeedSequence(seed, spawn_key=(k, 1))``, so that the
shapes, materials and rig of scene ``k`` stay those of the ``default`` regime and only the light
changes (deterministic per seed and scene): a quarter of the scenes are overcast (a sun at
2-8 % of its clear-sky irradiance, a sky 2-4 times brighter than the standard diffuse one, soft
shadows), the others sunny with the sun anywhere from 6 to 80 degrees above the horizon, any
azimuth, irradiance x0.3-1.3 and sky x0.3-1.8 (hard shadows, long ones at low sun).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import NidarError
from .objects import rnd
from .primitives import Layout, Sky, Sun

__all__ = ["LIGHTING_REGIMES", "OVERCAST_FRACTION", "relight", "sample_varied_light"]

#: The lighting regimes of :func:`relight`.
LIGHTING_REGIMES = ("default", "varied")
#: Share of overcast scenes in the ``varied`` regime.
OVERCAST_FRACTION = 0.25


def sample_varied_light(rng: np.random.Generator) -> tuple[Sun, Sky]:
    """A sun and sky of the ``varied`` regime (module docstring)."""
    overcast = rng.uniform() < OVERCAST_FRACTION
    elevation = rng.uniform(25.0, 80.0) if overcast else rng.uniform(6.0, 80.0)
    azimuth = rng.uniform(0.0, 360.0)
    if overcast:
        sun_scale, sky_scale = rng.uniform(0.02, 0.08), rng.uniform(2.0, 4.0)
    else:
        sun_scale, sky_scale = rng.uniform(0.3, 1.3), rng.uniform(0.3, 1.8)
    sun = Sun(elevation_deg=rnd(elevation, 2), azimuth_deg=rnd(azimuth, 2), scale=rnd(sun_scale))
    return sun, Sky(scale=rnd(sky_scale))


def relight(layout: Layout, seed: int, k: int, lighting: str = "default") -> Layout:
    """Scene ``k`` of run ``seed`` under the lighting regime ``lighting``.

    Raises:
        NidarError: an unknown regime.
    """
    if lighting not in LIGHTING_REGIMES:
        raise NidarError(
            f"lighting must be one of {', '.join(LIGHTING_REGIMES)} (got {lighting!r})"
        )
    if lighting == "default":
        return layout
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(k, 1)))
    sun, sky = sample_varied_light(rng)
    return dataclasses.replace(layout, sun=sun, sky=sky)
