"""A sensor's scans with their camera images, as sensor profiles and the evaluation see them.

A :class:`ScanFrame` is one LiDAR scan reduced to the returns that a camera sees, with their
intensity on the [0, 1] scale, their ring when known, and the camera images and models (loaded
when asked for, so that many frames fit in memory). :func:`load_scans` reads any of:

* a **NIDAR data folder** (``meta.json``; :mod:`nidar_mi.training_frames`), rendered or KITTI: its
  frames' ``points_*`` keys (frames of every split, or the splits asked for); intensities are
  divided by the folder's ``intensity_scale`` and clipped to [0, 1];
* a **KITTI folder** (``velodyne/``, ``image_2/``, ``calib/``): converted once into cached
  training frames (:func:`nidar_mi.datasets.kitti_frames.kitti_training_data`), then as above;
* a **generic folder**: ``points/<id>.<ext>`` (any format :func:`nidar_mi.io.read_point_cloud`
  reads, with an ``intensity`` field and optionally ``ring``), ``calib.yaml`` or ``calib.json``
  (the cameras, :mod:`nidar_mi.io.calib`) and the images ``images/<id>.png`` (one camera) or
  ``images/<camera name>/<id>.png`` (several). A return is kept when a camera sees it
  (:func:`nidar_mi.geometry.sample_cameras`, the cloud's own z-buffer). Intensities are divided
  by ``intensity_scale`` (default: 1 when they all lie in [0, 1], 255 when they lie in
  [0, 255]; otherwise it must be given). The simulator's own clouds are never taken for 8-bit
  ones: a cloud in a render folder (its real path ``<render>/<lidar id>/points.<ext>`` beside a
  manifest that lists the LiDAR) is divided by the sensor's full-scale intensity (the convention
  of its ``points.bin``), one with the simulator's points schema elsewhere by 1
  (:func:`simulator_scale`).
"""

from __future__ import annotations

import functools
import math
import os
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import NidarError

__all__ = [
    "ScanFrame",
    "frames_from_data",
    "frames_from_generic",
    "load_scans",
    "recording_of",
    "scan_frame",
    "scan_kind",
    "simulator_scale",
]

#: Columns only the simulator's points carry (:mod:`nidar_mi.io.points`): its schema.
_SIMULATOR_COLUMNS = ("material_names", "return_index", "reflectance")

_IMAGE_EXT = (".png", ".jpg", ".jpeg")


@dataclass(eq=False)
class ScanFrame:
    """One scan's camera-visible returns and the cameras that see them.

    Attributes:
        name: frame name (unique within a set of scans).
        xyz: (N, 3) float64 returns in the LiDAR frame, m.
        intensity: (N,) float64 the sensor's intensity on the [0, 1] scale.
        ring: (N,) int16 ring of each return (0 = the highest beam), -1 unknown.
        cameras: the C camera models (``T_cam_lidar`` from this LiDAR).
        source: where the frame came from (a path).
        group: the recording the frame belongs to (:func:`recording_of`): a profile fitted on
            frames of several recordings weighs each recording alike
            (:attr:`nidar_mi.profiles.context.ContextFitOptions.balance`).
    """

    name: str
    xyz: np.ndarray
    intensity: np.ndarray
    ring: np.ndarray
    cameras: list
    source: str = ""
    group: str = ""
    _images: Callable[[], list[np.ndarray]] = field(default=lambda: [], repr=False)

    @property
    def images(self) -> list[np.ndarray]:
        """The C (H, W, 3) uint8 sRGB images (read when asked for)."""
        return self._images()

    @property
    def range_m(self) -> np.ndarray:
        """(N,) float64 distance of each return from the LiDAR origin, m."""
        return np.linalg.norm(self.xyz, axis=1)

    @functools.cached_property
    def cos_incidence(self) -> np.ndarray:
        """(N,) float64 ``|cos θ|`` of the rays on the surfaces at the returns, normals estimated
        from these returns (:func:`nidar_mi.geometry.incidence_cosine`; computed once)."""
        from ..geometry import incidence_cosine

        return incidence_cosine(self.xyz)

    @functools.cached_property
    def local_geometry(self):
        """The returns' neighbourhood descriptors and incidence from one neighbour query
        (:func:`nidar_mi.geometry.local_features.local_geometry`; computed once)."""
        from ..geometry.local_features import local_geometry

        return local_geometry(self.xyz)

    @property
    def elevation_deg(self) -> np.ndarray:
        """(N,) float64 elevation of each return above the LiDAR's xy plane, degrees."""
        x, y, z = self.xyz.T
        return np.degrees(np.arctan2(z, np.hypot(x, y)))


