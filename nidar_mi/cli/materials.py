"""``python -m nidar_mi.materials``: list the material library and plot spectra.

Usage::

    python -m nidar_mi.materials --list
    python -m nidar_mi.materials --plot asphalt_old grass lane_paint_white -o spectra.png

``--list`` (the default) prints name, kind, reflectance at 550 / 905 / 1550 nm, sRGB colour and
source of every material. ``--plot`` writes a PNG of the chosen materials' reflectance from 360 to
1700 nm with the 905 and 1550 nm LiDAR wavelengths marked; an existing file (``-o``, default
``spectra.png``) is replaced only with ``--overwrite``.
"""

from __future__ import annotations

import os
import sys

from ..errors import NidarError
from ._common import out_path, parser, run

__all__ = ["main"]


def _parser():
    p = parser(
        "materials",
        "List the spectral material library and plot material spectra.",
        verbose="the source of each plotted spectrum",
        progress=False,
    )
    p.add_argument("--list", action="store_true", help="print the material table (default)")
    p.add_argument("--plot", nargs="+", metavar="NAME", help="materials to plot")
    p.add_argument(
        "-o",
        "--output",
        default=None,
        type=out_path,
        help="PNG path for --plot (default: spectra.png)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing --plot file (-o)")
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the process exit status (2 on a user error)."""
    args = _parser().parse_args(argv)

    def work():
        from ..io.atomic import check_output_file
        from ..materials.listing import format_table, list_materials, plot_spectra

        if args.output is not None and not args.plot:
            raise NidarError("-o/--output names the --plot file: give --plot NAME ... too")
        output = args.output or "spectra.png"
        if args.plot and not output.lower().endswith(".png"):
            raise NidarError(f"-o/--output: the plot is a PNG; name a .png file (got {output})")
        if args.plot and not os.path.isdir(os.path.dirname(os.path.abspath(output))):
            raise NidarError(f"output folder does not exist: {os.path.dirname(output)}")
        if args.overwrite and not args.plot:
            raise NidarError("--overwrite applies to the --plot file: give --plot NAME ... too")
        target = check_output_file(output, overwrite=args.overwrite) if args.plot else None
        if args.list or not args.plot:
            sys.stdout.write(format_table(list_materials()))
        if args.plot:
            plot_spectra(args.plot, str(target))
            sys.stdout.write(f"wrote {output}\n")

    return run(work, args=args)
