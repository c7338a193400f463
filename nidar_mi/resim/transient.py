"""Moving objects out of the fused surfaces: a triangle that the training frames of a stretch of
time saw through is transient.

Fusion (:mod:`.mesh`) keeps every surface that any training scan saw, and carving
(:mod:`.carve`) weighs all the frames' rays together: a car parked beside the road for the first
half of a drive and gone in the second is seen *on* by as many rays as pass *through* where it
stood, and stays, hiding from every later view what stands behind it. Here the evidence is kept
per frame: each frame that observes a triangle votes *on* (more of its rays end on the triangle
than pass through it) or *through* (the reverse; the same per-ray tests as carving,
:func:`.carve.hit_classes`). A static surface is seen on by the frames that observe it, bar a
stray ray; a surface that was there and then left is seen through by every frame after it left.
A triangle is removed when the frames that observe it, in time order, include a run of at least
``run`` consecutive *through* votes: consecutive views agree that the space is empty. Removal
uncovers the surfaces behind, which the later frames saw and the fusion already holds.
"""

from __future__ import annotations

import numpy as np

from .beam_rays import Rays
from .carve import layered_hits
from .mesh import Mesh, compact

__all__ = [
    "frame_votes",
    "longest_through_run",
    "transient_faces",
    "remove_transient",
    "RUN_FRAMES",
]

#: Consecutive observing frames that must see through a vertex for it to be transient.
RUN_FRAMES = 3
#: Transient corners that make a triangle transient.
CORNERS = 3


def frame_votes(prim, frame, through, on):
    """Per (triangle, frame) pair that observed it: the frame's vote.

    Args:
        prim: (N,) each ray's triangle (-1: none); frame: (N,) its frame index (time order);
        through, on: (N,) bool per ray (:func:`.carve.hit_classes`).

    Returns:
        ``(tri, frm, vote)``: (P,) sorted by triangle then frame; vote +1 on, -1 through (ties,
        where as many rays end on it as pass through, are left out).
    """
    sel = (prim >= 0) & (through | on)
    n_frames = int(frame.max(initial=0)) + 1
    key = prim[sel].astype(np.int64) * n_frames + frame[sel]
    pairs, inv = np.unique(key, return_inverse=True)
    diff = np.bincount(inv, weights=on[sel]) - np.bincount(inv, weights=through[sel])
    vote = np.sign(diff).astype(np.int64)
    keep = vote != 0
    return pairs[keep] // n_frames, pairs[keep] % n_frames, vote[keep]


def longest_through_run(tri, vote, n_faces: int) -> np.ndarray:
    """(n_faces,) the longest run of consecutive *through* votes of each triangle (votes sorted
    by triangle, then time, as :func:`frame_votes` gives them)."""
    run = np.zeros(n_faces, dtype=np.int64)
    if len(tri) == 0:
        return run
    start = np.concatenate([[True], (tri[1:] != tri[:-1]) | (vote[1:] != vote[:-1])])
    run_id = np.cumsum(start) - 1
    length = np.bincount(run_id)
    first = np.flatnonzero(start)
    through = vote[first] < 0
    np.maximum.at(run, tri[first][through], length[through])
    return run


def remove_transient(
    mesh: Mesh,
    rays: Rays,
    load_scene,
    *,
    run: int = RUN_FRAMES,
    passes: int = 8,
    through_m: float = 0.1,
):
    """The mesh without its transient triangles (module docstring).

    Args:
        mesh: the fused, carved mesh (world coordinates).
        rays: the training returns' rays, ``rays.frame`` in time order.
        load_scene: ``load_scene(mesh) -> mi.Scene`` of the mesh alone.
        run: consecutive *through* frames that make a triangle transient.
        passes: rounds (each uncovers the layers behind what the last removed).
        through_m: the gap across the surface that counts as passing through, m.

    Returns:
        ``(mesh, removed)``: the mesh and how many triangles each round removed.
    """
    removed = []
    for _ in range(passes):
        ray, prim, through, on = layered_hits(mesh, rays, load_scene, through_m=through_m)
        drop = transient_faces(mesh, prim, rays.frame[ray], through, on, run=run)
        removed.append(int(drop.sum()))
        if not drop.any():
            break
        mesh = Mesh(mesh.vertices, mesh.faces[~drop])
    return compact(mesh), removed


def transient_faces(mesh: Mesh, prim, frame, through, on, *, run: int = RUN_FRAMES):
    """(T,) bool: the triangles whose corners are all transient (module docstring).

    Args:
        mesh: the surfaces; prim, frame, through, on: (N,) per ray, as :func:`frame_votes`
        takes them; run: consecutive *through* frames that make a vertex transient.
    """
    hit = prim >= 0
    corners = mesh.faces[prim[hit]].ravel()
    vtx, _, vote = frame_votes(
        corners, np.repeat(frame[hit], 3), np.repeat(through[hit], 3), np.repeat(on[hit], 3)
    )
    transient = longest_through_run(vtx, vote, len(mesh.vertices)) >= run
    return transient[mesh.faces].sum(axis=1) >= CORNERS
