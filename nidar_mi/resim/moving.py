"""Surfaces that moved, at a held-out frame's time: what the training frame nearest in time saw
and the static surfaces lack.

The reconstructed surfaces are static (:mod:`.build`): a vehicle that moved during the drive is
left out (:mod:`.transient`) or kept where it stood at the drive's end. A held-out frame inside
the drive sees it where it was *then*. The training frame nearest in time (ties: the earlier
one) saw it nearly there, so its returns that the static surfaces do not explain are put back,
for that held-out frame only, as a mesh of their own (:func:`moving_surfaces`). A return is
explained when its ray, cast into the static surfaces, ends on them where it was measured: the
gap across the surface ``|t - d| · max(|cos θ|, 0.05)`` at most
:data:`~.observations.ON_SURFACE_M`, the rule that makes a return an intensity sample of the
inversion. The moving mesh is that frame's range-image mesh (:func:`.mesh.scan_triangles`) on
the unexplained returns (a triangle whose three corners are unexplained), in world coordinates.

Its reflectance is each vertex's own return inverted through the recovered sensor
(:func:`moving_rho`): the sensor reports ``max(G_l · ρ · cos θ · r(d) - b, 0)``
(:mod:`.inversion`), so ``ρ = (y + b) / (G_l · r(d) · cos θ)`` (no lower than the sensor
detects: :meth:`.inversion.SensorFit.reflectance_of`), with ``cos θ`` taken on the
vertex normal Mitsuba computes for the mesh (the normal the renderer shades the vertex with:
re-scanned from where it was measured, the vertex gives back its return's intensity).
Casting each return into the mesh, as the inversion's samples are cast, would lose about a
quarter of them: a ray through a mesh's vertex may pass between its triangles.

This is the zero-order model of motion (a surface is where it was last or next seen); it adds
nothing where nothing moved, and nothing past the drive's end, where the static surfaces
already hold what the last frames saw.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .beam_rays import Rays
from .mesh import Mesh, scan_triangles
from .observations import ON_SURFACE_M

__all__ = [
    "MovingSurfaces",
    "nearest_frame",
    "unexplained_returns",
    "moving_surfaces",
    "moving_rho",
]


@dataclass(frozen=True)
class MovingSurfaces:
    """The moving surfaces put back for one held-out frame.

    Attributes:
        frame: the index of the training frame they come from.
        mesh: the mesh, world coordinates (m); empty when the frame saw nothing moving.
        returns: (V,) int64, each vertex's return in that frame's scan.
    """

    frame: int
    mesh: Mesh
    returns: np.ndarray


def nearest_frame(k: int, train) -> int:
    """The training frame index nearest to frame index ``k`` in time (ties: the earlier)."""
    train = list(train)
    if not train:
        raise ValueError("nearest_frame: no training frame")
    return min(train, key=lambda j: (abs(j - k), j))


def unexplained_returns(t: np.ndarray, cos: np.ndarray, range_m: np.ndarray) -> np.ndarray:
    """(N,) bool: returns that the static surfaces do not explain (module docstring).

    Args:
        t: (N,) each return's ray's first hit on the static surfaces, m (inf: none);
        cos: (N,) ``|cos θ|`` there; range_m: (N,) the measured range along the ray, m.
    """
    gap = np.abs(np.asarray(range_m, np.float64) - t) * np.maximum(cos, 0.05)
    return ~(np.isfinite(t) & (gap <= ON_SURFACE_M))


def moving_surfaces(xyz: np.ndarray, grid, rays: Rays, static_scene, frame: int, *, wrap: bool):
    """The :class:`MovingSurfaces` of one training frame.

    Args:
        xyz: (N, 3) the frame's returns, LiDAR frame, m; grid: their cells
            (:class:`.range_image.ScanGrid`).
        rays: the returns' rays in world coordinates (:func:`.beam_rays.return_rays`), in the
            order of ``xyz``.
        static_scene: the static surfaces (a ``mi.Scene``).
        frame: the frame's index; wrap: its scans are full revolutions.
    """
    from .carve import hit_depths

    t, _, cos = hit_depths(static_scene, rays)
    free = unexplained_returns(t, cos, rays.range_m)
    tris = scan_triangles(xyz, grid, wrap=wrap)
    tris = tris[free[tris].all(axis=1)] if len(tris) else tris.reshape(0, 3)
    used = np.unique(tris)
    remap = np.full(len(xyz), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    world = rays.origin[used] + rays.direction[used] * rays.range_m[used, None]
    return MovingSurfaces(frame, Mesh(world, remap[tris]), used.astype(np.int64))


def moving_rho(
    moving: MovingSurfaces, rays: Rays, intensity: np.ndarray, sensor, load_scene
) -> np.ndarray:
    """(V,) the moving vertices' ρ from their own returns (module docstring), in
    [0, RHO_MAX].

    Args:
        moving: the surfaces; rays: the frame's return rays (world), in the order of its scan;
        intensity: (N,) the frame's measured intensities; sensor: the recovered
            :class:`.inversion.SensorFit` (gains, range response, offset);
        load_scene: ``load_scene(mesh) -> mi.Scene`` of a mesh alone
            (:func:`.build.scratch_scene`), whose vertex normals the renderer shades with.
    """
    import mitsuba as mi

    from .surfaces import SHAPE_ID

    idx = moving.returns
    if len(moving.mesh.faces) == 0:
        return np.zeros(len(idx))
    params = mi.traverse(load_scene(moving.mesh))
    normals = np.asarray(params[f"{SHAPE_ID}.vertex_normals"].numpy(), np.float64).reshape(-1, 3)
    cos = np.abs(np.einsum("ij,ij->i", normals, rays.direction[idx]))
    y = np.asarray(intensity, np.float64)[idx]
    return sensor.reflectance_of(y, rays.ring[idx], rays.range_m[idx], cos)
