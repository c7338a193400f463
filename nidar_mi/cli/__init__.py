"""The command line: one thin module per command, all sharing :mod:`nidar_mi.cli._common`.

Every command runs as ``python -m nidar_mi.<command>``, as ``nidar-mi <command>`` and as its
console script (``nidar-<command>`` with ``_`` written ``-``: ``nidar-pseudo-nir``; pyproject.toml
lists them); ``python -m nidar_mi`` (or ``nidar-mi``) lists the commands.
"""

from __future__ import annotations

import importlib
import sys

__all__ = ["COMMANDS", "main"]

#: Command name -> one-line summary, in the order of the data flow.
COMMANDS = {
    "scenegen": "generate random urban, vegetated, city and suburb scenes (Mitsuba XML), drives",
    "render": "scan every LiDAR and render every camera of a scene",
    "materials": "list the spectral material library, plot spectra",
    "dataset": "render scenes and build NIDAR training frames",
    "train": "train the NIDAR networks",
    "pseudo_nir": "pseudo-NIR images from colour photos (NIDAR's spectral translation)",
    "calibrate": "fit a sensor profile (distance and ring response) on a sensor's own scans",
    "assign": "NIDAR intensity for a point cloud from camera images (or a KITTI frame)",
    "weather": "add fog, rain or snow to point clouds recorded in clear air",
    "evaluate": "score NIDAR and the baselines (tables, figures)",
    "reflectance_cue": "how well image values rank the true reflectance; what the image adds",
    "drive": "odometry and loop closure per intensity source on a simulated drive",
    "reconstruct": "re-simulate a recorded drive: scene, reflectance and sensor from its scans",
}


def _usage() -> str:
    from .. import __version__

    width = max(map(len, COMMANDS))
    lines = [
        f"nidar_mi {__version__}: LiDAR scans with NIR intensity, and NIDAR.",
        "",
        "usage: python -m nidar_mi <command> [options]   (or: python -m nidar_mi.<command>)",
        "",
        "commands:",
    ]
    lines += [f"  {name:<{width}}  {text}" for name, text in COMMANDS.items()]
    lines += ["", "python -m nidar_mi <command> --help describes a command."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``python -m nidar_mi [command [options]]``: list the commands, or run one."""
    from .. import __version__

    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return 0
    if argv[0] == "--version":
        print(f"nidar_mi {__version__}")
        return 0
    if argv[0] not in COMMANDS:
        print(
            f"error: unknown command '{argv[0]}' (commands: {', '.join(COMMANDS)})", file=sys.stderr
        )
        return 2
    return importlib.import_module(f"{__name__}.{argv[0]}").main(argv[1:])
