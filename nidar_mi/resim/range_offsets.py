"""Each laser's range offset: what it adds to every range it reports, recovered from the
training scans, taken out of their returns before the surfaces are built and put back into
the recovered sensor (the ``lidar`` plugin's ``laser_range_offsets``).

A multi-beam sensor's lasers each time their pulses through their own electronics; the
factory's per-laser distance correction leaves a part, so one surface seen by two lasers sits
at two depths (per-beam range calibration, Levinson and Thrun, "Unsupervised Calibration for
Multi-beam Lasers", ISER 2010). On KITTI's HDL-64E what is left is about 2 cm (standard
deviation over the 64 lasers), the same lasers off the same way on different drives
(docs/RESIMULATION.md, step 10). Left in, the fused surfaces are as thick as the spread, and a
re-simulated scan puts every laser's returns on that average surface.

Fit (:func:`fit_range_offsets`): the training scans are meshed and fused
(:func:`.mesh.scan_triangles`, :func:`.mesh.fuse_meshes`: no carving) and every return's ray is
cast into that mesh; a return that lands within :data:`GATE_M` of its hit, at ``|cos θ| >=``
:data:`MIN_COS` (within 45° of the surface's normal), says ``d - t`` of its laser, and each
laser's offset is the median of what its returns say (:func:`laser_medians`, the lasers'
weighted mean taken out: the fused surfaces stay where the lasers put them on average). At
grazing incidence the ridges that the offsets themselves leave in the fused mesh move the hit
along the ray: on the rendered drive of :mod:`.synthetic` a laser that sees the road at
``cos θ = 0.22`` and little else came back 62 mm off with 0.3 as the bound, 8 mm with 0.7
(the bound chosen there and on the room of ``tests/resim/test_range_offsets.py``, before any
real drive was run with it; with no offsets in the renderer two lasers beside it come back 5
and 9 mm off, the others within 0.5 mm). Leaving out the hits on the mesh's creases, as the
inversion's sensor samples do, takes those two to 0 there, but a real drive's fused mesh is
rough: it left 37 of ``r0064``'s 64 lasers with too few returns, and was not kept. The fused
mesh holds each return itself (its vertices are means over 0.1 m cubes), so one round finds
part of the offset; the returns are corrected (:func:`corrected_returns`: ``d - o_r`` along
each return's ray) and the fit repeated, :data:`ROUNDS` rounds. At most :data:`MAX_FRAMES`
training frames, evenly spread, take part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .beam_rays import return_rays
from .drive_folder import evenly_spread
from .frames import Frames

__all__ = [
    "RangeOffsets",
    "GATE_M",
    "MIN_COS",
    "ROUNDS",
    "MAX_FRAMES",
    "laser_medians",
    "corrected_returns",
    "corrected_frames",
    "fit_range_offsets",
]

#: A return speaks for its laser's offset when it lands within this of its hit, m.
GATE_M = 0.15
#: ... and meets the surface at |cos θ| at least this (module docstring).
MIN_COS = 0.7
#: Fewest returns a laser needs for an offset of its own (else 0).
MIN_RETURNS = 100
#: Rounds of fit and correction.
ROUNDS = 3
#: The most training frames the fit reads.
MAX_FRAMES = 16


@dataclass(frozen=True)
class RangeOffsets:
    """The recovered offsets and the fit's record.

    Attributes:
        offsets_m: (R,) each laser's range offset o_r, m (its returns report ``d + o_r``).
        steps_sd_m: per round the standard deviation of that round's step over the lasers, m.
        returns: per laser the returns that spoke for it in the last round.
        frames: the training frames read.
    """

    offsets_m: np.ndarray
    steps_sd_m: tuple[float, ...]
    returns: np.ndarray
    frames: int

    def summary(self) -> dict:
        """JSON-safe, for ``report.json``."""
        return {
            "offsets_m": np.round(self.offsets_m, 5).tolist(),
            "sd_m": float(np.std(self.offsets_m)),
            "steps_sd_m": [round(s, 5) for s in self.steps_sd_m],
            "returns": self.returns.tolist(),
            "frames": self.frames,
        }


def laser_medians(
    residual: np.ndarray, ring: np.ndarray, rings: int, min_returns: int = MIN_RETURNS
) -> tuple[np.ndarray, np.ndarray]:
    """``(offsets, counts)``: (rings,) each laser's median ``residual`` (0 with fewer than
    ``min_returns``), less their mean weighted by the counts; (rings,) the counts."""
    residual = np.asarray(residual, dtype=np.float64)
    ring = np.asarray(ring, dtype=np.int64)
    counts = np.bincount(ring, minlength=rings)
    out = np.zeros(rings)
    order = np.argsort(ring, kind="stable")
    starts = np.concatenate([[0], np.cumsum(counts)])
    for r in np.flatnonzero(counts >= min_returns):
        out[r] = np.median(residual[order[starts[r] : starts[r + 1]]])
    used = counts >= min_returns
    if used.any():
        out[used] -= np.average(out[used], weights=counts[used])
    return out, counts


def corrected_returns(xyz: np.ndarray, grid, layout, offsets: np.ndarray) -> np.ndarray:
    """(N, 3) the returns ``xyz`` (LiDAR frame, m; cells ``grid``) with each laser's offset
    taken out along its ray: the point at ``d - o_r`` from the laser's origin."""
    rays = return_rays(xyz, grid, layout, np.eye(4), 0)
    d = rays.range_m - np.asarray(offsets, dtype=np.float64)[grid.ring]
    return rays.origin + rays.direction * d[:, None]


