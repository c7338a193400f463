"""KITTI frames as NIDAR training frames: real sparse intensity, visible returns, rings.

Each KITTI frame (:func:`nidar_mi.datasets.kitti_objects.load_kitti_frame`) becomes one training frame in the
format of :mod:`nidar_mi.training_frames` (source ``"kitti"``, keys
:data:`nidar_mi.training_frames.FRAME_SOURCES` ``["kitti"]``):

* the returns camera 2 sees: in front of it, inside the image and not hidden in the cloud's own
  z-buffer (:func:`nidar_mi.geometry.camera_returns`, the package defaults; KITTI has no
  rendered depth): ``points_xyz``, ``points_intensity`` (the stored reflectance in [0, 1]) and
  ``points_ring`` (:func:`~nidar_mi.datasets.kitti_rings.checked_rings`; the nominal HDL-64E elevation
  table when the scan order is lost);
* those returns splatted to camera resolution (nearest return wins a pixel): the sparse
  ``intensity`` and ``range`` (m) with their ``mask``;
* ``rgb``, ``K`` and ``T_cam_lidar`` of camera 2.

A data folder ``DATA`` holds ``meta.json`` and ``DATA/{train,val,test}/<source>__<id>.npz``
(``<source>`` is the name of the KITTI folder, e.g. ``kitti_raw_0926__000012``). The splits
follow a held-out frame list (:data:`DEFAULT_HELD_OUT`): the six scattered frames of
``kitti/`` are ``test`` (the folds of the leave-one-frame-out evaluation), a contiguous block at
the end of the raw drive (``kitti_raw_0926`` 000070-000077) is ``val``, everything else is
``train``. Frames are rewritten only when their source files are newer (or the format version
changed), so a build is cached; :func:`kitti_training_data` keeps one build per set of source
folders in the user's cache (:func:`nidar_mi.datasets.paths.cache_dir`). Nothing of it belongs in
the project: KITTI is non-commercial data.
"""

from __future__ import annotations

import logging
import os
import warnings
from pathlib import Path

import numpy as np

from ..errors import NidarError
from ..io.atomic import folder_lock
from ..io.cache_key import cache_key
from ..io.ownership import Owner
from .kitti_objects import KittiFrame, frame_ids, load_kitti_frame
from .kitti_rings import HDL64E_RINGS, checked_rings, elevation_rings
from .paths import cache_dir, data_root

__all__ = [
    "DEFAULT_HELD_OUT",
    "DEFAULT_SOURCES",
    "KITTI_FRAMES_VERSION",
    "OWNER",
    "build_kitti_frames",
    "default_kitti_dirs",
    "frame_name",
    "kitti_training_data",
    "kitti_training_frame",
]

log = logging.getLogger("nidar_mi.dataset")

#: Version of the frames this module writes (part of the cache key).
KITTI_FRAMES_VERSION = 1
#: KITTI folders under :func:`~nidar_mi.datasets.paths.data_root` used by default.
DEFAULT_SOURCES = ("kitti", "kitti_raw_0926")
#: Frames held out of ``train``: the scattered frames (``test``, the evaluation folds) and a
#: contiguous block of the raw drive (``val``; consecutive frames are strongly correlated).
DEFAULT_HELD_OUT: dict[str, tuple[str, ...]] = {
    "test": tuple(
        f"kitti__{i}" for i in ("000000", "000001", "000002", "000003", "000114", "900000")
    ),
    "val": tuple(f"kitti_raw_0926__{i:06d}" for i in range(70, 78)),
}


def frame_name(source: str, frame_id: str) -> str:
    """The name of a KITTI frame in a data folder: ``<source>__<id>``."""
    return f"{source}__{frame_id}"


def default_kitti_dirs(root: str | os.PathLike | None = None) -> list[Path]:
    """The :data:`DEFAULT_SOURCES` folders under ``root`` (default: the data root) that hold
    frames."""
    base = Path(root) if root is not None else data_root()
    return [base / s for s in DEFAULT_SOURCES if frame_ids(base / s)]


