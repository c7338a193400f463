"""``python -m nidar_mi.weather IN -o OUT --fog MOR_M | --rain MM_PER_H | --snow MM_PER_H``: fog,
rain or snow added to point clouds recorded in clear air.

IN is a point cloud (KITTI ``.bin``, ``.pcd``, ``.ply``, ``.las``/``.laz``, ``.npz``) or a
folder of them (not its subfolders); OUT is a folder that receives each cloud under its own
name and format, with ``weather.json`` (the weather, the sensor, the seed and, per cloud, the
points kept, moved to the fog or a particle, and lost). OUT is published whole when every cloud
succeeded (who may replace a non-empty OUT: :mod:`nidar_mi.io.ownership`).

The sensor (``--sensor``, a LiDAR preset; ``hdl64e``, KITTI's, by default) gives the range
window and, for ``hdl64e``, the detection threshold and receiver noise of the datasheet's link
budget; ``--threshold``, ``--noise``, ``--wavelength``, ``--divergence`` set them, and
``--intensity-mode`` / ``--intensity-scale`` say what the clouds' intensity is (KITTI's
reflectance in [0, 1]: ``compensated``, scale 1, the default). Deterministic given ``--seed``.

The work is :mod:`nidar_mi.cloud_weather`'s; this module finds the clouds, parses the command
line and writes the outputs.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

from ..io.ownership import Owner
from ._common import add_weather_args, out_path, parser, run, seed_arg, show_progress, weather_of

log = logging.getLogger("nidar_mi.weather")

__all__ = ["main", "build_parser", "EXTENSIONS", "MAX_POINTS"]

#: Cloud formats read and written (the output keeps the input's).
EXTENSIONS = (".bin", ".pcd", ".ply", ".las", ".laz", ".npz")
#: Most points of one cloud (a larger one is refused before any work): 20 million.
MAX_POINTS = 20_000_000
#: The flags of the library's parameters where the two names differ.
FLAGS = {"threshold": "--threshold", "intensity_scale": "--intensity-scale"}
#: The report of an output folder (the weather, the sensor, the clouds).
REPORT = "weather.json"


def _reported(folder: Path) -> list[str]:
    """The files an output folder of nidar_mi 0.1.0 (no record) lists in its report."""
    with open(folder / REPORT, encoding="utf-8") as f:
        return [REPORT, *json.load(f)["clouds"]]


#: Who writes a weather output folder (:mod:`nidar_mi.io.ownership`).
OWNER = Owner("weather", "clouds", names=(REPORT, *(f"*{e}" for e in EXTENSIONS)), listed=_reported)


def build_parser():
    p = parser(
        "weather",
        "Add fog, rain or snow to point clouds recorded in clear air (KITTI .bin, PCD, PLY, "
        "LAS, npz; a file or a folder of them).",
        verbose="one per cloud (its points in and out)",
    )
    p.add_argument("input", metavar="IN", help="point cloud file, or a folder of them")
    p.add_argument("-o", "--out", required=True, type=out_path, help="output folder")
    add_weather_args(p, what="to add")
    s = p.add_argument_group("the sensor that recorded the clouds")
    s.add_argument("--sensor", default="hdl64e", help="LiDAR preset (default hdl64e: KITTI's)")
    s.add_argument("--wavelength", type=float, default=None, help="nm (default 905)")
    s.add_argument(
        "--threshold", type=float, default=None, help="detection threshold, raw, gain 1 (1/m²)"
    )
    s.add_argument("--noise", type=float, default=None, help="receiver noise σ_n, the unit of T")
    s.add_argument(
        "--divergence", type=float, default=None, help="beam divergence, mrad (default 2)"
    )
    s.add_argument(
        "--intensity-mode",
        default=None,
        choices=("compensated", "raw"),
        help="the clouds' intensity: compensated (s ρ cos θ, KITTI's; default) or raw "
        "(s ρ cos θ / d²)",
    )
    s.add_argument("--intensity-scale", type=float, default=None, help="s (default 1)")
    s.add_argument(
        "--return-mode",
        default=None,
        choices=("strongest", "first", "last"),
        help="default strongest",
    )
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of the draws (default 0)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an OUT written by nidar_mi 0.1.0 (no record of its files); a file "
        "weather did not write is never removed",
    )
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    return run(lambda: _weather(args), flags=FLAGS, args=args)


def _clouds(path: str) -> list[Path]:
    """The clouds of IN: the file, or the supported files of the folder, sorted by name."""
    from ..errors import NidarError

    p = Path(path)
    if p.is_dir():
        found = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in EXTENSIONS)
        if not found:
            raise NidarError(f"{path}: no point cloud ({' '.join(EXTENSIONS)}) in the folder")
        return found
    from ..io.atomic import file_problem

    problem = file_problem(p, "file or folder")
    if problem:
        raise NidarError(f"{path}: {problem}")
    if p.suffix.lower() not in EXTENSIONS:
        raise NidarError(
            f"{path}: unknown point cloud format {p.suffix or '(none)'!r} "
            f"(expected one of {' '.join(EXTENSIONS)})"
        )
    return [p]


def _sensor(args):
    from ..cloud_weather import cloud_sensor

    return cloud_sensor(
        args.sensor,
        wavelength=args.wavelength,
        detection_threshold=args.threshold,
        receiver_noise_std=args.noise,
        beam_divergence=args.divergence,
        intensity_mode=args.intensity_mode,
        intensity_scale=args.intensity_scale,
        return_mode=args.return_mode,
    )


def _weather(args) -> None:
    from ..errors import NidarError
    from ..io.atomic import check_output_folder, staged_directory

    weather = weather_of(args)
    if weather is None or weather.clear:
        raise NidarError("give the weather to add: `fog`, `rain` or `snow`")
    sensor = _sensor(args)
    clouds = _clouds(args.input)
    publish = dict(owner=OWNER, overwrite=args.overwrite, inputs=[args.input])
    check_output_folder(args.out, **publish)
    names = [c.name for c in clouds]
    with staged_directory(args.out, **publish) as stage:
        report = _augment(clouds, stage, (weather, sensor, args.seed), show_progress(args))
        from ..io.atomic import atomic_write_json

        atomic_write_json(
            os.path.join(stage, REPORT),
            {
                "weather": weather.to_dict(),
                "sensor": sensor.__dict__,
                "seed": args.seed,
                "clouds": report,
            },
        )
    if not args.quiet:
        kept = sum(r["points_out"] for r in report.values())
        given = sum(r["points_in"] for r in report.values())
        print(
            f"{weather.describe()}: {len(names)} clouds, {given} points in, {kept} out; "
            f"wrote {args.out}"
        )


def _augment(clouds: list[Path], stage, setting, progress: bool) -> dict:
    """Add the weather to every cloud, writing each into ``stage``; per cloud, the counts."""
    import numpy as np

    from ..cloud_intensity import finite_points
    from ..cloud_weather import add_weather
    from ..errors import NidarError
    from ..io.point_cloud import read_point_cloud
    from ..progress import progress_bar

    weather, sensor, seed = setting
    report = {}
    with progress_bar(total=len(clouds), show=progress, desc="weather", unit="cloud") as bar:
        for index, path in enumerate(clouds):
            points = finite_points(read_point_cloud(path), str(path))
            n = len(points["xyz"])
            if n > MAX_POINTS:
                raise NidarError(f"{path}: {n} points, more than the {MAX_POINTS} a cloud may have")
            rng = np.random.default_rng(np.random.SeedSequence([seed, index]))
            out = add_weather(points, weather, sensor, rng)
            _write(Path(stage) / path.name, out)
            kinds = np.bincount(out["scatterer"], minlength=4)
            log.debug("%s: %d points in, %d out", path.name, n, len(out["xyz"]))
            report[path.name] = {
                "points_in": n,
                "points_out": int(len(out["xyz"])),
                "surface": int(kinds[0]),
                "fog": int(kinds[1]),
                "drop": int(kinds[2]),
                "flake": int(kinds[3]),
            }
            bar.update(1)
    return report


def _write(path: Path, points: dict) -> None:
    """Write a cloud in the format of its name."""
    from ..io.kitti import write_kitti_bin
    from ..io.las import write_las
    from ..io.pcd import write_pcd
    from ..io.points import write_npz, write_ply

    suffix = path.suffix.lower()
    if suffix == ".bin":
        write_kitti_bin(path, points["xyz"], points["intensity"])
    elif suffix in (".las", ".laz"):
        write_las(path, points)
    else:
        {".pcd": write_pcd, ".ply": write_ply, ".npz": write_npz}[suffix](path, points)
