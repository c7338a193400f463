"""NIDAR intensity for point clouds from elsewhere: the inputs, the clean-up, the assignment,
the output folder.

A cloud comes with its cameras and one image per camera (:func:`read_inputs`: point, calibration
and image files; :func:`kitti_inputs`: a KITTI frame). :func:`assign_cloud` drops the points
with a non-finite value (:func:`finite_points`), picks the sensor profile and adds the
columns of :func:`assign_intensity`; :func:`write_points` publishes the result whole.
``python -m nidar_mi.assign`` (:mod:`nidar_mi.cli.assign`) is this module on the command line.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import warnings

import numpy as np

from .errors import NidarError
from .io.ownership import Owner

__all__ = [
    "ASSIGN_OWNER",
    "FORMATS",
    "CloudInputs",
    "assign_cloud",
    "assign_intensity",
    "check_observed",
    "finite_points",
    "kitti_inputs",
    "read_inputs",
    "write_points",
]

log = logging.getLogger("nidar_mi.assign")

#: Output formats of :func:`write_points`: ``points.<format>``.
FORMATS = ("npz", "ply", "las")
#: Who writes an assign output folder (:mod:`nidar_mi.io.ownership`).
ASSIGN_OWNER = Owner("assign", "points", names=tuple(f"points.{f}" for f in FORMATS))


@dataclasses.dataclass
class CloudInputs:
    """A point cloud and the cameras that see it."""

    points: dict[str, np.ndarray]
    """Columns of N points: ``xyz`` (N, 3) float32 in the LiDAR frame (m), optional
    ``intensity`` (N,) float32, ``ring`` (N,) int, any other column kept as it is."""
    cameras: list
    """The cameras (:class:`nidar_mi.geometry.CameraModel`), one per image."""
    images: list[np.ndarray]
    """One (H, W, 3) uint8 sRGB image per camera."""
    name: str
    """A short name of the cloud (the command's default output folder ``out/assign/<name>``)."""
    where: str
    """How messages name the cloud (its file, or the KITTI frame)."""
    kitti: bool = False
    """The cloud is a KITTI HDL-64E frame (its sensor profile is ``kitti-hdl64e``)."""
    simulator: bool = False
    """The cloud is a render of the simulator (its calibration is a renderer ``calib.json``; its
    sensor profile is the weights' own, ``sim-905``)."""
    kitti_frame: tuple[str, str] | None = None
    """``(folder, frame id)`` of a KITTI frame: its ``kitti-hdl64e`` profile is fitted on the
    folder's other frames, never on this one."""


def kitti_inputs(folder: str, frame: str) -> CloudInputs:
    """KITTI ``velodyne/ID.bin``, ``image_2/ID.png`` and ``calib/ID.txt`` (camera P2); the rings
    recovered from the storage order (:func:`nidar_mi.datasets.kitti_rings.checked_rings`)."""
    from .datasets.kitti_objects import load_kitti_frame
    from .datasets.kitti_rings import checked_rings

    f = load_kitti_frame(folder, frame)
    points = {"xyz": f.xyz, "intensity": f.intensity}
    ring = checked_rings(f.xyz)
    if ring is not None:
        points["ring"] = ring
    return CloudInputs(
        points,
        [f.camera],
        [f.rgb],
        f"kitti_{frame}",
        f"KITTI frame {frame}",
        kitti=True,
        kitti_frame=(folder, frame),
    )


def read_inputs(points: str, calib: str, images: list[str], lidar: str | None = None):
    """A cloud file (.ply .pcd .las .bin .npz) with its calibration file and one image file per
    camera, in the calibration's order.

    Args:
        points: the point cloud file.
        calib: YAML/JSON camera calibration, or the render command's ``calib.json``.
        images: the image files (8-bit colour PNG as a camera delivers it).
        lidar: with a ``calib.json`` of several LiDARs, the LiDAR of ``points``.

    Returns:
        The :class:`CloudInputs` (``xyz`` and ``intensity`` as float32).

    Raises:
        NidarError: the count of images or an image's size does not match the cameras, or the
            cloud is empty.
    """
    from .io.calib import is_render_calib, load_calib
    from .io.images import read_rgb8
    from .io.point_cloud import read_point_cloud

    cameras = load_calib(calib, lidar=lidar)
    if len(cameras) != len(images):
        raise NidarError(f"{calib} has {len(cameras)} cameras but {len(images)} `images` given")
    # the cloud before the images: an empty one is refused before an image's warning is shown
    cloud = read_point_cloud(points)
    if len(cloud["xyz"]) == 0:
        raise NidarError(f"{points}: the point cloud holds no points")
    rgb = [read_rgb8(im) for im in images]
    for cam, im, path in zip(cameras, rgb, images):
        if im.shape[:2] != (cam.height, cam.width):
            raise NidarError(
                f"{path}: image {im.shape[1]}x{im.shape[0]} does not match camera "
                f"'{cam.name}' {cam.width}x{cam.height}"
            )
    cloud["xyz"] = np.asarray(cloud["xyz"], dtype=np.float32)
    if "intensity" in cloud:
        cloud["intensity"] = np.asarray(cloud["intensity"], dtype=np.float32)
    name = os.path.splitext(os.path.basename(points))[0]
    return CloudInputs(cloud, cameras, rgb, name, points, simulator=is_render_calib(calib))


def assign_intensity(
    xyz,
    cameras,
    images,
    *,
    weights=None,
    occlusion=True,
    branch=None,
    profile=None,
    ring=None,
) -> dict[str, np.ndarray]:
    """Per-point NIDAR intensity: ``{"intensity_nidar", "reflectance_nidar", "nidar_observed"}``.

    Args:
        xyz: (N, 3) points in the LiDAR frame (m).
        cameras: the cameras; ``images`` one (H, W, 3) uint8 image each.
        weights: NIDAR weights folder (None: the shipped model), or the loaded model.
        occlusion: drop points another point hides from the camera.
        branch: ``R`` or ``I_hat``; None: the profile's branch (``R`` without a profile). A
            branch the profile was not fitted on is an error.
        profile: a profile name or file, or the profile itself (None: ``branch`` with the
            weights' own calibration, or raw for ``I_hat``).
        ring: (N,) the points' rings for the profile (-1 unknown), or None.

    Returns:
        ``intensity_nidar`` (N,) float32 (0 where unobserved), ``reflectance_nidar`` (N,) float32
        (IRNet's reflectance R at the point, the per-surface cue, 0 where unobserved),
        ``nidar_observed`` (N,) bool.
    """
    from .datasets.sensor_profiles import resolve_profile
    from .nidar.pipeline import NidarModel
    from .profiles import SensorProfile

    model = weights if isinstance(weights, NidarModel) else NidarModel.load(weights)
    prof = profile
    if profile is not None and not isinstance(profile, SensorProfile):
        prof = resolve_profile(profile, model)
    if (
        prof is not None
        and branch is not None
        and prof.branch is not None
        and branch != prof.branch
    ):
        raise NidarError(
            f"`branch` {branch}: profile {prof.name} maps the {prof.branch} branch; "
            f"leave out `branch` or fit a profile on {branch} (calibrate --branch {branch})"
        )
    if branch is None:
        branch = prof.branch if prof is not None and prof.branch is not None else "R"
    for cam, im in zip(cameras, images):
        if im.shape[:2] != (cam.height, cam.width):
            raise NidarError(
                f"image {im.shape[1]}x{im.shape[0]} does not match camera '{cam.name}' "
                f"{cam.width}x{cam.height}"
            )
    res = model.point_intensity(
        xyz, cameras, images, occlusion=occlusion, branch=branch, profile=prof, ring=ring
    )
    return {
        "intensity_nidar": res.intensity,
        "reflectance_nidar": res.reflectance,
        "nidar_observed": res.observed,
    }


def check_observed(xyz, cameras) -> None:
    """Refuse, before any inference, a cloud of which no point falls inside a camera image.

    A camera whose principal point lies outside its image (an image far too small for the
    calibration, e.g. a thumbnail beside a full-size calibration) is warned about first.

    Args:
        xyz: (N, 3) points in the LiDAR frame (m).
        cameras: the cameras (:class:`~nidar_mi.geometry.camera_model.CameraModel`).

    Raises:
        NidarError: N > 0 and no point projects into any camera's image.
    """
    import warnings

    from .geometry.projection import in_image, project

    n = len(xyz)
    if n == 0:
        return
    seen = np.zeros(n, dtype=bool)
    for cam in cameras:
        uv, _, front = project(xyz, cam)
        inside = in_image(uv[front], cam)
        seen[front] |= inside
        log.debug("camera '%s': %d of %d points fall inside its image", cam.name, inside.sum(), n)
        cx, cy = cam.K[0, 2], cam.K[1, 2]
        if not (0 <= cx <= cam.width and 0 <= cy <= cam.height):
            warnings.warn(
                f"camera '{cam.name}': the image is {cam.width}x{cam.height} but the "
                f"calibration's principal point is at ({cx:g}, {cy:g}): an image far too small "
                "for the calibration",
                stacklevel=2,
            )
    if not seen.any():
        raise NidarError(f"0 of {n} points observed: no point falls inside a camera image")


def finite_points(points: dict, where: str) -> dict:
    """``points`` without the points that hold a non-finite value in any float column.

    Warns with the count when points are dropped.

    Raises:
        NidarError: the cloud is empty, or no finite point is left.
    """
    n = len(points["xyz"])
    if n == 0:
        raise NidarError(f"{where}: the point cloud holds no points")
    keep = np.ones(n, dtype=bool)
    for value in points.values():
        a = np.asarray(value)
        if a.dtype.kind == "f" and a.ndim >= 1 and a.shape[0] == n:
            keep &= np.isfinite(a.reshape(n, -1)).all(axis=1)
    dropped = int(n - keep.sum())
    if dropped == 0:
        return points
    if dropped == n:
        raise NidarError(f"{where}: none of its {n} points has finite coordinates and values")
    warnings.warn(
        f"{where}: dropped {dropped} of {n} points with NaN or infinite values",
        RuntimeWarning,
        stacklevel=2,
    )
    out = {}
    for key, value in points.items():
        a = np.asarray(value)
        out[key] = a[keep] if a.ndim >= 1 and a.shape[0] == n and a.dtype.kind != "U" else a
    return out


def assign_cloud(
    inputs: CloudInputs, *, weights=None, occlusion=True, branch=None, profile=None
) -> dict[str, np.ndarray]:
    """The cloud's finite points with NIDAR's columns added (:func:`assign_intensity`).

    ``profile`` None on the ``R`` branch (None or ``R``) picks the cloud's default
    (:func:`nidar_mi.datasets.sensor_profiles.default_profile`): ``kitti-hdl64e`` for a KITTI
    frame, the weights' own for a render of the simulator, else ``generic-compensated`` with a
    warning (an unknown sensor); on ``I_hat`` the raw head. The cloud's ``ring`` column, when
    present, gives the profile its rings.
    """
    from .datasets.sensor_profiles import DEFAULT_KITTI_PROFILE

    points = dict(finite_points(inputs.points, inputs.where))
    log.debug(
        "%s: %d points read, %d finite", inputs.where, len(inputs.points["xyz"]), len(points["xyz"])
    )
    check_observed(points["xyz"], inputs.cameras)
    if profile is None and branch in (None, "R"):
        from .datasets.sensor_profiles import default_profile, warn_unknown_sensor

        profile = default_profile(kitti=inputs.kitti, simulator=inputs.simulator)
        if not (inputs.kitti or inputs.simulator):
            warn_unknown_sensor()
    ring = np.asarray(points["ring"], dtype=np.int64) if "ring" in points else None
    if inputs.kitti_frame is not None and str(profile) == DEFAULT_KITTI_PROFILE:
        from .datasets.sensor_profiles import resolve_profile
        from .nidar.pipeline import NidarModel

        weights = NidarModel.load(weights)  # kitti-hdl64e of the frame's own folder, not of it
        profile = resolve_profile(profile, weights, kitti_frame=inputs.kitti_frame)
    points.update(
        assign_intensity(
            points["xyz"],
            inputs.cameras,
            inputs.images,
            weights=weights,
            occlusion=occlusion,
            branch=branch,
            profile=profile,
            ring=ring,
        )
    )
    return points


def write_points(out_dir: str, points: dict, formats, overwrite: bool = False) -> list[str]:
    """``out_dir/points.<format>`` for each of ``formats`` (:data:`FORMATS`), published whole.

    Returns:
        The paths written.
    """
    from .io.atomic import staged_directory
    from .io.las import write_las
    from .io.points import write_npz, write_ply

    writers = {"npz": write_npz, "ply": write_ply, "las": write_las}
    with staged_directory(out_dir, owner=ASSIGN_OWNER, overwrite=overwrite) as stage:
        for fmt in formats:
            writers[fmt](os.path.join(stage, f"points.{fmt}"), points)
    return [os.path.join(out_dir, f"points.{fmt}") for fmt in formats]
