"""The beams the sensor's mounting blocks, found in the training frames: the recovered sensor's
``laser_shadow``.

A roof-mounted unit sees parts of its own vehicle: the lowest lasers of an HDL-64E on a KITTI
car meet the roof and the bonnet within a couple of metres at some azimuths, returns a drive's
scans drop (they lie closer than :data:`.frames.MIN_RANGE_M`) or never record. The
reconstructed surfaces do not hold the vehicle, so a re-simulated beam there goes on to the road
and returns where the real sensor never does. Evidence, per beam (ring, column of the drive's
grid): over up to :data:`SHADOW_FRAMES` training frames (evenly spaced), ``hits`` the frames
whose expected scan (the recovered sensor at the frame's pose in the static surfaces, no noise,
no dropout) returns on that beam and ``returned`` those of them where the real scan returned
too. A beam is in the shadow when it hits in at least :data:`MIN_HITS` frames and the real scan
returned in at most :data:`MAX_SHARE` of them: the surfaces were there, the sensor saw nothing,
whatever the pose. A beam the surfaces never reach (the sky) has no evidence and stays open.

The mask becomes per-laser azimuth intervals (:func:`shadow_intervals`: runs of consecutive
columns), the plugin's ``laser_shadow`` (:mod:`nidar_mi.lidar.config`), written into
``sensor_recovered.xml``: the shadow belongs to this sensor on this vehicle, so a preset sensor
put in its place does not carry it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .drive_folder import Drive
from .frames import Frames

__all__ = [
    "Shadow",
    "SHADOW_FRAMES",
    "MIN_HITS",
    "MAX_SHARE",
    "shadow_mask",
    "shadow_intervals",
    "shadow_value",
    "mounting_shadow",
]

#: The most training frames scanned for the evidence.
SHADOW_FRAMES = 16
#: A beam needs the surfaces in at least this many of them ...
MIN_HITS = 2
#: ... and real returns in at most this share of those to be in the shadow.
MAX_SHARE = 0.1


@dataclass(frozen=True)
class Shadow:
    """The recovered shadow: ``intervals`` (laser, from, to) in degrees, ``beams`` the shadowed
    beams of the drive's grid, ``frames`` the training frames that gave the evidence."""

    intervals: tuple[tuple[int, float, float], ...]
    beams: int
    frames: int

    def summary(self) -> dict:
        """JSON-safe: beams, frames and intervals."""
        return {"beams": self.beams, "frames": self.frames, "intervals": len(self.intervals)}


def shadow_mask(
    hits: np.ndarray, returned: np.ndarray, min_hits: int = MIN_HITS, max_share: float = MAX_SHARE
) -> np.ndarray:
    """(R, C) bool: ``hits >= min_hits`` and ``returned <= max_share · hits`` ((R, C) counts)."""
    hits, returned = np.asarray(hits), np.asarray(returned)
    return (hits >= min_hits) & (returned <= max_share * hits)


def shadow_intervals(mask: np.ndarray, columns: int) -> tuple[tuple[int, float, float], ...]:
    """Each ring's runs of consecutive shadowed columns of (R, C) ``mask`` as ``(ring, from,
    to)``: column c covers azimuths [-180 + c·360/C, -180 + (c+1)·360/C) degrees (the drive's
    grid, :mod:`.range_image`)."""
    step = 360.0 / columns
    out = []
    for ring in range(mask.shape[0]):
        row = np.r_[False, mask[ring], False].astype(np.int8)
        starts = np.flatnonzero(np.diff(row) == 1)
        stops = np.flatnonzero(np.diff(row) == -1)
        for a, b in zip(starts, stops):
            out.append((ring, round(-180.0 + a * step, 4), round(-180.0 + b * step, 4)))
    return tuple(out)


def shadow_value(intervals) -> str:
    """The plugin's ``laser_shadow`` text of ``(ring, from, to)`` intervals."""
    return ", ".join(f"{r}:{a:g}:{b:g}" for r, a, b in intervals)


def mounting_shadow(scene_path: str, drive: Drive, frames: Frames, poses) -> Shadow:
    """The shadow of the recovered sensor of ``scene_path`` from the drive's training frames
    (module docstring)."""
    from ..scene import load_scene
    from .heldout_scans import expected_scan

    loaded = load_scene(scene_path)
    sensor = next(s for s in loaded.scene.sensors() if hasattr(s, "config"))
    quiet = {"receiver_noise_std": 0.0, "noise_intensity_std": 0.0, "noise_range_std": 0.0}
    cfg = replace(sensor.config, dropout=0.0, laser_shadow=None, **quiet)
    train = [drive.index(i) for i in drive.train]
    pick = np.unique(np.linspace(0, len(train) - 1, min(SHADOW_FRAMES, len(train))).round())
    hits = np.zeros((cfg.rings, frames.columns), np.int32)
    returned = np.zeros_like(hits)
    for k in (train[int(i)] for i in pick):
        occ = expected_scan(loaded.scene, cfg, poses[k], frames)[2]
        hits += occ
        returned += occ & frames.grid[k].occupancy()
    mask = shadow_mask(hits, returned)
    return Shadow(shadow_intervals(mask, frames.columns), int(mask.sum()), len(pick))
