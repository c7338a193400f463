"""The ``--work`` folder of ``benchmarks/resim_drives.py`` as the scripts that read it take it:
each run's drive in ``DIR/drives/<run>``, its re-simulation in ``DIR/out/<run>``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def work_parser(description: str) -> argparse.ArgumentParser:
    """A parser with ``--work DIR`` and ``--runs NAME,...`` (default: every run there)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--work", required=True, type=Path, help="a resim_drives.py --work folder")
    ap.add_argument("--runs", default=None, help="runs to read (default: every one there)")
    return ap


def work_runs(args) -> list[str]:
    """The runs that ``--runs`` names, or every finished run (with its ``report.json``) in
    ``--work``'s ``out/``, sorted; one ``error:`` line and exit 2 when the folder is not such a
    folder or a named run is not in it."""
    out = Path(args.work) / "out"
    if not out.is_dir():
        _fail(f"{args.work} is not a resim_drives.py --work folder (no out/ in it)")
    if not args.runs:  # every finished run there
        return sorted(p.name for p in out.iterdir() if (p / "report.json").is_file())
    runs = args.runs.split(",")
    for run in runs:
        if not (out / run / "report.json").is_file() or not (out.parent / "drives" / run).is_dir():
            _fail(f"no run {run!r} in {args.work} (out/{run}/report.json and drives/{run}/)")
    return runs


def _fail(message: str):
    print(f"error: {message}", file=sys.stderr)
    raise SystemExit(2)
