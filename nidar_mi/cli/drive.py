"""``python -m nidar_mi.drive -o OUT``: the drive study (odometry and loop closure per intensity
source on a simulated drive; :mod:`nidar_mi.eval.drive.study`).

Writes ``OUT/results.json``, ``OUT/report.md`` and figures; the scene, the sweeps (a sequence
folder per kind, published whole) and NIDAR's columns are cached under ``OUT`` (an interrupted
run resumes from the last step it completed; new NIDAR weights recompute only NIDAR's columns
and the analysis).
"""

from __future__ import annotations

from ..extras import require
from ._common import out_path, parser, run, show_progress

__all__ = ["main", "build_parser"]


def build_parser():
    from ..eval.drive.study import SOURCES, StudyConfig

    d = StudyConfig()
    p = parser(
        "drive",
        "Render a drive through a generated city, run KISS-ICP on it (ATE/RPE against the true "
        "poses) and detect its loops with scan context for each intensity source "
        f"({', '.join(SOURCES)}); pose-graph correction with the verified loops.",
        verbose="one per step of the study (frames, odometry and loops per source) with its time",
    )
    p.add_argument("-o", "--out", required=True, type=out_path, help="output and cache folder")
    p.add_argument("--kind", choices=("city", "suburb"), default=d.kind, help="layout kind")
    p.add_argument("--seed", type=int, default=d.seed, help="scene seed (default 0)")
    p.add_argument("--blocks", default="4,3", metavar="NX,NY", help="blocks of the layout (4,3)")
    p.add_argument("--frames", type=int, default=d.frames, help=f"frames (default {d.frames})")
    p.add_argument("--rate", type=float, default=d.rate_hz, help="frame rate, Hz (10)")
    p.add_argument("--speed", type=float, default=d.speed, help="cruising speed, m/s (10)")
    p.add_argument("--cols", type=int, default=d.cols, help="LiDAR columns per sweep (2048)")
    p.add_argument("--width", type=int, default=d.width, help="camera width for NIDAR (320)")
    p.add_argument("--height", type=int, default=d.height, help="camera height for NIDAR (180)")
    p.add_argument("--spp", type=int, default=d.spp, help="camera samples per pixel (4)")
    p.add_argument("--weights", default=None, help="NIDAR weights folder (default: shipped)")
    p.add_argument(
        "--sources", default=",".join(SOURCES), help="intensity sources to compare (all)"
    )
    p.add_argument(
        "--sequence",
        default=None,
        help="a `render --trajectory` folder of the same drive (per-point times): adds the "
        "motion-distorted odometry runs",
    )
    p.add_argument(
        "--no-body-motion",
        action="store_true",
        help="keep the LiDAR level at a constant height (no roll, pitch or heave)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="write into OUT even when it holds files of something else (none is removed; "
        "another command's output is refused)",
    )
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    def work():
        from ..backend import set_variant
        from ..errors import NidarError
        from ..eval.drive.report import markdown_tables
        from ..eval.drive.study import StudyConfig, run_study

        try:
            blocks = tuple(int(v) for v in args.blocks.split(","))
        except ValueError:
            blocks = ()
        if len(blocks) != 2 or blocks[0] < 2 or blocks[1] < 1:
            raise NidarError(f"--blocks expects NX,NY with NX >= 2, NY >= 1 (got '{args.blocks}')")
        if args.sequence is not None:
            import os

            if not os.path.isdir(args.sequence):
                raise NidarError(f"--sequence: {args.sequence} is not a folder")
        cfg = StudyConfig(
            kind=args.kind,
            seed=args.seed,
            blocks=blocks,
            frames=args.frames,
            rate_hz=args.rate,
            speed=args.speed,
            cols=args.cols,
            width=args.width,
            height=args.height,
            spp=args.spp,
            weights=args.weights,
            sources=tuple(s.strip() for s in args.sources.split(",") if s.strip()),
            sequence=args.sequence,
            body_motion=not args.no_body_motion,
        )
        cfg.check()  # bad options are named before the variant starts
        require("drive", "drive")
        if "nidar" in cfg.sources:
            require("nidar", "drive --sources nidar")
        set_variant()
        results = run_study(args.out, cfg, progress=show_progress(args), overwrite=args.overwrite)
        if not args.quiet:
            print(markdown_tables(results))
            print(f"report: {args.out}/report.md")

    return run(
        work,
        on_interrupt="the scene and the sweeps completed so far are kept; run again to resume",
        args=args,
    )
