"""``python -m nidar_mi.scenegen --count N --seed S -o DIR``: random urban and vegetated scenes.

Writes ``DIR/scene_<S>_<k>.xml`` for k = 0 .. N-1 (scenes already there are skipped, so a run
resumes; a file holding a scene of another run is refused unless ``--overwrite``, a file edited
by hand is kept) and ``DIR/index.json``. Every scene renders with ``python -m nidar_mi.render``.
``--kind city`` / ``--kind suburb`` draw a grid of blocks (``--blocks NX,NY``) with a drive round
it: ``DIR/scene_<S>_<k>_drive.tum`` (``--frames``, ``--rate``, ``--speed``;
:mod:`nidar_mi.scenegen.drives`).
"""

from __future__ import annotations

from ..scenegen.drives import DEFAULT_FRAMES
from ..scenegen.generate import KINDS
from ._common import parser, run, seed_arg, show_progress

__all__ = ["main", "build_parser"]


def build_parser():
    p = parser(
        "scenegen",
        "Generate random urban and vegetated scenes (library materials, sun and sky "
        "with NIR, a LiDAR + camera rig) as Mitsuba XML. Resumable: existing scenes are skipped.",
    )
    p.add_argument("--count", type=int, required=True, help="number of scenes")
    p.add_argument("--seed", type=seed_arg, default=0, help="run seed, 0 .. 2**32-1 (default 0)")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.add_argument(
        "--kind",
        choices=KINDS,
        default=None,
        help="only this kind (default: a mix, 60%% urban, 40%% vegetated); city and suburb are "
        "grids of blocks with a drive",
    )
    p.add_argument(
        "--materials",
        choices=("all", "train", "heldout"),
        default="all",
        help="all (default); train: none of the held-out materials; heldout: the held-out "
        "materials wherever a part has one (a test of unseen spectra)",
    )
    p.add_argument(
        "--lighting",
        choices=("default", "varied"),
        default="default",
        help="default: each layout's own sun and sky; varied: sun and sky redrawn per scene "
        "(overcast a quarter of the time, sun 6-80 deg; the shapes stay those of default)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace scene files of another run (another --kind or --materials) and files "
        "edited by hand",
    )
    p.add_argument(
        "--blocks", default=None, metavar="NX,NY", help="city/suburb: blocks along x and y (4,3)"
    )
    p.add_argument(
        "--frames", type=int, default=DEFAULT_FRAMES, help="city/suburb: frames of the drive"
    )
    p.add_argument("--rate", type=float, default=10.0, help="city/suburb: frame rate, Hz")
    p.add_argument("--speed", type=float, default=10.0, help="city/suburb: cruising speed, m/s")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    def work():
        from ..errors import NidarError
        from ..scenegen.generate import generate

        blocks = None
        if args.blocks is not None:
            try:
                blocks = tuple(int(v) for v in args.blocks.split(","))
            except ValueError:
                blocks = ()
            if len(blocks) != 2 or blocks[0] < 2 or blocks[1] < 1:
                raise NidarError(
                    f"--blocks expects NX,NY with NX >= 2, NY >= 1 (got '{args.blocks}')"
                )
        if args.frames < 2 or not args.rate > 0 or not args.speed > 0:
            raise NidarError("--frames must be >= 2, --rate and --speed > 0")
        drive = {"frames": args.frames, "rate_hz": args.rate, "speed": args.speed}
        index = generate(
            args.out,
            args.count,
            args.seed,
            kind=args.kind,
            progress=show_progress(args),
            blocks=blocks,
            drive=drive,
            overwrite=args.overwrite,
            materials=args.materials,
            lighting=args.lighting,
        )
        if not args.quiet:
            stats = index["run"]
            print(
                f"{stats['written']} scenes written, {stats['skipped']} already there, "
                f"{len(index['scenes'])} in {args.out}/index.json"
            )

    return run(
        work,
        on_interrupt="the scenes written so far are complete",
        flags={"out_dir": "-o"},
        args=args,
    )
