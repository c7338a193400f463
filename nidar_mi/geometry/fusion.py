"""A per-point value from several cameras: sample every camera that sees the point, then fuse.

Points are in the LiDAR frame, in metres; depths are camera-forward distances in metres;
pixel coordinates follow :mod:`nidar_mi.geometry.camera_model` (pixel centres at integer
coordinates). This is the "point cloud intensity assignment" step of the NIDAR paper
(§III.F), plus the occlusion test of :mod:`nidar_mi.geometry.visibility`, which the paper
does not have.

**Fusion rules** (:data:`FUSION_RULES`), among the cameras that see a point:

* ``"nearest_center"`` (default): the camera in which the point lies closest to the image
  centre, measured as ``hypot((u - (W-1)/2) / (W/2), (v - (H-1)/2) / (H/2))`` (0 at the
  centre, 1 at mid-edges, so cameras of different resolution compare fairly); sampling is
  least affected by lens edges there.
* ``"min_depth"``: the camera with the smallest depth to the point (finest footprint).
* ``"mean"``: the unweighted mean over all seeing cameras.

Ties go to the lowest camera index.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from nidar_mi.errors import NidarError

from .camera_model import CameraModel
from .projection import bilinear_sample, check_points, project_in_image
from .visibility import DEFAULT_ABS_TOL, DEFAULT_ZBUFFER_CELL, visible_mask

__all__ = ["FUSION_RULES", "VISIBILITY_OPTIONS", "Sightings", "locate_in_cameras", "sample_cameras"]

FUSION_RULES = ("nearest_center", "mean", "min_depth")
"""Rules :func:`sample_cameras` can fuse several cameras' samples with."""


@dataclass(frozen=True)
class Sightings:
    """Where the cameras see a cloud's points, before any image is sampled
    (:func:`locate_in_cameras`).

    Attributes:
        n: number of points of the cloud.
        per_camera: for each camera, ``(index, uv, depth)``: (M,) int64 ascending indices of
            the points it sees (in front, inside the image, not occluded when the occlusion
            test was on), their (M, 2) pixel coordinates and (M,) depths, m.
    """

    n: int
    per_camera: tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]

    @property
    def seen(self) -> np.ndarray:
        """(N,) bool: some camera sees the point (an image finite there gives it a value)."""
        out = np.zeros(self.n, dtype=bool)
        for index, _, _ in self.per_camera:
            out[index] = True
        return out