def corrected_frames(frames: Frames, train, offsets: np.ndarray | None) -> Frames:
    """``frames`` with the returns of the training frames ``train`` (indices) corrected
    (:func:`corrected_returns`); the held-out frames' returns are left as measured."""
    from dataclasses import replace

    if offsets is None:
        return frames
    xyz = list(frames.xyz)
    for k in train:
        xyz[k] = corrected_returns(frames.xyz[k], frames.grid[k], frames.layout, offsets)
    return replace(frames, xyz=xyz)


def _round_residuals(frames: Frames, poses, idx, offsets, load, voxel_m: float):
    """``(residual, ring)`` of one round: the corrected returns of frames ``idx`` cast into
    their fused mesh (module docstring)."""
    from .carve import hit_depths
    from .mesh import Mesh, compact, fuse_meshes, scan_triangles

    xyz = {k: corrected_returns(frames.xyz[k], frames.grid[k], frames.layout, offsets) for k in idx}
    meshes = []
    for k in idx:
        tris = scan_triangles(xyz[k], frames.grid[k], wrap=not frames.cut)
        meshes.append(compact(Mesh(xyz[k], tris)).transformed(poses[k]))
    fused = fuse_meshes(meshes, voxel_m)
    if len(fused.faces) == 0:  # nothing to cast into: no laser speaks (the surfaces step says why)
        return np.zeros(0), np.zeros(0, np.int64)
    scene = load(fused)
    res, ring = [], []
    for k in idx:
        rays = return_rays(xyz[k], frames.grid[k], frames.layout, poses[k], k)
        t, _, cos = hit_depths(scene, rays)
        r = rays.range_m - t
        ok = np.isfinite(t) & (np.abs(r) < GATE_M) & (cos >= MIN_COS)
        res.append(r[ok])
        ring.append(rays.ring[ok])
    return np.concatenate(res), np.concatenate(ring)


def fit_range_offsets(
    frames: Frames, poses: np.ndarray, train, load, voxel_m: float, rounds: int = ROUNDS
) -> RangeOffsets:
    """Each laser's range offset from the training frames ``train`` (indices; module
    docstring).

    Args:
        frames: the drive's scans; poses: (F, 4, 4) every frame's LiDAR-to-world pose.
        load: ``load(mesh) -> mi.Scene`` of a mesh alone (:func:`.build.scratch_scene`).
        voxel_m: the fusion's cube, m (the surfaces' own).
    """
    idx = evenly_spread(list(train), MAX_FRAMES)
    rings = frames.layout.rings
    offsets = np.zeros(rings)
    steps, counts = [], np.zeros(rings, np.int64)
    for _ in range(rounds):
        res, ring = _round_residuals(frames, poses, idx, offsets, load, voxel_m)
        step, counts = laser_medians(res, ring, rings)
        offsets = offsets + step
        steps.append(float(np.std(step)))
    return RangeOffsets(offsets, tuple(steps), counts, len(idx))
