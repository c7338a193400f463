"""What the training scans saw, cast into the reconstructed surfaces: the samples the
inversion fits.

Every return of a training frame becomes a ray (:func:`.rays.return_rays`) cast into the
surfaces. It is an **intensity sample** when it lands on them where it was measured: the gap
across the surface ``|t - d| · max(|cos θ|, 0.05)`` at most :data:`ON_SURFACE_M`. Every beam of
the frame's coverage that returned nothing (:func:`.rays.miss_rays`) and hits the surfaces
within :data:`MISS_RANGE_M` is a **miss sample**; with the intensity samples they are the
**detection samples** (hit/miss) of the ray-drop fit. A miss sample is cast along the layout's
nominal direction for its cell, so it lands where the missing return would have been.

The samples keep what the surfaces' BSDF reads the reflectance through: the triangle hit and the
barycentric weights of its corners (Mitsuba's ``mesh_attribute`` texture interpolates the
per-vertex ``vertex_rho`` linearly with them), and the range and incidence cosine of the hit
from :func:`nidar_mi.lidar.raycast.monostatic_reflectance`.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from .beam_rays import Rays, concat

__all__ = ["Samples", "ON_SURFACE_M", "MISS_RANGE_M", "cast_samples"]

#: Largest gap across the surface (m) between a return and the surfaces for it to be a sample.
ON_SURFACE_M = 0.1
#: Misses are sampled where the beam meets the surfaces closer than this, m.
MISS_RANGE_M = 80.0


class Samples(NamedTuple):
    """The training samples, on the device (Dr.Jit) and on the host (NumPy).

    Attributes:
        beams: :class:`nidar_mi.lidar.raycast.Cast` of every sample ray (returns, then misses).
        ring: ``mi.UInt32`` (S,) the laser of each sample.
        corners: three ``mi.UInt32`` (S,) vertex indices of the triangle hit.
        weights: three ``mi.Float`` (S,) barycentric weights of those vertices.
        intensity: (S,) float32 measured intensity (NumPy; 0 for misses).
        detected: (S,) bool: a return (True) or a miss (False).
        frame: (S,) int frame index.
        range_m: (S,) float32 hit distance along the ray, m.
        cos: (S,) float32 |cos θ| at the hit (shading normal); cos_t the same on the device.
        rays: the host rays of the samples.
    """

    beams: Any
    ring: Any
    corners: Any
    weights: Any
    intensity: np.ndarray
    detected: np.ndarray
    frame: np.ndarray
    range_m: np.ndarray
    cos: np.ndarray
    cos_t: Any
    rays: Rays


def _select(r: Rays, keep: np.ndarray) -> Rays:
    return Rays(*(getattr(r, f)[keep] for f in Rays._fields))


def cast_samples(scene, faces, returns: Rays, intensity: np.ndarray, misses: Rays) -> Samples:
    """The samples of the training rays (module docstring).

    Args:
        scene: the surfaces (:func:`.surfaces.surface_scene`).
        faces: (T, 3) the surfaces' triangles (vertex indices, in the scene's order).
        returns: the returns' rays; intensity: (N,) their measured intensity.
        misses: the beams without a return.
    """
    import drjit as dr
    import mitsuba as mi

    from ..lidar.raycast import cast, monostatic_reflectance
    from .beam_rays import jit_rays
    from .carve import across_gap, hit_depths

    t, _, cos = hit_depths(scene, returns)
    on = np.isfinite(t) & (np.abs(across_gap(returns.range_m, t, cos)) <= ON_SURFACE_M)
    tm, _, _ = hit_depths(scene, misses)
    seen = np.isfinite(tm) & (tm <= MISS_RANGE_M)
    rays = concat([_select(returns, on), _select(misses, seen)])
    y = np.concatenate([np.asarray(intensity)[on], np.zeros(int(seen.sum()))]).astype(np.float32)
    detected = np.concatenate([np.ones(int(on.sum()), bool), np.zeros(int(seen.sum()), bool)])
    wl = mi.Float(905.0)
    beams = cast(scene, jit_rays(rays), wl)
    _, cos_t, _ = monostatic_reflectance(beams, wl)
    dr.eval(beams, cos_t)
    prim = beams.si.prim_index.numpy().astype(np.int64)
    uv = np.asarray(beams.si.uv.numpy(), dtype=np.float64).reshape(2, -1)
    corner = np.asarray(faces)[prim].astype(np.uint32)
    bary = (1.0 - uv[0] - uv[1], uv[0], uv[1])
    return Samples(
        beams=beams,
        ring=mi.UInt32(rays.ring.astype(np.uint32)),
        corners=tuple(mi.UInt32(corner[:, k]) for k in range(3)),
        weights=tuple(mi.Float(w.astype(np.float32)) for w in bary),
        intensity=y,
        detected=detected,
        frame=rays.frame,
        range_m=beams.path_m.numpy().astype(np.float32),
        cos=cos_t.numpy().astype(np.float32),
        cos_t=cos_t,
        rays=rays,
    )
