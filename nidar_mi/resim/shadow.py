"""The beams the sensor's mounting blocks, found in the training frames before the fit: the
recovered sensor's ``laser_shadow``.

A roof-mounted unit sees parts of its own vehicle: the lowest lasers of an HDL-64E on a KITTI
car meet the roof and the bonnet within a couple of metres at some azimuths, returns a drive's
scans drop (they lie closer than :data:`.frames.MIN_RANGE_M`) or never record. The
reconstructed surfaces do not hold the vehicle, so a re-simulated beam there goes on to the road
and returns where the real sensor never does; and in the fit those beams are misses on surfaces
that are there, which the ray-drop term would read as dropout.

Evidence, per beam (ring, column of the drive's grid), from the training samples
(:mod:`.observations`: every return that lands on the surfaces, every beam without a return
whose ray meets them): over the training frames at least :data:`MIN_SPACING_M` apart (a car
that stops adds no evidence by standing still), ``hits`` the frames with a sample on that beam
(the surfaces are there) and ``returned`` those of them where it is a return. A beam is in the
shadow when ``hits >= MIN_HITS`` and ``returned <= MAX_SHARE · hits``: the surfaces were there
and the sensor saw nothing, from every place it stood. A beam that never meets the surfaces
(the sky) has no evidence and stays open.

The mask's misses are taken out of the samples before the fit (:func:`.invert.invert`), and
each laser's runs of shadowed columns become azimuth intervals (:func:`shadow_intervals`), the
plugin's ``laser_shadow`` (:mod:`nidar_mi.lidar.config`), written into
``sensor_recovered.xml``: the shadow belongs to this sensor on this vehicle, so a preset sensor
put in its place does not carry it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .beam_rays import Rays

__all__ = [
    "Shadow",
    "MIN_HITS",
    "MAX_SHARE",
    "MIN_SPACING_M",
    "MISS_REACH_M",
    "evidence_frames",
    "ray_columns",
    "beam_evidence",
    "shadow_mask",
    "shadow_intervals",
    "shadow_value",
    "find_shadow",
]

#: A beam needs the surfaces in at least this many evidence frames ...
MIN_HITS = 2
#: ... and real returns in at most this share of those to be in the shadow.
MAX_SHARE = 0.1
#: Evidence frames lie at least this far apart, m.
MIN_SPACING_M = 0.5
#: A miss ray's column is read at this distance along it (m), where its origin's offset from
#: the sensor's centre no longer moves its azimuth.
MISS_REACH_M = 100.0


@dataclass(frozen=True)
class Shadow:
    """The recovered shadow: ``mask`` (R, C) bool on the drive's grid, ``intervals`` (laser,
    from, to) in degrees, ``frames`` the training frames that gave the evidence."""

    mask: np.ndarray = field(repr=False)
    intervals: tuple[tuple[int, float, float], ...]
    frames: int

    def summary(self) -> dict:
        """JSON-safe: beams, frames and intervals."""
        return {
            "beams": int(self.mask.sum()),
            "frames": self.frames,
            "intervals": len(self.intervals),
        }


def evidence_frames(positions: np.ndarray, spacing: float = MIN_SPACING_M) -> np.ndarray:
    """Indices into (F, 3) ``positions`` (in drive order) of the frames kept as evidence: the
    first, then each frame at least ``spacing`` m from the last one kept."""
    keep, last = [], None
    for i, p in enumerate(np.asarray(positions, dtype=np.float64)):
        if last is None or np.linalg.norm(p - last) >= spacing:
            keep.append(i)
            last = p
    return np.asarray(keep, dtype=np.int64)


def ray_columns(rays: Rays, poses: np.ndarray, columns: int) -> np.ndarray:
    """(N,) the grid column of each ray in its frame: the azimuth, in the frame's LiDAR frame,
    of where the ray ends (its measured range, or :data:`MISS_REACH_M` for a miss), as
    :mod:`.range_image` bins a return. ``poses``: (F, 4, 4) LiDAR to world."""
    poses = np.asarray(poses, dtype=np.float64)
    reach = np.where(np.isfinite(rays.range_m), rays.range_m, MISS_REACH_M)
    end = rays.origin + rays.direction * reach[:, None]
    T = poses[rays.frame]
    local = np.einsum("nji,nj->ni", T[:, :3, :3], end - T[:, :3, 3])  # Rᵀ (p - t)
    az = np.degrees(np.arctan2(local[:, 1], local[:, 0]))
    return np.floor((az + 180.0) * columns / 360.0).astype(np.int64) % columns


def beam_evidence(ring, column, frame, detected, shape: tuple[int, int]):
    """``(hits, returned)``, (R, C) int each: per beam the distinct frames with a sample, and
    those with a detected one. ``ring``, ``column``, ``frame``, ``detected``: (N,) per sample."""
    rings, columns = shape
    cell = np.asarray(ring, np.int64) * columns + np.asarray(column, np.int64)
    key = np.asarray(frame, np.int64) * (rings * columns) + cell

    def distinct(keys):
        return np.bincount(np.unique(keys) % (rings * columns), minlength=rings * columns)

    hits = distinct(key).reshape(shape)
    returned = distinct(key[np.asarray(detected, bool)]).reshape(shape)
    return hits, returned


def shadow_mask(
    hits: np.ndarray, returned: np.ndarray, min_hits: int = MIN_HITS, max_share: float = MAX_SHARE
) -> np.ndarray:
    """(R, C) bool: ``hits >= min_hits`` and ``returned <= max_share · hits`` ((R, C) counts)."""
    hits, returned = np.asarray(hits), np.asarray(returned)
    return (hits >= min_hits) & (returned <= max_share * hits)


def shadow_intervals(mask: np.ndarray, columns: int) -> tuple[tuple[int, float, float], ...]:
    """Each ring's runs of consecutive shadowed columns of (R, C) ``mask`` as ``(ring, from,
    to)``: column c covers azimuths [-180 + c·360/C, -180 + (c+1)·360/C) degrees (the drive's
    grid, :mod:`.range_image`); bounds rounded to 1e-4° outwards."""
    step = 360.0 / columns
    out = []
    for ring in range(mask.shape[0]):
        row = np.diff(np.r_[0, np.asarray(mask[ring], np.int8), 0])
        for a, b in zip(np.flatnonzero(row == 1), np.flatnonzero(row == -1)):
            lo = np.floor((-180.0 + a * step) * 1e4) / 1e4
            hi = np.ceil((-180.0 + b * step) * 1e4) / 1e4
            out.append((int(ring), float(lo), float(min(hi, 180.0))))
    return tuple(out)


def shadow_value(intervals) -> str:
    """The plugin's ``laser_shadow`` text of ``(ring, from, to)`` intervals."""
    return ", ".join(f"{r}:{a:.4f}:{b:.4f}" for r, a, b in intervals)


def find_shadow(samples, poses: np.ndarray, train: list[int], shape: tuple[int, int]) -> Shadow:
    """The shadow from the training ``samples`` (:class:`.observations.Samples` of the frames
    ``train``, indices into ``poses`` (F, 4, 4)) on the drive's (rings, columns) grid
    ``shape`` (module docstring)."""
    train = np.asarray(sorted(train), dtype=np.int64)
    used = train[evidence_frames(np.asarray(poses)[train, :3, 3])]
    rays = samples.rays
    keep = np.isin(rays.frame, used)
    column = ray_columns(rays, poses, shape[1])
    hits, returned = beam_evidence(
        rays.ring[keep], column[keep], rays.frame[keep], samples.detected[keep], shape
    )
    mask = shadow_mask(hits, returned)
    return Shadow(mask, shadow_intervals(mask, shape[1]), len(used))
