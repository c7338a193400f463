"""Moving objects out of the fused surfaces: the surfaces that consecutive training frames saw
through are transient.

Fusion (:mod:`.mesh`) keeps every surface that any training scan saw, and carving
(:mod:`.carve`) weighs all the frames' first hits together: a vehicle that stood beside the road
for the first half of a drive and left in the second is seen *on* by about as many rays as pass
*through* where it stood, and stays, hiding from every later view what stands behind it; one
that crept forward leaves a stack of layers, of which carving sees only the front one. Here
every ray is followed through each triangle it passes through to the next
(:func:`.carve.layered_hits`, the carving's per-hit tests), each hit counts for the triangle's
three corners, and the evidence is kept per frame: a frame that observes a vertex votes *on*
(more of its hits end on the vertex's triangles than pass through them) or *through* (the
reverse). A static surface is seen on by the frames that observe it, bar a stray ray; a surface
that was there and then left is seen through by every frame after it left (one that came, by
every frame before it came). A vertex is transient when the frames that observe it, in time
order, end with at least ``run`` consecutive *through* votes: the views after it left agree
that the space is empty, where a stretch of stray *through* votes between *on* votes
(neighbouring frames see alike, so the stray ones come in runs) says nothing. A surface that
came during the drive (its votes start *through*) is kept: it stands at the drive's end and
past it, where the re-simulated views go; counting those runs too removed static surfaces
(docs/RESIMULATION.md, step 4). A triangle
is transient when its three corners are. Removing one can expose another behind it that no ray
reached, so the test repeats until nothing is removed (at most ``passes`` rounds). What the
removed surfaces hid, the later frames saw, and the fusion already holds it.
"""

from __future__ import annotations

import numpy as np

from .beam_rays import Rays
from .carve import layered_hits
from .mesh import Mesh, compact

__all__ = [
    "frame_votes",
    "end_through_run",
    "transient_faces",
    "remove_transient",
    "RUN_FRAMES",
]

#: Consecutive observing frames that must see through a vertex for it to be transient.
RUN_FRAMES = 3
#: Transient corners that make a triangle transient.
CORNERS = 3


def frame_votes(prim, frame, through, on):
    """Per (element, frame) pair that observed it: the frame's vote.

    Args:
        prim: (N,) each hit's element, a triangle or a vertex (-1: none); frame: (N,) the
        hit's frame index (time order); through, on: (N,) bool per hit
        (:func:`.carve.hit_classes`).

    Returns:
        ``(elem, frm, vote)``: (P,) sorted by element then frame; vote +1 on, -1 through
        (ties, where as many hits end on it as pass through, are left out).
    """
    sel = (prim >= 0) & (through | on)
    n_frames = int(frame.max(initial=0)) + 1
    key = prim[sel].astype(np.int64) * n_frames + frame[sel]
    pairs, inv = np.unique(key, return_inverse=True)
    diff = np.bincount(inv, weights=on[sel]) - np.bincount(inv, weights=through[sel])
    vote = np.sign(diff).astype(np.int64)
    keep = vote != 0
    return pairs[keep] // n_frames, pairs[keep] % n_frames, vote[keep]


def end_through_run(elem, vote, n: int) -> np.ndarray:
    """(n,) the run of consecutive *through* votes that ends each element's votes (sorted by
    element, then time, as :func:`frame_votes` gives them): the frames after it left; 0 where
    its last vote is *on*."""
    run = np.zeros(n, dtype=np.int64)
    if len(elem) == 0:
        return run
    start = np.concatenate([[True], (elem[1:] != elem[:-1]) | (vote[1:] != vote[:-1])])
    length = np.bincount(np.cumsum(start) - 1)
    first = np.flatnonzero(start)
    owner = elem[first]
    new = np.concatenate([[True], owner[1:] != owner[:-1]])
    at_end = np.concatenate([new[1:], [True]])  # an element's last run
    ok = (vote[first] < 0) & at_end
    np.maximum.at(run, owner[ok], length[ok])
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
        run: consecutive *through* frames that make a vertex transient.
        passes: the most rounds (each exposes what the last one removed hid).
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
        mesh: the surfaces; prim, frame, through, on: (H,) per hit (:func:`.carve.layered_hits`,
        the frame of each hit's ray); run: consecutive *through* frames that make a vertex
        transient.
    """
    hit = prim >= 0
    corners = mesh.faces[prim[hit]].ravel()
    vtx, _, vote = frame_votes(
        corners, np.repeat(frame[hit], 3), np.repeat(through[hit], 3), np.repeat(on[hit], 3)
    )
    transient = end_through_run(vtx, vote, len(mesh.vertices)) >= run
    return transient[mesh.faces].sum(axis=1) >= CORNERS
