"""Re-simulation of the real KITTI drives: interpolation and extrapolation tables
(docs/RESIMULATION.md).

``python benchmarks/resim_drives.py [--data ../shared/data] [--work DIR] [--json out.json]
[--runs NAME,...]``

Each run lays a drive folder out of the shared data (symbolic links: ``velodyne/``,
``image_2/``, ``calib/``), runs ``python -m nidar_mi.reconstruct`` on it with its held-out frames
(wall time measured around the command) and reads ``report.json``. Runs:

* ``0926_interp``: ``kitti_raw_0926`` frames 000000-000077, held out 000035-000039;
* ``0926_extrap``: its frames 000000-000024, held out the last five (000020-000024);
* ``<drive>_interp`` / ``<drive>_extrap`` for each five-frame ``kitti_more`` drive
  (``r0064_0500``, ``r0048_0000``, ``r0009_0328``, ``r0005_0140``): held out the middle frame /
  the last frame.

Prints one markdown table per regime (means over a run's held-out frames): geometry (Chamfer,
F-score, ray-drop agreement) and intensity (Spearman, RMSE) of the re-simulation and of every
baseline. KITTI is research-only data: nothing derived from it is written into the repository
(the tables are numbers, copied into the docs by hand).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MORE = ("r0064_0500", "r0048_0000", "r0009_0328", "r0005_0140")


def _runs() -> dict:
    """name -> (source folder, frame ids, held-out ids)."""
    ids = [f"{k:06d}" for k in range(78)]
    runs = {
        "0926_interp": ("kitti_raw_0926", ids, ids[35:40]),
        "0926_extrap": ("kitti_raw_0926", ids[:25], ids[20:25]),
    }
    for first in MORE:
        drive, start = first.split("_")
        frames = [f"{drive}_{int(start) + k:04d}" for k in range(5)]
        runs[f"{drive}_interp"] = ("kitti_more", frames, frames[2:3])
        runs[f"{drive}_extrap"] = ("kitti_more", frames, frames[4:])
    return runs


def _lay_out(data: Path, source: str, frames: list[str], folder: Path) -> None:
    for sub, ext in (("velodyne", ".bin"), ("image_2", ".png"), ("calib", ".txt")):
        (folder / sub).mkdir(parents=True, exist_ok=True)
        for f in frames:
            src = data / source / sub / f"{f}{ext}"
            dst = folder / sub / f"{f}{ext}"
            if src.exists() and not dst.exists():
                dst.symlink_to(src)


def run_one(name: str, spec, data: Path, work: Path, extra: list[str]) -> dict:
    """Lay the drive out, run the command, return its report and wall time."""
    source, frames, held = spec
    drive = work / "drives" / name
    _lay_out(data, source, frames, drive)
    out = work / "out" / name
    cmd = [sys.executable, "-m", "nidar_mi.reconstruct", str(drive), "-o", str(out)]
    cmd += ["--holdout", ",".join(held), "--overwrite", "-q", *extra]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=REPO)
    wall = time.perf_counter() - t0
    report = json.loads((out / "report.json").read_text())
    return {"wall_s": wall, "command": " ".join(cmd[1:]), "report": report}


def _table(results: dict, regime: str) -> str:
    rows = {k: v for k, v in results.items() if k.endswith(regime)}
    if not rows:
        return ""
    methods = list(next(iter(rows.values()))["report"]["heldout"]["mean"]["intensity"])
    head = (
        "| drive | frames | wall (s) | Chamfer (m) | CD² (m²) | F@0.1 m | F@0.05 m² | drop agr. |"
    )
    lines = [head + "".join(f" {m} ρₛ / RMSE |" for m in methods)]
    lines.append("|" + " --- |" * (8 + len(methods)))
    for name, r in rows.items():
        rep = r["report"]
        m = rep["heldout"]["mean"]
        cells = [
            name.rsplit("_", 1)[0],
            str(len(rep["frames"])),
            f"{r['wall_s']:.0f}",
            f"{m['chamfer_m']:.3f}",
            f"{m['chamfer_sq']:.3f}",
            f"{m['fscore']:.3f}",
            f"{m['fscore_sq']:.3f}",
            f"{m['drop_agreement']:.3f}",
        ]
        for meth in methods:
            q = m["intensity"].get(meth)
            cells.append("-" if q is None else f"{q['spearman']:.3f} / {q['rmse']:.3f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=str(REPO.parent.parent / "shared" / "data"))
    p.add_argument("--work", default="/tmp/nidar_resim_drives")
    p.add_argument("--json", default=None)
    p.add_argument("--runs", default="", help="comma-separated run names (default: all)")
    p.add_argument("--extra", default="", help="extra flags for the command")
    args = p.parse_args(argv)
    data = Path(args.data)
    if not (data / "kitti_raw_0926").is_dir():
        print(f"KITTI drives not found under {data}: nothing to run", file=sys.stderr)
        return 0
    runs = _runs()
    names = [n for n in args.runs.split(",") if n] or list(runs)
    results = {}
    for name in names:
        results[name] = run_one(name, runs[name], data, Path(args.work), args.extra.split())
        print(f"{name}: {results[name]['wall_s']:.0f} s", file=sys.stderr)
        if args.json:
            Path(args.json).write_text(json.dumps(results, indent=1))
    for regime in ("interp", "extrap"):
        print(f"\n### {regime}\n\n{_table(results, regime)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