def kitti_training_frame(frame: KittiFrame) -> tuple[dict[str, np.ndarray], dict]:
    """One KITTI frame as a training frame (module docstring).

    Returns:
        ``(frame dict, info)``; ``info`` has ``points``, ``visible``, ``rings`` (count) and
        ``ring_method`` (``"scan order"`` or ``"elevation"``).
    """
    from ..geometry import camera_returns
    from ..lidar.pattern import elevation_table

    xyz = frame.xyz.astype(np.float64)
    rings = checked_rings(frame.xyz)
    method = "scan order"
    if rings is None:
        rings = elevation_rings(frame.xyz, elevation_table("hdl64e"))
        method = "elevation"
    cam = frame.camera
    dist = np.linalg.norm(xyz, axis=1)
    visible = camera_returns(xyz, cam, {"intensity": frame.intensity, "range": dist})
    maps, seen = visible.maps, visible.index
    out = {
        "rgb": np.ascontiguousarray(frame.rgb),
        "intensity": maps["intensity"],
        "range": maps["range"],
        "mask": visible.mask,
        "K": cam.K.astype(np.float64),
        "T_cam_lidar": cam.T_cam_lidar.astype(np.float64),
        "points_xyz": frame.xyz[seen].astype(np.float32),
        "points_intensity": frame.intensity[seen].astype(np.float32),
        "points_ring": rings[seen].astype(np.int16),
    }
    info = {
        "points": int(len(xyz)),
        "visible": int(len(seen)),
        "rings": int(rings.max()) + 1 if len(rings) else 0,
        "ring_method": method,
    }
    return out, info


def _source_mtime(kitti_dir: Path, fid: str) -> float:
    return max(
        os.path.getmtime(kitti_dir / sub / f"{fid}{ext}")
        for sub, ext in (("velodyne", ".bin"), ("image_2", ".png"), ("calib", ".txt"))
    )


#: Who writes a dataset folder of KITTI frames (:mod:`nidar_mi.io.ownership`).
OWNER = Owner(
    "dataset",
    "kitti",
    names=("meta.json", "train/*", "val/*", "test/*", "*.tmp-*"),
    label="dataset --kitti",
    whole=False,
)