def scan_kind(path: str | os.PathLike) -> str:
    """``"data"``, ``"kitti"`` or ``"generic"`` for a folder (module docstring).

    Raises:
        NidarError: the path is not a folder of any of these kinds.
    """
    p = Path(path)
    if not p.is_dir():
        raise NidarError(f"{p}: no such folder")
    if (p / "meta.json").is_file():
        return "data"
    if (p / "velodyne").is_dir():
        return "kitti"
    if (p / "points").is_dir():
        return "generic"
    raise NidarError(
        f"{p}: not a scan folder (expected meta.json, a KITTI layout with velodyne/, or points/ + "
        "images/ + calib.yaml)"
    )


def frames_from_data(
    data_dir: str | os.PathLike, splits: Sequence[str] | None = None
) -> list[ScanFrame]:
    """The frames of a NIDAR data folder (module docstring), sorted by split then name.

    Raises:
        NidarError: a frame without the ``points_*`` keys (rebuild the folder).
    """
    from ..training_frames import SPLITS, list_frames, load_frame, load_meta

    meta = load_meta(data_dir)
    scale = float(meta["intensity_scale"])
    out = []
    for split in splits or SPLITS:
        for path in list_frames(data_dir, split):
            f = load_frame(path, _SCAN_KEYS)
            images = lambda p=path: [load_frame(p, ("rgb",))["rgb"]]  # noqa: E731
            out.append(scan_frame(f, path.stem, str(path), scale, images))
    return out


#: The keys of a training frame (:mod:`nidar_mi.training_frames`) a :class:`ScanFrame` is made of.
_SCAN_KEYS = ("K", "T_cam_lidar", "mask", "points_xyz", "points_intensity", "points_ring")


def scan_frame(
    f: dict, name: str, source: str, scale: float, images: Callable[[], list[np.ndarray]]
) -> ScanFrame:
    """A training frame (:mod:`nidar_mi.training_frames`; its :data:`_SCAN_KEYS`) as a scan: the
    camera-visible returns, their intensity divided by ``scale`` and clipped to [0, 1], the
    camera, and ``images`` to read the image when asked for."""
    from ..geometry import CameraModel

    h, w = f["mask"].shape
    cam = CameraModel(K=f["K"], width=w, height=h, T_cam_lidar=f["T_cam_lidar"], name=name)
    return ScanFrame(
        name=name,
        xyz=f["points_xyz"].astype(np.float64),
        intensity=np.clip(f["points_intensity"].astype(np.float64) / scale, 0.0, 1.0),
        ring=f["points_ring"],
        cameras=[cam],
        source=source,
        group=recording_of(name, source),
        _images=images,
    )


def recording_of(name: str, source: str) -> str:
    """The recording of a frame: the ``<source>`` of a name ``<source>__<id>`` (a KITTI frame
    of a converted folder names its folder so); else ``source`` when it is a folder (a KITTI
    folder read frame by frame), or the folder of the file ``source`` (a data folder's frames:
    the data folder, above its split)."""
    if "__" in name:
        return name.split("__", 1)[0]
    if Path(source).is_dir():
        return str(source)
    parent = Path(source).parent
    return str(parent.parent if parent.name in ("train", "val", "test") else parent)


def _auto_scale(values: np.ndarray, given: float | None, where: str) -> float:
    if given is not None:
        if not given > 0:
            raise NidarError(f"intensity scale must be > 0 (got {given})")
        return float(given)
    top = float(np.max(values)) if values.size else 0.0
    if top <= 1.0:
        return 1.0
    if top <= 255.0:
        warnings.warn(f"{where}: intensities up to {top:g}; dividing them by 255", stacklevel=3)
        return 255.0
    raise NidarError(f"{where}: intensities up to {top:g}; give the intensity scale")


def simulator_scale(path: str | os.PathLike, cloud: dict) -> float | None:
    """The divisor that puts the simulator's own cloud on the [0, 1] scale; None for a cloud of
    another tool.

    The cloud is the simulator's when its file (symbolic links followed) is
    ``<render>/<lidar id>/points.<ext>`` of a render folder whose manifest lists the LiDAR: the
    sensor's :func:`~nidar_mi.lidar.return_model.full_scale_intensity` (from the manifest's
    ``gain`` and ``intensity_mode``; ``points.bin``'s convention); or when it carries the
    simulator's schema (``material_names``, ``return_index``, ``reflectance``): 1, the full
    scale of the default gain and the ``intensity_scale`` of rendered training data.
    """
    from ..lidar.return_model import full_scale_intensity
    from ..render_folder import read_manifest

    real = Path(os.path.realpath(path))
    render, lidar = real.parent.parent, real.parent.name
    if (render / "manifest.json").is_file():
        try:
            params = read_manifest(render)["lidars"][lidar]["parameters"]
            return full_scale_intensity(params["gain"], params["intensity_mode"])
        except (NidarError, KeyError, TypeError, ValueError):
            pass
    if all(name in cloud for name in _SIMULATOR_COLUMNS):
        return 1.0
    return None


