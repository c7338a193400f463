"""``python -m nidar_mi.assign``: NIDAR intensity for point clouds from elsewhere.

Two ways in::

    python -m nidar_mi.assign --points cloud.ply --image cam.png --calib calib.yaml -o OUT
    python -m nidar_mi.assign --kitti DIR --frame 000003 -o OUT

``--points`` reads .ply/.pcd/.las/.bin (KITTI float32 x,y,z,i)/.npz; ``--calib`` is YAML/JSON with one
entry per camera (schema: :mod:`nidar_mi.io.calib`; the render command's ``calib.json`` works too,
``--lidar`` choosing the LiDAR of a scene with several), one ``--image`` per camera in the same
order: 8-bit colour PNG as a camera delivers it (RGBA loses alpha, 16-bit is reduced to 8 bit, a
greyscale image is used as R = G = B with a warning). ``--kitti`` reads ``velodyne/ID.bin``,
``image_2/ID.png`` and ``calib/ID.txt`` (camera P2; :func:`nidar_mi.datasets.kitti.load_frame`).

Points with a non-finite value (NaN or infinity, e.g. the no-return points of an organised
cloud) are dropped before any work, with a warning that counts them.

``--profile NAME|FILE`` chooses the sensor profile that turns NIDAR's map into the sensor's
intensity (:mod:`nidar_mi.datasets.sensor_profiles`): ``kitti-hdl64e`` by default with
``--kitti`` (fitted on the real KITTI frames at first use and cached), ``sim-905`` (the
simulator's) by default otherwise, or a file from ``python -m nidar_mi.calibrate``. A cloud's ``ring`` column gives the
profile its rings; with ``--kitti`` they are recovered from the storage order
(:func:`nidar_mi.datasets.kitti_rings.checked_rings`) and written as ``ring``. ``--branch I_hat``
without ``--profile`` assigns the dense head raw.

Output in OUT: ``points.npz`` with every column and metadata entry of the input (``xyz``,
``intensity``, ``ring``, ...) plus ``intensity_nidar`` (N float32, 0 where unobserved) and
``nidar_observed`` (N bool); plus ``points.ply`` and ``points.las`` (``--formats``). OUT is
published whole when everything succeeded (a non-empty OUT that is not an earlier output needs
``--overwrite``).
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from ..errors import NidarError
from ._common import parser, run

__all__ = ["main", "assign_intensity"]

FORMATS = ("npz", "ply", "las")


def assign_intensity(
    xyz, cameras, images, *, weights=None, occlusion=True, branch=None, profile=None, ring=None
) -> dict[str, np.ndarray]:
    """Per-point NIDAR intensity: ``{"intensity_nidar", "nidar_observed"}``.

    ``profile`` is a profile name or file (None: ``branch`` with the weights' own calibration,
    or raw for ``I_hat``); ``ring`` the points' rings for it (-1 unknown). ``branch`` None means
    the profile's branch (``R`` without a profile); a branch the profile was not fitted on is an
    error.
    """
    from ..datasets.sensor_profiles import resolve_profile
    from ..nidar.pipeline import NidarModel

    model = NidarModel.load(weights)
    prof = resolve_profile(profile, model) if profile is not None else None
    if (
        prof is not None
        and branch is not None
        and prof.branch is not None
        and branch != prof.branch
    ):
        raise NidarError(
            f"--branch {branch}: profile {prof.name} maps the {prof.branch} branch; "
            f"leave out --branch or fit a profile on {branch} (calibrate --branch {branch})"
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
    return {"intensity_nidar": res.intensity, "nidar_observed": res.observed}


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


def _write(out_dir: str, points: dict, formats, overwrite: bool) -> list[str]:
    from ..io.atomic import staged_directory
    from ..io.las import write_las
    from ..io.points import write_npz, write_ply

    writers = {"npz": write_npz, "ply": write_ply, "las": write_las}
    with staged_directory(out_dir, overwrite=overwrite, marker="points.npz") as stage:
        for fmt in formats:
            writers[fmt](os.path.join(stage, f"points.{fmt}"), points)
    return [os.path.join(out_dir, f"points.{fmt}") for fmt in formats]


def build_parser():
    p = parser("assign", "NIDAR intensity for a point cloud from camera images (or a KITTI frame).")
    src = p.add_argument_group("input")
    src.add_argument("--points", help="point cloud (.ply .pcd .las .bin .npz), LiDAR frame")
    src.add_argument(
        "--image",
        action="append",
        default=[],
        help="camera image (8-bit sRGB PNG as delivered), one per camera, in --calib's order",
    )
    src.add_argument("--calib", help="camera calibration (YAML/JSON, or render's calib.json)")
    src.add_argument(
        "--lidar", help="with a render calib.json of several LiDARs: the LiDAR of --points"
    )
    src.add_argument("--kitti", help="KITTI folder with velodyne/, image_2/, calib/")
    src.add_argument("--frame", help="KITTI frame id, e.g. 000003")
    p.add_argument("-o", "--out", help="output folder (default: out/assign/<name>)")
    p.add_argument("--weights", help="NIDAR weights folder (default: the shipped model)")
    p.add_argument("--formats", default=",".join(FORMATS), help="npz,ply,las (default: all)")
    p.add_argument("--no-occlusion", action="store_true", help="skip the occlusion test")
    p.add_argument(
        "--branch",
        default=None,
        choices=("R", "I_hat"),
        help="R: calibrated reflectance branch (the paper's, default); I_hat: dense intensity "
        "head; with --profile: the profile's branch by default, another one is an error",
    )
    p.add_argument(
        "--profile",
        help="sensor profile: kitti-hdl64e (default with --kitti), sim-905 (default otherwise) "
        "or a profile file from python -m nidar_mi.calibrate",
    )
    p.add_argument(
        "--overwrite", action="store_true", help="replace OUT even when it holds other files"
    )
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    return run(lambda: _assign(args))


def _inputs(args):
    """``(points, cameras, images, name)`` from the command line."""
    if args.kitti:
        if not args.frame:
            raise NidarError("--kitti needs --frame")
        from ..datasets.kitti import load_frame
        from ..datasets.kitti_rings import checked_rings

        frame = load_frame(args.kitti, args.frame)
        points = {"xyz": frame.xyz, "intensity": frame.intensity}
        ring = checked_rings(frame.xyz)
        if ring is not None:
            points["ring"] = ring
        return points, [frame.camera], [frame.rgb], f"kitti_{args.frame}"
    if not (args.points and args.calib and args.image):
        raise NidarError("give --points, --calib and --image (or --kitti DIR --frame ID)")
    from ..io.calib import load_calib
    from ..io.images import read_rgb8
    from ..io.point_cloud import read_point_cloud

    cameras = load_calib(args.calib, lidar=args.lidar)
    if len(cameras) != len(args.image):
        raise NidarError(
            f"{args.calib} has {len(cameras)} cameras but {len(args.image)} --image given"
        )
    images = [read_rgb8(im) for im in args.image]
    for cam, im, path in zip(cameras, images, args.image):
        if im.shape[:2] != (cam.height, cam.width):
            raise NidarError(
                f"{path}: image {im.shape[1]}x{im.shape[0]} does not match camera "
                f"'{cam.name}' {cam.width}x{cam.height}"
            )
    points = read_point_cloud(args.points)
    points["xyz"] = np.asarray(points["xyz"], dtype=np.float32)
    if "intensity" in points:
        points["intensity"] = np.asarray(points["intensity"], dtype=np.float32)
    name = os.path.splitext(os.path.basename(args.points))[0]
    return points, cameras, images, name


def _assign(args) -> None:
    from ..io.atomic import check_output_folder

    formats = [f.strip() for f in args.formats.split(",") if f.strip()]
    if not formats or any(f not in FORMATS for f in formats):
        raise NidarError(f"--formats: choose from {', '.join(FORMATS)} (got '{args.formats}')")
    if args.lidar and not args.calib:
        raise NidarError("--lidar applies to --calib (a render calib.json)")
    points, cameras, images, name = _inputs(args)
    out = args.out or os.path.join("out", "assign", name)
    check_output_folder(out, overwrite=args.overwrite, marker="points.npz")
    points = finite_points(points, args.points or f"KITTI frame {args.frame}")
    profile = args.profile
    if profile is None and args.kitti and args.branch in (None, "R"):
        profile = "kitti-hdl64e"
    ring = np.asarray(points["ring"], dtype=np.int64) if "ring" in points else None
    points.update(
        assign_intensity(
            points["xyz"],
            cameras,
            images,
            weights=args.weights,
            occlusion=not args.no_occlusion,
            branch=args.branch,
            profile=profile,
            ring=ring,
        )
    )
    written = _write(out, points, formats, args.overwrite)
    n, seen = len(points["xyz"]), int(points["nidar_observed"].sum())
    print(
        f"{seen} of {n} points seen by a camera ({100.0 * seen / max(n, 1):.1f} %); "
        f"wrote {', '.join(written)}"
    )
