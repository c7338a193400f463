"""``python -m nidar_mi.reconstruct DRIVE -o OUT``: re-simulate a recorded drive
(:mod:`nidar_mi.resim`).

Builds a Mitsuba scene from the drive's scans (meshes with per-vertex NIR reflectance), recovers
the sensor (per-laser layout and gains, range response, intensity offset, detection threshold and
receiver noise) by differentiating the ``lidar`` plugin's return model, re-simulates the held-out
frames and scores them with the baselines. Writes ``OUT/scene.xml`` (and its files),
``OUT/poses.txt``, ``OUT/heldout/<id>.bin`` and ``OUT/report.json``; see
:mod:`nidar_mi.resim.reconstruction`.
"""

from __future__ import annotations

from ._common import parser, run, show_progress

__all__ = ["main", "build_parser"]


#: The steps a flag switches off, and what each does by default (``--help``).
STEP_SWITCHES = (
    (
        "--no-moving",
        "held-out frames see the static surfaces only (default: with the surfaces that moved, "
        "as the training frame nearest in time saw them, moved on at the velocity another "
        "training frame gives them)",
    ),
    (
        "--no-holes",
        "keep the held-out frames' returns where the training scans next to them returned "
        "nothing, or a few scattered returns short of them (default: dropped, the surfaces "
        "too dark for the sensor)",
    ),
    (
        "--no-see-through",
        "keep the static surfaces that the training scans next to a held-out frame saw through "
        "(default: hidden at that frame, layers no longer there)",
    ),
    (
        "--no-splats",
        "no splats for the returns that the scans' meshes leave out (foliage, edges, far "
        "surfaces; default: one quad per such return off the mesh, its range-image cell on its "
        "local plane)",
    ),
    (
        "--no-range-offsets",
        "no per-laser range offsets (default: each laser's offset recovered from the training "
        "scans, taken out of their returns and written into the recovered sensor)",
    ),
    ("--no-prior", "no NIDAR prior and no NIDAR baseline (no images)"),
)


def _add_step_switches(p) -> None:
    for flag, text in STEP_SWITCHES:
        p.add_argument(flag, action="store_true", help=text)


def build_parser():
    from ..resim.reconstruction import (
        MAX_CARVE_PASSES,
        MAX_FRAMES,
        MAX_ITERATIONS,
        ReconstructOptions,
    )
    from ..resim.write import DEFAULT_ALBEDO_SCALE

    d = ReconstructOptions("", "")
    p = parser(
        "reconstruct",
        "Re-simulate a recorded drive (KITTI layout: DRIVE/velodyne/*.bin, optional poses.txt, "
        "image_2/ and calib/): surfaces meshed from the scans, their reflectance and the "
        "sensor's response fitted by differentiable inversion, held-out frames re-simulated "
        "and scored against their real scans.",
        verbose="one line per step (read, poses, mesh, fit, write, evaluate) with its wall time",
    )
    p.add_argument("drive", help="drive folder (velodyne/<id>.bin, >= 2 scans)")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.add_argument(
        "--holdout",
        default="",
        metavar="IDS",
        help="frame ids never used to build or fit anything: a,b,c and ranges a:b (ids of the "
        "same width, ends included)",
    )
    p.add_argument(
        "--poses",
        default=None,
        metavar="FILE",
        help="KITTI poses (LiDAR to world, one line per scan in sorted order; default: "
        "DRIVE/poses.txt, else KISS-ICP odometry)",
    )
    p.add_argument(
        "--voxel", type=float, default=d.voxel_m, help=f"mesh vertex spacing, m ({d.voxel_m})"
    )
    p.add_argument(
        "--iterations",
        type=int,
        default=d.iterations,
        help=f"fit steps ({d.iterations}; at most {MAX_ITERATIONS})",
    )
    p.add_argument(
        "--carve-passes",
        type=int,
        default=d.carve_passes,
        help=f"free-space carving passes ({d.carve_passes}; 0: none; at most {MAX_CARVE_PASSES})",
    )
    p.add_argument(
        "--transient-frames",
        type=int,
        default=d.transient_frames,
        metavar="N",
        help="remove the surfaces that the last N training frames to observe them saw through "
        f"(objects that moved away; {d.transient_frames}; 0: keep them)",
    )
    _add_step_switches(p)
    p.add_argument("--weights", default=None, help="NIDAR weights folder (default: shipped)")
    p.add_argument(
        "--albedo-scale",
        type=float,
        default=None,
        metavar="K",
        help="the fitted ρ over the surfaces' reflectance, e.g. from a target of known "
        "reflectance (default: NIDAR's, from the images; without them "
        f"{DEFAULT_ALBEDO_SCALE}, KITTI's HDL-64E)",
    )
    p.add_argument("--seed", type=int, default=d.seed, help="sampling seed (0)")
    p.add_argument(
        "--max-frames",
        type=int,
        default=MAX_FRAMES,
        metavar="N",
        help=f"the most scans a drive may have ({MAX_FRAMES}); more are refused before any work",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an OUT written by nidar_mi 0.1.0 (no record of its files); a file "
        "reconstruct did not write is never removed",
    )
    return p


def _summary(report: dict, out: str) -> str:
    mean = report["heldout"]["mean"]
    lines = [f"scene: {out}/scene.xml ({report['mesh']['faces']} triangles)"]
    if mean:
        lines.append(
            f"held out {len(report['holdout'])} frames: Chamfer {mean['chamfer_m']:.3f} m, "
            f"F-score@0.1m {mean['fscore']:.3f}"
        )
        for name, m in mean["intensity"].items():
            lines.append(f"  {name:<20} Spearman {m['spearman']:.3f}  RMSE {m['rmse']:.3f}")
    lines.append(f"report: {out}/report.json")
    return "\n".join(lines)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    def work():
        from ..backend import set_variant
        from ..errors import check_seed
        from ..resim.drive_folder import parse_ids
        from ..resim.reconstruction import ReconstructOptions, check, reconstruct

        options = ReconstructOptions(
            drive=args.drive,
            out=args.out,
            holdout=tuple(parse_ids(args.holdout, limit=max(args.max_frames, 2))),
            poses=args.poses,
            voxel_m=args.voxel,
            iterations=args.iterations,
            carve_passes=args.carve_passes,
            transient_frames=args.transient_frames,
            moving=not args.no_moving,
            holes=not args.no_holes,
            through=not args.no_see_through,
            splats=not args.no_splats,
            range_offsets=not args.no_range_offsets,
            prior=not args.no_prior,
            weights=args.weights,
            albedo_scale=args.albedo_scale,
            seed=check_seed(args.seed),
            max_frames=args.max_frames,
            progress=show_progress(args),
            overwrite=args.overwrite,
        )
        check(options)  # every input refused before the variant starts
        set_variant()
        report = reconstruct(options)
        if not args.quiet:
            print(_summary(report, args.out))

    return run(work, flags={"voxel_m": "--voxel"}, args=args)
