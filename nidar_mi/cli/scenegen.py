"""``python -m nidar_mi.scenegen --count N --seed S -o DIR``: random urban and vegetated scenes.

Writes ``DIR/scene_<S>_<k>.xml`` for k = 0 .. N-1 (scenes already there are skipped, so a run
resumes; a file holding a scene of another run is refused unless ``--overwrite``, a file edited
by hand is kept) and ``DIR/index.json``. Every scene renders with ``python -m nidar_mi.render``.
"""

from __future__ import annotations

from ..scenegen.layout import KINDS
from ._common import parser, run, seed_arg

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
        "--kind", choices=KINDS, default=None, help="only this kind (default: a mix, 60%% urban)"
    )
    p.add_argument(
        "--materials",
        choices=("all", "train", "heldout"),
        default="all",
        help="all (default); train: none of the held-out materials; heldout: the held-out "
        "materials wherever a part has one (a test of unseen spectra)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace scene files of another run (another --kind or --materials) and files "
        "edited by hand",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    def work():
        from ..scenegen.generate import generate

        index = generate(
            args.out,
            args.count,
            args.seed,
            kind=args.kind,
            progress=not args.quiet,
            overwrite=args.overwrite,
            materials=args.materials,
        )
        if not args.quiet:
            stats = index["run"]
            print(
                f"{stats['written']} scenes written, {stats['skipped']} already there, "
                f"{len(index['scenes'])} in {args.out}/index.json"
            )

    return run(work, on_interrupt="the scenes written so far are complete")