def build_kitti_frames(
    kitti_dirs,
    out_dir: str | os.PathLike,
    *,
    held_out: dict[str, tuple[str, ...]] | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> dict:
    """Write every frame of ``kitti_dirs`` into ``out_dir`` (cached) and its ``meta.json``.

    Args:
        kitti_dirs: KITTI folders (``velodyne/``, ``image_2/``, ``calib/``); the folder names
            must differ (they prefix the frame names).
        out_dir: the data folder.
        held_out: split name -> frame names held out of ``train`` (default
            :data:`DEFAULT_HELD_OUT`); names not present are ignored.
        progress: show a progress bar.
        overwrite: the user passed ``overwrite`` (``out_dir`` is another kind of dataset, or
            one of nidar_mi 0.1.0: :func:`nidar_mi.io.ownership.check_owner`).

    Returns:
        The meta dict (also written to ``out_dir/meta.json``).

    Raises:
        NidarError: no frames, clashing folder names, a malformed frame (nothing this build
            wrote is left then), or an output folder :data:`OWNER` may not write.
    """
    from ..io.atomic import atomic_write_json, check_output_folder, write_record
    from ..io.ownership import folder_files
    from ..training_frames import SPLITS

    dirs = [Path(d) for d in kitti_dirs]
    names, held, jobs = _kitti_jobs(dirs, held_out)
    out = check_output_folder(out_dir, owner=OWNER, overwrite=overwrite, inputs=dirs)
    made = [p for p in (out, *(out / s for s in SPLITS)) if not p.exists()]
    try:
        splits, info = _write_frames(jobs, held, out, progress)
    except BaseException:
        for folder in reversed(made):  # the folders this build made, when left empty
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
        raise
    _drop_moved_frames(out, splits)
    short = _warn_about_scans(info)
    meta = {
        "source": "kitti",
        "version": KITTI_FRAMES_VERSION,
        "sensor": "Velodyne HDL-64E (KITTI), camera 2",
        "intensity": "stored Velodyne reflectance in [0, 1]",
        "intensity_scale": 1.0,
        "kitti_dirs": {s: str(d.resolve()) for d, s in zip(dirs, names)},
        "held_out": {k: sorted(v) for k, v in held.items()},
        "frames": splits,
        "frame_info": info,
        "short_scans": short,
    }
    atomic_write_json(out / "meta.json", meta)
    write_record(out, OWNER, [f for f in folder_files(out) if OWNER.writes(f)])
    return meta


def _kitti_jobs(dirs: list[Path], held_out) -> tuple[list[str], dict[str, set], list[tuple]]:
    """The folders' names (the frames' prefixes), the held-out frames per split and the frames
    to write, ``(folder, name, frame id)`` each, checked (:func:`build_kitti_frames`)."""
    from ..training_frames import SPLITS

    names = [d.resolve().name for d in dirs]
    if len(set(names)) != len(names):
        raise NidarError(f"KITTI folders need distinct names (got {', '.join(map(str, dirs))})")
    held = {k: set(v) for k, v in (DEFAULT_HELD_OUT if held_out is None else held_out).items()}
    unknown = set(held) - set(SPLITS)
    if unknown:
        raise NidarError(f"held-out splits must be among {', '.join(SPLITS)}, not {unknown}")
    jobs = [(d, s, fid) for d, s in zip(dirs, names) for fid in frame_ids(d)]
    if not jobs:
        raise NidarError(
            "no KITTI frame (velodyne/ID.bin + image_2/ID.png + calib/ID.txt) in "
            + ", ".join(map(str, dirs))
        )
    return names, held, jobs


def _write_frames(jobs, held: dict[str, set], out: Path, progress: bool):
    """Write every frame not current in ``out`` (written by this version after its scan):
    ``(splits, info)``, the frame names per split and each frame's record. Frames this build
    created are removed again if it fails (``meta.json`` does not list them)."""
    from ..progress import progress_bar
    from ..training_frames import SPLITS, load_meta, write_frame

    old_version, old_info = None, {}
    if (out / "meta.json").is_file():
        old = load_meta(out)
        old_version, old_info = old.get("version"), old.get("frame_info", {})
    splits: dict[str, list[str]] = {s: [] for s in SPLITS}
    info: dict[str, dict] = {}
    added: list[Path] = []
    try:
        for kitti_dir, source, fid in progress_bar(
            jobs, show=progress, desc="KITTI frames", unit="frame"
        ):
            name = frame_name(source, fid)
            split = next((s for s, names in held.items() if name in names), "train")
            target = out / split / f"{name}.npz"
            fresh = (
                old_version == KITTI_FRAMES_VERSION
                and target.is_file()
                and os.path.getmtime(target) >= _source_mtime(kitti_dir, fid)
            )
            prev = old_info.get(name) if fresh else None
            if prev is None:
                frame, prev = kitti_training_frame(load_kitti_frame(kitti_dir, fid))
                if not target.exists():
                    added.append(target)
                write_frame(target, frame)
            info[name] = prev
            splits[split].append(name)
            log.debug(
                "%s: %d points, %d seen by camera 2 (%s)",
                name,
                prev["points"],
                prev["visible"],
                split,
            )
    except BaseException:
        for path in added:
            path.unlink(missing_ok=True)
        raise
    return splits, info


def _drop_moved_frames(out: Path, splits: dict[str, list[str]]) -> None:
    """Remove the frames an earlier build left in another split."""
    from ..training_frames import SPLITS, list_frames

    for split in SPLITS:
        keep = set(splits[split])
        for path in list_frames(out, split):
            if path.stem not in keep:
                path.unlink()


def _warn_about_scans(info: dict[str, dict]) -> dict[str, int]:
    """Warn about short scans and scans whose rings come from their elevations; the short
    scans' ring counts by frame name."""
    short = {n: i["rings"] for n, i in info.items() if 0 < i["rings"] < HDL64E_RINGS}
    if short:
        warnings.warn(
            "short scans (fewer than 64 rings, only the top ones): "
            + ", ".join(f"{n} ({r} rings)" for n, r in sorted(short.items())),
            RuntimeWarning,
            stacklevel=3,
        )
    elevation = sorted(n for n, i in info.items() if i["ring_method"] != "scan order")
    if elevation:
        warnings.warn(
            f"{len(elevation)} scan(s) not in KITTI's stored order; their rings come from the "
            "nominal HDL-64E elevations (approximate): " + ", ".join(elevation[:5]),
            RuntimeWarning,
            stacklevel=3,
        )
    return short


def kitti_training_data(kitti_dirs=None, *, progress: bool = True) -> Path:
    """The cached training-frame folder of ``kitti_dirs`` (built or refreshed as needed).

    Args:
        kitti_dirs: KITTI folders; None: :func:`default_kitti_dirs`.
        progress: show a progress bar while building.

    Returns:
        ``<cache>/kitti_frames/<key>`` (``key`` from the resolved folders and the version).

    Raises:
        NidarError: no KITTI frames found (the message says where they were looked for).
    """
    dirs = [Path(d) for d in (kitti_dirs if kitti_dirs is not None else default_kitti_dirs())]
    if not dirs:
        raise NidarError(
            f"no KITTI frames under {data_root()} ({', '.join(DEFAULT_SOURCES)}); give the "
            "KITTI folders explicitly or set NIDAR_MI_DATA"
        )
    key = cache_key([str(d.resolve()) for d in dirs] + [KITTI_FRAMES_VERSION])
    out = cache_dir("kitti_frames", key)
    # the package's own cache; a second process building it at the same time waits
    with folder_lock(out.parent, "the KITTI frame cache"):
        build_kitti_frames(dirs, out, progress=progress, overwrite=True)
    return out
