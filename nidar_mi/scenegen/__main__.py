"""``python -m nidar_mi.scenegen --count N --seed S -o DIR``: random urban and vegetated scenes.

Writes ``DIR/scene_<S>_<k>.xml`` for k = 0 .. N-1 (scenes already there are skipped, so a run
resumes) and ``DIR/index.json``. Every scene renders with ``python -m nidar_mi.render``.
"""

from __future__ import annotations

import argparse
import sys

from ..errors import NidarError
from .layout import KINDS

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m nidar_mi.scenegen",
        description="Generate random urban and vegetated scenes (library materials, sun and sky "
        "with NIR, a LiDAR + camera rig) as Mitsuba XML. Resumable: existing scenes are skipped.",
    )
    p.add_argument("--count", type=int, required=True, help="number of scenes")
    p.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.add_argument(
        "--kind", choices=KINDS, default=None, help="only this kind (default: a mix, 60%% urban)"
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from .generate import generate

    try:
        index = generate(args.out, args.count, args.seed, kind=args.kind, progress=not args.quiet)
    except NidarError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted; scenes written so far are complete", file=sys.stderr)
        return 130
    if not args.quiet:
        run = index["run"]
        print(
            f"{run['written']} scenes written, {run['skipped']} already there, "
            f"{len(index['scenes'])} in {args.out}/index.json"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
