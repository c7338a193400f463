"""Free-space carving: the triangles a training ray passed through are removed.

A return at range ``d`` along a ray says the space before it is empty. A triangle that the ray
hits at ``t`` well before ``d`` is therefore wrong for that view: a skirt that a single-scan mesh
stretched across a depth discontinuity, a car that has since moved, a misplaced layer. The hit
counts as *through* when ``(d - t) · max(|cos θ|, 0.05) > through_m`` (the gap measured across
the surface, so that a grazing hit on the road, where a centimetre of height is a metre of
range, is not taken for a hole) and ``d - t > 0.3`` m; as *on* when ``|d - t| · max(|cos θ|,
0.05) <= through_m``. A triangle with at least two *through* hits and more *through* than *on*
hits is removed; removing it uncovers what was behind, so carving repeats ``passes`` times.
"""

from __future__ import annotations

import numpy as np

from .beam_rays import Rays, jit_rays
from .mesh import Mesh, compact

__all__ = ["across_gap", "carve", "carved_faces", "hit_classes", "hit_depths", "layered_hits"]

#: Rays cast per Dr.Jit launch.
BLOCK = 1 << 20


def hit_depths(scene, rays: Rays):
    """Cast ``rays`` into ``scene``.

    Returns:
        ``(t, prim, cos)``: (N,) hit distance (inf: none), triangle index (-1: none), |cos θ|
        of the hit (geometric normal).
    """
    import drjit as dr

    t, prim, cos = [], [], []
    for start in range(0, len(rays.range_m), BLOCK):
        ray = jit_rays(rays, start, start + BLOCK)
        si = scene.ray_intersect(ray)
        valid = si.is_valid()
        c = dr.abs(dr.dot(si.n, ray.d))
        dr.eval(si.t, si.prim_index, c, valid)
        v = valid.numpy()
        t.append(np.where(v, si.t.numpy(), np.inf))
        prim.append(np.where(v, si.prim_index.numpy().astype(np.int64), -1))
        cos.append(np.where(v, c.numpy(), 0.0))
    if not t:
        return np.zeros(0), np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(t), np.concatenate(prim), np.concatenate(cos)


def across_gap(range_m, t, cos):
    """(N,) how far a return at ``range_m`` lies beyond its ray's hit at ``t`` (negative: in
    front of it), measured across the hit surface: ``(range_m − t) · max(|cos θ|, 0.05)``, so
    that a grazing hit on the road, where a centimetre of height is a metre of range, is no
    gap; m."""
    return (np.asarray(range_m, np.float64) - t) * np.maximum(cos, 0.05)


def _classes(range_m, t, prim, cos, through_m: float):
    """(N,) bools: the hit passed *through* its triangle; the ray ended *on* it."""
    gap = across_gap(range_m, t, cos)
    hit = prim >= 0
    through = hit & (gap > through_m) & (range_m - t > 0.3)
    return through, hit & (np.abs(gap) <= through_m)


def hit_classes(mesh: Mesh, rays: Rays, load_scene, through_m: float = 0.1):
    """Each ray's first triangle and whether it passed through it or ended on it.

    Returns:
        ``(prim, through, on)``: (N,) triangle index (-1: no hit) and two (N,) bools (module
        docstring).
    """
    t, prim, cos = hit_depths(load_scene(mesh), rays)
    return (prim, *_classes(rays.range_m, t, prim, cos, through_m))


def layered_hits(mesh: Mesh, rays: Rays, load_scene, *, through_m: float = 0.1, layers: int = 16):
    """Every triangle each ray meets before it ends: its first hit and, past each hit it
    passed *through*, the next one, up to ``layers`` hits per ray.

    Returns:
        ``(ray, prim, through, on)``: (H,) per hit the ray's index, the triangle (-1: none) and
        the two classes of :func:`hit_classes`.
    """
    scene = load_scene(mesh)
    idx, sub, out = np.arange(len(rays.range_m)), rays, []
    for _ in range(layers):
        t, prim, cos = hit_depths(scene, sub)
        through, on = _classes(sub.range_m, t, prim, cos, through_m)
        out.append((idx, prim, through, on))
        if not through.any():
            break
        step = t[through] + 1e-3  # just past the surface passed through
        sub = Rays(
            sub.origin[through] + sub.direction[through] * step[:, None],
            sub.direction[through],
            sub.range_m[through] - step,
            sub.ring[through],
            sub.frame[through],
        )
        idx = idx[through]
    return tuple(np.concatenate(a) for a in zip(*out))


def carve(mesh: Mesh, rays: Rays, load_scene, *, through_m: float = 0.1, passes: int = 2):
    """The mesh without the triangles the rays passed through (module docstring).

    Args:
        mesh: the fused mesh (world coordinates).
        rays: the training returns' rays (finite ranges).
        load_scene: ``load_scene(mesh) -> mi.Scene`` of the mesh alone.
        through_m: the gap across the surface that counts as passing through, m.
        passes: carving rounds.

    Returns:
        ``(mesh, removed)``: the carved mesh and how many triangles each pass removed.
    """
    keep, removed = carved_faces(mesh, rays, load_scene, through_m=through_m, passes=passes)
    return compact(Mesh(mesh.vertices, mesh.faces[keep])), removed


def carved_faces(mesh: Mesh, rays: Rays, load_scene, *, through_m: float = 0.1, passes: int = 2):
    """:func:`carve` as ``(keep, removed)``: (T,) bool, the triangles of ``mesh`` it keeps."""
    keep = np.ones(len(mesh.faces), bool)
    removed = []
    for _ in range(passes):
        idx = np.flatnonzero(keep)
        prim, through, on = hit_classes(
            Mesh(mesh.vertices, mesh.faces[idx]), rays, load_scene, through_m
        )
        n_through = np.bincount(prim[through], minlength=len(idx))
        n_on = np.bincount(prim[on], minlength=len(idx))
        drop = (n_through >= 2) & (n_through > n_on)
        removed.append(int(drop.sum()))
        if not drop.any():
            break
        keep[idx[drop]] = False
    return keep, removed