def _locate_camera(
    p: np.ndarray, cam: CameraModel, depth_image: Any, *, occlusion: bool, visibility: dict
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(index, uv, depth)`` of the points one camera sees (:class:`Sightings`)."""
    index, uv, depth = project_in_image(p, cam)  # only the points that land in the image
    if occlusion:
        seen = visible_mask(uv, depth, cam, depth_image=depth_image, **visibility)
        index, uv, depth = index[seen], uv[seen], depth[seen]
    return index, uv, depth


def _sample_camera(
    cam: CameraModel, img: np.ndarray, located: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One camera's samples of the points it sees: ``(index, value, centre score, depth)``,
    (M,) arrays, ``index`` ascending into the cloud; points where the image is not finite are
    dropped."""
    index, uv, depth = located
    sample = bilinear_sample(img, uv)
    ok = np.isfinite(sample)
    index, uv = index[ok], uv[ok]
    du = (uv[:, 0] - (cam.width - 1) / 2.0) / (cam.width / 2.0)
    dv = (uv[:, 1] - (cam.height - 1) / 2.0) / (cam.height / 2.0)
    return index, sample[ok], np.hypot(du, dv), depth[ok]


def _one_camera(n: int, index: np.ndarray, value: np.ndarray):
    """:func:`_fuse`'s result for a single camera's samples (``index``, ``value``) of ``n``
    points, without (1, n) arrays: the value where it sees a point."""
    values = np.zeros(n, dtype=np.float32)
    values[index] = value
    observed = np.zeros(n, dtype=bool)
    observed[index] = True
    camera_index = np.full(n, -1, dtype=np.int64)
    camera_index[index] = 0
    return values, observed, camera_index


def _stacked(n: int, per_camera: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(C, n) values, centre scores and depths of the cameras' samples; NaN / inf where a
    camera does not see a point."""
    vals, score, dep = np.full((3, len(per_camera), n), np.inf)
    vals[:] = np.nan
    for c, (index, value, sc, depth) in enumerate(per_camera):
        vals[c, index], score[c, index], dep[c, index] = value, sc, depth
    return vals, score, dep


def _fuse(
    vals: np.ndarray, score: np.ndarray, dep: np.ndarray, fusion: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fuse (C, N) per-camera samples into ``(values, observed, camera_index)``."""
    n = vals.shape[1]
    observed = np.isfinite(vals).any(axis=0)
    pick = np.argmin(dep if fusion == "min_depth" else score, axis=0)
    if fusion == "mean":
        fused = np.nanmean(vals[:, observed], axis=0)  # each column has a finite value
    else:
        fused = vals[pick[observed], np.flatnonzero(observed)]
    values = np.zeros(n, dtype=np.float32)
    values[observed] = fused
    camera_index = np.where(observed, pick, -1).astype(np.int64)
    return values, observed, camera_index


#: The options of the occlusion test (:func:`~nidar_mi.geometry.visibility.visible_mask`) that
#: :func:`sample_cameras` and :func:`locate_in_cameras` hand on, and their defaults.
VISIBILITY_OPTIONS = {
    "depth_kind": "z",
    "rel_tol": None,
    "abs_tol": DEFAULT_ABS_TOL,
    "zbuffer_cell": DEFAULT_ZBUFFER_CELL,
}


def _visibility(options: dict[str, Any], caller: str) -> dict[str, Any]:
    """The occlusion test's options: :data:`VISIBILITY_OPTIONS` updated by ``options``."""
    unknown = sorted(set(options) - set(VISIBILITY_OPTIONS))
    if unknown:
        raise NidarError(f"{caller}: unknown option(s) {', '.join(unknown)}")
    return VISIBILITY_OPTIONS | options


def locate_in_cameras(
    points: Any,
    cameras: Sequence[CameraModel],
    *,
    depth_images: Sequence[Any] | None = None,
    occlusion: bool = True,
    **visibility: Any,
) -> Sightings:
    """Which points each camera sees, and where: the geometric half of :func:`sample_cameras`,
    which needs no image (so it can run while the images are still being computed).

    Args:
        points: (N, 3) points in the LiDAR frame, metres.
        cameras: C cameras (a single :class:`CameraModel` is taken as one camera).
        depth_images, occlusion: as for :func:`sample_cameras`.
        **visibility: ``depth_kind``, ``rel_tol``, ``abs_tol``, ``zbuffer_cell`` as for
            :func:`sample_cameras`.

    Returns:
        The :class:`Sightings`, to pass to :func:`sample_cameras` as ``sightings``.

    Raises:
        NidarError: no cameras, points not (N, 3) or not finite, or depth images that do not
            match the cameras in number.
    """
    caller = "locate_in_cameras"
    visibility = _visibility(visibility, caller)
    return _locate(points, cameras, depth_images, occlusion, visibility, caller)


def _locate(
    points: Any,
    cameras: Sequence[CameraModel],
    depth_images: Sequence[Any] | None,
    occlusion: bool,
    visibility: dict[str, Any],
    caller: str,
) -> Sightings:
    """:func:`locate_in_cameras`, its errors prefixed with the public function's name
    ``caller``."""
    if isinstance(cameras, CameraModel):
        cameras = [cameras]
    if len(cameras) == 0:
        raise NidarError(f"{caller}: no cameras given")
    if depth_images is None:
        depth_images = [None] * len(cameras)
    elif len(depth_images) != len(cameras):
        raise NidarError(f"{caller}: {len(cameras)} cameras but {len(depth_images)} depth images")
    p = check_points(points)
    per_camera = tuple(
        _locate_camera(p, cam, dimg, occlusion=occlusion, visibility=visibility)
        for cam, dimg in zip(cameras, depth_images, strict=True)
    )
    return Sightings(len(p), per_camera)


def sample_cameras(
    points: Any,
    cameras: Sequence[CameraModel],
    images: Sequence[Any],
    *,
    depth_images: Sequence[Any] | None = None,
    occlusion: bool = True,
    fusion: str = "nearest_center",
    sightings: Sightings | None = None,
    **visibility: Any,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Give each point a value sampled from the camera images that see it.

    A camera *sees* a point when the point is in front of it, inside its image, not
    occluded (when ``occlusion``; see :func:`~nidar_mi.geometry.visibility.visible_mask`,
    using that camera's depth image if given, else the cloud z-buffer) and the bilinear
    sample is finite. The samples of the seeing cameras are fused by ``fusion`` (module
    docstring); with ``"mean"``, ``camera_index`` reports the ``"nearest_center"`` choice.

    Args:
        points: (N, 3) points in the LiDAR frame, metres.
        cameras: C cameras (a single :class:`CameraModel` is taken as one camera).
        images: C single-channel (H_c, W_c) images (e.g. NIDAR's ``R`` branch), matching the
            cameras' sizes.
        depth_images: optional C entries, each an (H_c, W_c) rendered depth in metres or None.
        occlusion: apply the occlusion test.
        fusion: ``"nearest_center"``, ``"mean"`` or ``"min_depth"``.
        sightings: :func:`locate_in_cameras` of these points and cameras, computed before
            (the arguments it took are then not used again); None: located here.
        **visibility: the occlusion test's options (:data:`VISIBILITY_OPTIONS`):
            ``depth_kind``, what the depth images hold, ``"z"`` or ``"range"``; ``rel_tol``,
            the relative occlusion tolerance (None for
            :data:`~nidar_mi.geometry.visibility.DEFAULT_REL_TOL`); ``abs_tol``, the absolute
            one in metres; ``zbuffer_cell``, the z-buffer cell in pixels when a camera has no
            depth image.

    Returns:
        ``(values, observed, camera_index)``: (N,) float32 values (0 where no camera sees
        the point), (N,) bool observed flags, (N,) int64 index of the chosen camera
        (-1 where unobserved).

    Raises:
        NidarError: no cameras, an unknown fusion rule or option, or images / depth images
            that do not match the cameras in number or size; ``sightings`` of another cloud or
            camera count.
    """
    if isinstance(cameras, CameraModel):
        cameras = [cameras]
    if len(cameras) == 0:
        raise NidarError("sample_cameras: no cameras given")
    if fusion not in FUSION_RULES:
        raise NidarError(f"sample_cameras: fusion must be one of {FUSION_RULES}, not {fusion!r}")
    if len(images) != len(cameras):
        raise NidarError(f"sample_cameras: {len(cameras)} cameras but {len(images)} images")
    images = [np.asarray(img) for img in images]
    for k, (cam, img) in enumerate(zip(cameras, images, strict=True)):
        if img.shape != (cam.height, cam.width):
            raise NidarError(
                f"sample_cameras: image {k} is {img.shape}, camera {k} is {(cam.height, cam.width)}"
            )
    visibility = _visibility(visibility, "sample_cameras")
    if sightings is None:
        sightings = _locate(points, cameras, depth_images, occlusion, visibility, "sample_cameras")
    elif len(sightings.per_camera) != len(cameras) or sightings.n != len(np.asarray(points)):
        raise NidarError("sample_cameras: sightings of another cloud or other cameras")
    per_camera = [
        _sample_camera(cam, img, located)
        for cam, img, located in zip(cameras, images, sightings.per_camera, strict=True)
    ]
    if len(per_camera) == 1:  # every fusion rule gives the camera's own samples
        return _one_camera(sightings.n, *per_camera[0][:2])
    return _fuse(*_stacked(sightings.n, per_camera), fusion)
