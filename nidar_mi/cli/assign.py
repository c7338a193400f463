"""``python -m nidar_mi.assign``: NIDAR intensity for point clouds from elsewhere.

Two ways in::

    python -m nidar_mi.assign --points cloud.ply --image cam.png --calib calib.yaml -o OUT
    python -m nidar_mi.assign --kitti DIR --frame 000003 -o OUT

``--points`` reads .ply/.pcd/.las/.bin (KITTI float32 x,y,z,i)/.npz; ``--calib`` is YAML/JSON with one
entry per camera (schema: :mod:`nidar_mi.io.calib`; the render command's ``calib.json`` works too,
``--lidar`` choosing the LiDAR of a scene with several), one ``--image`` per camera in the same
order: 8-bit colour PNG as a camera delivers it (RGBA loses alpha, 16-bit is reduced to 8 bit, a
greyscale image is used as R = G = B with a warning). ``--kitti`` reads ``velodyne/ID.bin``,
``image_2/ID.png`` and ``calib/ID.txt`` (camera P2; :func:`nidar_mi.datasets.kitti_objects.load_kitti_frame`).

Points with a non-finite value (NaN or infinity, e.g. the no-return points of an organised
cloud) are dropped before any work, with a warning that counts them.

``--profile NAME|FILE`` chooses the sensor profile that turns NIDAR's map into the sensor's
intensity (:mod:`nidar_mi.datasets.sensor_profiles`): ``kitti-hdl64e`` by default with ``--kitti`` (fitted
on the real KITTI frames at first use and cached), ``sim-905`` (the simulator's) by default for
a render of the simulator (a renderer ``calib.json``), ``generic-compensated`` (a closed form,
``R·|cos θ|``) with a warning for any other cloud (an unknown sensor; ``generic-raw`` for one
without range compensation), or a file from ``python -m nidar_mi.calibrate``. One stderr line
names the profile used. A cloud's ``ring`` column gives the
profile its rings; with ``--kitti`` they are recovered from the storage order
(:func:`nidar_mi.datasets.kitti_rings.checked_rings`) and written as ``ring``. ``--branch I_hat``
without ``--profile`` assigns the dense head raw.

Output in OUT: ``points.npz`` with every column and metadata entry of the input (``xyz``,
``intensity``, ``ring``, ...) plus ``intensity_nidar`` (N float32, 0 where unobserved) and
``nidar_observed`` (N bool); plus ``points.ply`` and ``points.las`` (``--formats``). OUT is
published whole when everything succeeded (a non-empty OUT that is not an earlier output needs
``--overwrite``).

The work is :mod:`nidar_mi.cloud_intensity`'s; this module parses the command line.
"""

from __future__ import annotations

import os
import warnings

from ..errors import NidarError
from ..extras import require
from ._common import out_path, parser, run

__all__ = ["main", "build_parser"]

#: The flags of the library's parameters where the two names differ.
FLAGS = {"images": "--image"}


def build_parser():
    p = parser(
        "assign",
        "NIDAR intensity for a point cloud from camera images (or a KITTI frame).",
        verbose="the points read and dropped, the profile, the points each camera sees",
    )
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
    p.add_argument("-o", "--out", type=out_path, help="output folder (default: out/assign/<name>)")
    p.add_argument("--weights", help="NIDAR weights folder (default: the shipped model)")
    p.add_argument("--formats", default="npz,ply,las", help="npz,ply,las (default: all)")
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
        help="sensor profile: kitti-hdl64e (default with --kitti), sim-905 (default for a "
        "render's calib.json), generic-compensated (default otherwise, with a warning), "
        "generic-raw, or a profile file from python -m nidar_mi.calibrate",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an OUT written by nidar_mi 0.1.0 (no record of its files); a file "
        "assign did not write is never removed",
    )
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    def work():
        require("nidar", "assign")
        _assign(args)

    return run(work, flags=FLAGS, args=args)


def _formats(text: str) -> list[str]:
    """The ``--formats`` list."""
    from ..cloud_intensity import FORMATS

    formats = [f.strip() for f in text.split(",") if f.strip()]
    if not formats or any(f not in FORMATS for f in formats):
        raise NidarError(f"--formats: choose from {', '.join(FORMATS)} (got '{text}')")
    return formats


#: The input flags of the --points mode, each with its argparse attribute.
_OWN_INPUTS = {"--points": "points", "--image": "image", "--calib": "calib", "--lidar": "lidar"}


def _inputs(args):
    """The cloud, its cameras and images named on the command line."""
    from ..cloud_intensity import kitti_inputs, read_inputs

    if args.kitti:
        given = [f for f, v in _OWN_INPUTS.items() if getattr(args, v)]
        if given:
            raise NidarError(
                f"--kitti reads the frame's own cloud, image and calibration: drop {', '.join(given)}"
            )
        if not args.frame:
            raise NidarError("--kitti needs --frame")
        return kitti_inputs(args.kitti, args.frame)
    if args.frame:
        raise NidarError("--frame needs --kitti (the KITTI folder of the frame)")
    if args.lidar and not args.calib:
        raise NidarError("--lidar applies to --calib (a render calib.json)")
    if not (args.points and args.calib and args.image):
        raise NidarError("give --points, --calib and --image (or --kitti DIR --frame ID)")
    return read_inputs(args.points, args.calib, args.image, lidar=args.lidar)


def _profile(args, inputs) -> tuple[str | None, bool]:
    """The profile named or chosen for the cloud, and whether its sensor is unknown (no
    profile named for a cloud that is neither KITTI's nor the simulator's)."""
    from ..datasets.sensor_profiles import default_profile

    if args.profile is not None or args.branch not in (None, "R"):
        return args.profile, False
    unknown = not (inputs.kitti or inputs.simulator)
    return default_profile(kitti=inputs.kitti, simulator=inputs.simulator), unknown


def _assign(args) -> None:
    from ..cloud_intensity import ASSIGN_OWNER, assign_cloud, write_points
    from ..datasets.sensor_profiles import profile_line, warn_unknown_sensor
    from ..io.atomic import check_output_folder

    formats = _formats(args.formats)
    read = [args.points, args.calib, *args.image, args.kitti, args.weights, args.profile]
    publish = dict(owner=ASSIGN_OWNER, overwrite=args.overwrite, inputs=read)
    if args.out:  # before the inputs are read; the default OUT is named after them
        check_output_folder(args.out, **publish)
    # the inputs' warnings are shown once the cloud has its intensity: bad input is one line
    with warnings.catch_warnings(record=True) as held:
        warnings.simplefilter("always")
        inputs = _inputs(args)
        out = args.out or os.path.join("out", "assign", inputs.name)
        check_output_folder(out, **publish)
        profile, unknown = _profile(args, inputs)
        points = assign_cloud(
            inputs,
            weights=args.weights,
            occlusion=not args.no_occlusion,
            branch=args.branch,
            profile=profile,
        )
    for text in dict.fromkeys(str(w.message) for w in held):
        warnings.warn(text, RuntimeWarning, stacklevel=1)
    written = write_points(out, points, formats, args.overwrite)
    if not args.quiet:
        print(profile_line(profile, branch=args.branch))
    if unknown:
        warn_unknown_sensor()
    n, seen = len(points["xyz"]), int(points["nidar_observed"].sum())
    print(
        f"{seen} of {n} points seen by a camera ({100.0 * seen / max(n, 1):.1f} %); "
        f"wrote {', '.join(written)}"
    )
