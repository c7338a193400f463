"""A recorded drive in the KITTI layout, and the checks made before any work.

A drive is a folder::

    DRIVE/velodyne/<id>.bin     required, >= 2 scans (float32 x, y, z, intensity; LiDAR frame)
    DRIVE/poses.txt             optional: KITTI odometry poses, LiDAR to world, one line per
                                scan in the sorted order of the ids
    DRIVE/image_2/, calib/      optional: camera images and calibration (NIDAR's prior)

Frames are the ``.bin`` files sorted by name; a frame's id is its file stem. Every check of
:func:`open_drive` runs before anything is computed and raises a one-line
:class:`~nidar_mi.errors.NidarError`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import NidarError

__all__ = ["Drive", "MAX_SCAN_POINTS", "open_drive", "parse_ids", "evenly_spread"]

#: The most points a scan may hold (16 bytes each): a 128-ring sensor at 4096 columns with two
#: returns per beam holds about 1 M.
MAX_SCAN_POINTS = 4_000_000


@dataclass(frozen=True)
class Drive:
    """The frames of a drive and what is held out.

    Attributes:
        root: the drive folder.
        ids: (F,) frame ids (file stems), sorted.
        holdout: ids never used to build or fit anything (a subset of ``ids``).
        poses: (F, 4, 4) float64 LiDAR-to-world poses from a file, or None (odometry).
        poses_source: the poses file read, or ``"kiss-icp"``.
    """

    root: str
    ids: tuple[str, ...]
    holdout: tuple[str, ...]
    poses: np.ndarray | None
    poses_source: str

    @property
    def train(self) -> tuple[str, ...]:
        """The ids the scene and the sensor are fitted on, in order."""
        held = set(self.holdout)
        return tuple(i for i in self.ids if i not in held)

    def index(self, frame_id: str) -> int:
        """Position of ``frame_id`` in :attr:`ids`."""
        return self.ids.index(frame_id)

    def scan_path(self, frame_id: str) -> str:
        """The ``.bin`` file of a frame."""
        return os.path.join(self.root, "velodyne", f"{frame_id}.bin")

    def calib_path(self, frame_id: str) -> str | None:
        """The frame's calibration file (``calib/<id>.txt``, else ``calib.txt``), or None."""
        for p in (os.path.join(self.root, "calib", f"{frame_id}.txt"),):
            if os.path.isfile(p):
                return p
        p = os.path.join(self.root, "calib.txt")
        return p if os.path.isfile(p) else None

    def image_path(self, frame_id: str) -> str | None:
        """The frame's ``image_2`` picture, or None."""
        for ext in (".png", ".jpg"):
            p = os.path.join(self.root, "image_2", frame_id + ext)
            if os.path.isfile(p):
                return p
        return None


def evenly_spread(items: list, limit: int) -> list:
    """At most ``limit`` of ``items`` (``limit >= 2``), evenly spread, the first and the last
    kept; all of them when there are no more."""
    if len(items) <= limit:
        return list(items)
    pick = np.linspace(0, len(items) - 1, limit).round().astype(int)
    return [items[k] for k in pick]


def parse_ids(text: str | None, limit: int | None = None) -> list[str]:
    """Frame ids from ``A,B,C`` and ranges ``A:B`` (both ends included, ids of equal width);
    empty or None: none. ``limit``: the most ids a range may name (a drive of at most that many
    scans holds no more), checked before the range is expanded."""
    out: list[str] = []
    for part in (text or "").split(","):
        part = part.strip()
        if not part:
            continue
        if ":" in part:
            a, b = (s.strip() for s in part.split(":", 1))
            if not (a.isdigit() and b.isdigit()) or int(b) < int(a):
                raise NidarError(f"`holdout`: '{part}' is not a range of numeric ids A:B (A <= B)")
            if limit is not None and int(b) - int(a) + 1 > limit:
                raise NidarError(
                    f"`holdout`: '{part}' names {int(b) - int(a) + 1} ids, more than a drive "
                    f"may hold (`max_frames` {limit})"
                )
            out += [str(k).zfill(len(a)) for k in range(int(a), int(b) + 1)]
        else:
            out.append(part)
    return out


def open_drive(root: str, *, holdout: list[str] | None = None, poses_file: str | None = None):
    """The drive at ``root``, checked.

    Args:
        root: the drive folder.
        holdout: frame ids to hold out.
        poses_file: a KITTI poses file (default: ``root/poses.txt`` when present, else None:
            the poses come from odometry).

    Raises:
        NidarError: no ``velodyne/`` folder, fewer than 2 scans, a held-out id that is not a
            frame, every frame held out, or a poses file whose line count differs from the
            scans' or that holds a non-finite or non-rigid pose.
    """
    vel = os.path.join(root, "velodyne")
    if not os.path.isdir(root):
        raise NidarError(f"drive folder {root} does not exist")
    if not os.path.isdir(vel):
        raise NidarError(f"{root} has no velodyne/ folder (the KITTI layout: velodyne/<id>.bin)")
    ids = tuple(sorted(n[:-4] for n in os.listdir(vel) if n.endswith(".bin")))
    if len(ids) < 2:
        raise NidarError(f"{vel} holds {len(ids)} scan(s); a drive needs at least 2")
    for i in ids:  # memory bounded before any scan is read
        path = os.path.join(vel, i + ".bin")
        if os.path.isfile(path) and os.path.getsize(path) > MAX_SCAN_POINTS * 16:
            raise NidarError(
                f"{path} holds {os.path.getsize(path) // 16} points, more than a scan may "
                f"({MAX_SCAN_POINTS})"
            )
    held = list(dict.fromkeys(holdout or []))
    unknown = [i for i in held if i not in ids]
    if unknown:
        shown = ", ".join(unknown[:5]) + (" ..." if len(unknown) > 5 else "")
        raise NidarError(f"`holdout` names frames that are not in {vel}: {shown}")
    if len(held) >= len(ids):
        raise NidarError("`holdout` holds out every frame: nothing is left to fit")
    source = poses_file or os.path.join(root, "poses.txt")
    poses = None
    if poses_file is not None or os.path.isfile(source):
        poses = _read_poses(source, len(ids))
    return Drive(
        root=root,
        ids=ids,
        holdout=tuple(sorted(held, key=ids.index)),
        poses=poses,
        poses_source=source if poses is not None else "kiss-icp",
    )


def _read_poses(path: str, frames: int) -> np.ndarray:
    from ..io.kitti import read_kitti_poses

    if not os.path.isfile(path):
        raise NidarError(f"`poses`: {path} does not exist")
    poses = read_kitti_poses(path)
    if len(poses) != frames:
        raise NidarError(f"`poses`: {path} has {len(poses)} poses for {frames} scans")
    if not np.all(np.isfinite(poses)):
        bad = int(np.flatnonzero(~np.isfinite(poses).all(axis=(1, 2)))[0])
        raise NidarError(f"`poses`: {path} line {bad + 1} is not finite")
    R = poses[:, :3, :3]
    err = np.abs(np.einsum("kij,kil->kjl", R, R) - np.eye(3)).max(axis=(1, 2))
    if np.any(err > 1e-3) or np.any(np.linalg.det(R) < 0):
        bad = int(np.flatnonzero((err > 1e-3) | (np.linalg.det(R) < 0))[0])
        raise NidarError(f"`poses`: {path} line {bad + 1} is not a rotation and translation")
    return poses
