"""``python -m nidar_mi.scenegen --count N --seed S -o DIR``: random urban and vegetated scenes.

Writes ``DIR/scene_<S>_<k>.xml`` for k = 0 .. N-1 (scenes already there are skipped, so a run
resumes; a file holding a scene of another run is refused unless ``--overwrite``, a file edited
by hand is kept) and ``DIR/index.json``; a non-empty ``DIR`` that holds files scenegen did not
write is refused unless ``--overwrite`` (they are kept), another command's output always
(:mod:`nidar_mi.io.ownership`). Every scene renders with ``python -m nidar_mi.render``.
``--kind city`` / ``--kind suburb`` draw a grid of blocks (``--blocks NX,NY``) with a drive round
it: ``DIR/scene_<S>_<k>_drive.tum`` (``--frames``, ``--rate``, ``--speed``;
:mod:`nidar_mi.scenegen.drives`); these options with another kind are refused.
"""

from __future__ import annotations

from ..errors import NidarError
from ..scenegen.drives import DEFAULT_FRAMES
from ..scenegen.generate import KINDS
from ..scenegen.route import check_drive
from ..scenegen.streets import CITY_KINDS
from ._common import out_path, parser, run, seed_arg, show_progress

__all__ = ["main", "build_parser"]


def build_parser():
    p = parser(
        "scenegen",
        "Generate random urban and vegetated scenes (library materials, sun and sky "
        "with NIR, a LiDAR + camera rig) as Mitsuba XML. Resumable: existing scenes are skipped.",
        verbose="one per scene (written, skipped or kept)",
    )
    p.add_argument("--count", type=int, required=True, help="number of scenes")
    p.add_argument("--seed", type=seed_arg, default=0, help="run seed, 0 .. 2**32-1 (default 0)")
    p.add_argument("-o", "--out", required=True, type=out_path, help="output folder")
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
        "--spectra",
        choices=("library", "earthlib", "earthlib-family"),
        default="library",
        help="library: each material's own spectrum (default); earthlib: 3/4 of the diffuse, "
        "road and paint materials of each scene take a random measured earthlib spectrum from a "
        "class no held-out material comes from (training scenes of many spectra); "
        "earthlib-family: the same within each material's family (a grass another canopy, a "
        "road another pavement; paints keep theirs)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace scene files of another run (another --kind or --materials) and files "
        "edited by hand; write into a folder that holds other files (none of them is removed; "
        "another command's output is refused)",
    )
    p.add_argument(
        "--blocks", default=None, metavar="NX,NY", help="city/suburb: blocks along x and y (4,3)"
    )
    p.add_argument(
        "--frames",
        type=int,
        default=None,
        help=f"city/suburb: frames of the drive (default {DEFAULT_FRAMES})",
    )
    p.add_argument("--rate", type=float, default=None, help="city/suburb: frame rate, Hz (10)")
    p.add_argument(
        "--speed", type=float, default=None, help="city/suburb: cruising speed, m/s (10)"
    )
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    def work():
        from ..scenegen.generate import generate

        blocks = None
        city = [f for f in ("blocks", "frames", "rate", "speed") if getattr(args, f) is not None]
        if city and args.kind not in CITY_KINDS:
            raise NidarError(
                f"{', '.join('--' + f for f in city)}: options of --kind city or suburb "
                f"(got {'--kind ' + args.kind if args.kind else 'no --kind'})"
            )
        if args.blocks is not None:
            try:
                blocks = tuple(int(v) for v in args.blocks.split(","))
            except ValueError:
                blocks = ()
            if len(blocks) != 2 or blocks[0] < 2 or blocks[1] < 1:
                raise NidarError(
                    f"--blocks expects NX,NY with NX >= 2, NY >= 1 (got '{args.blocks}')"
                )
        drive = {
            "frames": DEFAULT_FRAMES if args.frames is None else args.frames,
            "rate_hz": 10.0 if args.rate is None else args.rate,
            "speed": 10.0 if args.speed is None else args.speed,
        }
        check_drive(drive["frames"], drive["rate_hz"], drive["speed"])
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
            spectra=args.spectra,
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
