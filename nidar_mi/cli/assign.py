"""``python -m nidar_mi.assign``: NIDAR intensity for point clouds from elsewhere.

Two ways in::

    python -m nidar_mi.assign --points cloud.ply --image cam.png --calib calib.yaml -o OUT
    python -m nidar_mi.assign --kitti DIR --frame 000003 -o OUT

``--points`` reads .ply/.pcd/.las/.bin (KITTI float32 x,y,z,i)/.npz; ``--calib`` is YAML/JSON with one
entry per camera (schema: :mod:`nidar_mi.io.calib`; the render command's ``calib.json`` of a scene
with one LiDAR works too), one ``--image`` per camera in the same order. ``--kitti`` reads
``velodyne/ID.bin``, ``image_2/ID.png`` and ``calib/ID.txt`` (camera P2;
:func:`nidar_mi.datasets.kitti.load_frame`).

``--profile NAME|FILE`` chooses the sensor profile that turns NIDAR's map into the sensor's
intensity (:mod:`nidar_mi.nidar.profiles`): ``kitti-hdl64e`` by default with ``--kitti`` (fitted
on the real KITTI frames at first use and cached; the rings come from the scan order,
:func:`nidar_mi.datasets.kitti_rings.checked_rings`), ``sim-905`` (the simulator's) by default otherwise,
or a file from ``python -m nidar_mi.calibrate``. A cloud with a ``ring`` field gives its rings to
the profile. ``--branch I_hat`` without ``--profile`` assigns the dense head raw.

Output in OUT: ``points.npz`` with ``xyz`` (N,3 float32), the input's own ``intensity`` when it has
one, ``intensity_nidar`` (N float32, 0 where unobserved) and ``nidar_observed`` (N bool); plus
``points.ply`` and ``points.las`` (``--formats``). Files appear only when everything succeeded.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import NidarError
from ._common import parser, run

__all__ = ["main", "assign_intensity"]

FORMATS = ("npz", "ply", "las")


def assign_intensity(
    xyz, cameras, images, *, weights=None, occlusion=True, branch="R", profile=None, ring=None
) -> dict[str, np.ndarray]:
    """Per-point NIDAR intensity: ``{"intensity_nidar", "nidar_observed"}``.

    ``profile`` is a profile name or file (None: ``branch`` with the weights' own calibration,
    or raw for ``I_hat``); ``ring`` the points' rings for it (-1 unknown).
    """
    from ..nidar.pipeline import NidarModel
    from ..nidar.profiles import resolve_profile

    model = NidarModel.load(weights)
    prof = resolve_profile(profile, model) if profile is not None else None
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
    p = parser("assign", __doc__.split("\n")[0])
    src = p.add_argument_group("input")
    src.add_argument("--points", help="point cloud (.ply .pcd .las .bin .npz), LiDAR frame")
    src.add_argument(
        "--image", action="append", default=[], help="camera image (8-bit sRGB), one per camera"
    )
    src.add_argument("--calib", help="camera calibration (YAML/JSON)")
    src.add_argument("--kitti", help="KITTI folder with velodyne/, image_2/, calib/")
    src.add_argument("--frame", help="KITTI frame id, e.g. 000003")
    p.add_argument("-o", "--out", help="output folder (default: out/assign/<name>)")
    p.add_argument("--weights", help="NIDAR weights folder (default: the shipped model)")
    p.add_argument("--formats", default=",".join(FORMATS), help="npz,ply,las")
    p.add_argument("--no-occlusion", action="store_true", help="skip the occlusion test")
    p.add_argument(
        "--branch",
        default="R",
        choices=("R", "I_hat"),
        help="R: calibrated reflectance branch (the paper's, default); I_hat: dense intensity head",
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


def _assign(args) -> None:
    formats = [f.strip() for f in args.formats.split(",") if f.strip()]
    if not formats or any(f not in FORMATS for f in formats):
        raise NidarError(f"--formats: choose from {', '.join(FORMATS)} (got '{args.formats}')")
    if args.kitti:
        if not args.frame:
            raise NidarError("--kitti needs --frame")
        from ..datasets.kitti import load_frame
        from ..datasets.kitti_rings import checked_rings

        frame = load_frame(args.kitti, args.frame)
        cameras, images, name = [frame.camera], [frame.rgb], f"kitti_{args.frame}"
        points = {"xyz": frame.xyz, "intensity": frame.intensity}
        ring = checked_rings(frame.xyz)
        profile = args.profile or ("kitti-hdl64e" if args.branch == "R" else None)
    else:
        if not (args.points and args.calib and args.image):
            raise NidarError("give --points, --calib and --image (or --kitti DIR --frame ID)")
        from ..io.calib import load_calib
        from ..io.images import read_png
        from ..io.point_cloud import read_point_cloud

        cloud = read_point_cloud(args.points)
        cameras = load_calib(args.calib)
        if len(cameras) != len(args.image):
            raise NidarError(
                f"{args.calib} has {len(cameras)} cameras but {len(args.image)} --image given"
            )
        images = [read_png(im)[..., :3] for im in args.image]
        if any(im.dtype != np.uint8 for im in images):
            raise NidarError("--image: 8-bit images expected")
        points = {"xyz": np.asarray(cloud["xyz"], dtype=np.float32)}
        if "intensity" in cloud:
            points["intensity"] = np.asarray(cloud["intensity"], dtype=np.float32)
        ring = np.asarray(cloud["ring"], dtype=np.int64) if "ring" in cloud else None
        profile = args.profile
        name = os.path.splitext(os.path.basename(args.points))[0]
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
    out = args.out or os.path.join("out", "assign", name)
    written = _write(out, points, formats, args.overwrite)
    n, seen = len(points["xyz"]), int(points["nidar_observed"].sum())
    print(
        f"{seen} of {n} points seen by a camera ({100.0 * seen / max(n, 1):.1f} %); wrote {', '.join(written)}"
    )
