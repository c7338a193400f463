"""``--workers N`` and ``--ray-address ADDRESS``: the options of every command that runs many tasks.

Without them the work runs one task after the other in the command's own process (Ray is not
imported); see :mod:`nidar_mi.tasks` and docs/SCALING.md.
"""

from __future__ import annotations

import argparse

__all__ = ["add_worker_options"]


def add_worker_options(p: argparse.ArgumentParser, what: str = "scenes") -> None:
    """Add ``--workers`` and ``--ray-address`` (parsed as ``args.workers``, ``args.ray_address``).

    Args:
        p: the command's parser.
        what: what runs in parallel, for the help text.
    """
    g = p.add_argument_group("parallel work (needs Ray: pip install 'nidar_mi[ray]')")
    g.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help=f"{what} at once on a local Ray runtime started for the command "
        "(default: one after the other, without Ray)",
    )
    g.add_argument(
        "--ray-address",
        default=None,
        metavar="ADDRESS",
        help="run on an existing Ray cluster (host:port, ray://host:port or auto); "
        "--workers then caps the tasks in flight",
    )