def _image_path(folder: Path, fid: str, camera: str, n_cams: int) -> Path:
    base = folder / "images" / (camera if n_cams > 1 else "")
    for ext in _IMAGE_EXT:
        p = base / f"{fid}{ext}"
        if p.is_file():
            return p
    raise NidarError(f"{folder}: frame {fid} has no image {base / fid}.png")


def frames_from_generic(
    folder: str | os.PathLike, intensity_scale: float | None = None
) -> list[ScanFrame]:
    """The frames of a generic scan folder (module docstring).

    Raises:
        NidarError: a missing calibration or image, a cloud without intensity.
    """
    from ..geometry import sample_cameras
    from ..io.calib import load_calib
    from ..io.images import read_png
    from ..io.point_cloud import read_point_cloud

    folder = Path(folder)
    calib = next(
        (folder / n for n in ("calib.yaml", "calib.yml", "calib.json") if (folder / n).is_file()),
        None,
    )
    if calib is None:
        raise NidarError(f"{folder}: no calib.yaml or calib.json")
    cameras = load_calib(calib)
    out = []
    for pts_path in sorted(p for p in (folder / "points").iterdir() if p.is_file()):
        cloud = read_point_cloud(pts_path)
        if "intensity" not in cloud:
            raise NidarError(f"{pts_path}: the cloud has no intensity field")
        fid = pts_path.stem
        paths = [_image_path(folder, fid, c.name, len(cameras)) for c in cameras]

        def images(paths=paths):
            return [read_png(p)[..., :3] for p in paths]

        imgs = images()
        for cam, im, p in zip(cameras, imgs, paths):
            if im.shape[:2] != (cam.height, cam.width) or im.dtype != np.uint8:
                raise NidarError(
                    f"{p}: {im.shape[1]}x{im.shape[0]} {im.dtype}, camera {cam.name} is {cam.width}x{cam.height} 8-bit"
                )
        xyz = np.asarray(cloud["xyz"], dtype=np.float64)
        inten = np.asarray(cloud["intensity"], dtype=np.float64)
        ring = np.asarray(cloud.get("ring", np.full(len(xyz), -1)), dtype=np.int64)
        finite = np.isfinite(xyz).all(axis=1) & np.isfinite(inten)
        if not finite.all():
            warnings.warn(
                f"{pts_path}: {int((~finite).sum())} of {len(finite)} points with a NaN or "
                "infinite coordinate or intensity are left out",
                stacklevel=2,
            )
            xyz, inten, ring = xyz[finite], inten[finite], ring[finite]
        if inten.size and float(inten.min()) < 0.0:
            raise NidarError(
                f"{pts_path}: negative intensities (down to {float(inten.min()):g}); a LiDAR's "
                "intensity is >= 0"
            )
        zeros = [np.zeros((c.height, c.width), np.float32) for c in cameras]
        _, seen, _ = sample_cameras(xyz, cameras, zeros)
        scale = None if intensity_scale is not None else simulator_scale(pts_path, cloud)
        if scale is None:
            scale = _auto_scale(inten, intensity_scale, str(pts_path))
        out.append(
            ScanFrame(
                name=fid,
                xyz=xyz[seen],
                intensity=np.clip(inten[seen] / scale, 0.0, 1.0),
                ring=ring[seen].astype(np.int16),
                cameras=list(cameras),
                source=str(pts_path),
                group=str(folder),
                _images=images,
            )
        )
    if not out:
        raise NidarError(f"{folder / 'points'}: no point clouds")
    return out


def load_scans(
    paths: Sequence[str | os.PathLike],
    *,
    splits: Sequence[str] | None = None,
    intensity_scale: float | None = None,
    progress: bool = True,
) -> list[ScanFrame]:
    """The frames of every folder in ``paths`` (each detected by :func:`scan_kind`).

    KITTI folders are converted together (one cached data folder). Frame names get the
    folder's name as a prefix when several folders are given and names clash.

    Raises:
        NidarError: ``intensity_scale`` not a finite number > 0, an unsupported folder, or no
            frame at all.
    """
    from .kitti_frames import kitti_training_data

    if intensity_scale is not None and not (math.isfinite(intensity_scale) and intensity_scale > 0):
        raise NidarError(f"`intensity_scale` must be a finite number > 0 (got {intensity_scale})")
    kinds = [(Path(p), scan_kind(p)) for p in paths]
    frames: list[ScanFrame] = []
    kitti = [p for p, k in kinds if k == "kitti"]
    if kitti:
        frames += frames_from_data(kitti_training_data(kitti, progress=progress), splits)
    for p, k in kinds:
        if k == "data":
            frames += frames_from_data(p, splits)
        elif k == "generic":
            frames += frames_from_generic(p, intensity_scale)
    if not frames:
        raise NidarError("no scans in " + ", ".join(map(str, paths)))
    names = [f.name for f in frames]
    if len(set(names)) != len(names):
        for f in frames:
            f.name = f"{Path(f.source).parent.parent.name}__{f.name}"
    return frames
