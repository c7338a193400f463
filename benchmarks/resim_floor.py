"""What the real sensor scores against itself: each held-out scan of the re-simulation runs
scored against the real scan of the frame nearest to it, as the re-simulation is scored
(docs/RESIMULATION.md, "Targets").

``python benchmarks/resim_floor.py --work DIR [--runs NAME,...]``

``DIR`` is a ``benchmarks/resim_drives.py --work`` folder (each run's drive in
``DIR/drives/<run>``, its re-simulation in ``DIR/out/<run>``: the poses and the held-out frames
are read from there). For each held-out frame, the real scan of the other frame whose pose is
nearest (held-out frames included: a reference, not a method, as it reads scans the
re-simulation may not) is moved into the held-out frame's LiDAR frame and scored with the
re-simulation's own metrics (:mod:`nidar_mi.resim.scan_scores`): Chamfer, F-score at 0.1 m,
ray-drop agreement, intensity Spearman and RMSE at the matched returns. Prints a markdown table,
the re-simulation's scores beside. KITTI is research-only data: only numbers are printed.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def neighbour_scores(run_dir: Path, out_dir: Path) -> dict:
    """Held-out id -> the scores of its nearest real neighbour (and which, how far)."""
    from nidar_mi.io.kitti import read_kitti_poses
    from nidar_mi.resim.drive_folder import open_drive
    from nidar_mi.resim.frames import load_frames
    from nidar_mi.resim.range_image import scan_grid
    from nidar_mi.resim.scan_scores import (
        drop_metrics,
        geometry_metrics,
        intensity_metrics,
        matches,
    )

    report = json.loads((out_dir / "report.json").read_text())
    drive = open_drive(str(run_dir), holdout=report["holdout"])
    frames = load_frames(drive)
    poses = read_kitti_poses(str(out_dir / "poses.txt"))
    out = {}
    for fid in drive.holdout:
        k = drive.index(fid)
        dist = np.linalg.norm(poses[:, :3, 3] - poses[k, :3, 3], axis=1)
        dist[k] = np.inf
        n = int(np.argmin(dist))
        M = np.linalg.inv(poses[k]) @ poses[n]
        nb = frames.xyz[n] @ M[:3, :3].T + M[:3, 3]
        real, y = frames.xyz[k], frames.intensity[k]
        ok, idx = matches(real, nb)
        grid = scan_grid(nb, frames.columns, frames.layout.elevation_deg)
        scores = {"neighbour": drive.ids[n], "distance_m": float(dist[n])}
        scores |= geometry_metrics(real, nb)
        scores |= drop_metrics(frames.grid[k].occupancy(), grid.occupancy(), frames.coverage)
        scores |= intensity_metrics(frames.intensity[n][idx[ok]], y[ok])
        out[fid] = scores
    return out


def main(argv=None) -> int:
    from work_folder import work_parser, work_runs

    ap = work_parser(__doc__.split("\n\n")[0])
    args = ap.parse_args(argv)
    runs = work_runs(args)
    print(
        "| run | nearest real scan, m | Chamfer (m) | F@0.1 m | drop agr. | Spearman / RMSE "
        "| re-simulation: Chamfer / F / drop agr. / Spearman / RMSE |"
    )
    print("| --- | ---: | ---: | ---: | ---: | ---: | --- |")
    for run in runs:
        out_dir = args.work / "out" / run
        res = neighbour_scores(args.work / "drives" / run, out_dir)
        mean = {q: float(np.mean([r[q] for r in res.values()])) for q in next(iter(res.values()))
                if q != "neighbour"}  # fmt: skip
        m = json.loads((out_dir / "report.json").read_text())["heldout"]["mean"]
        q = m["intensity"]["resim"]
        print(
            f"| `{run}` | {mean['distance_m']:.2f} | {mean['chamfer_m']:.3f} | "
            f"{mean['fscore']:.3f} | {mean['drop_agreement']:.3f} | {mean['spearman']:.3f} / "
            f"{mean['rmse']:.3f} | {m['chamfer_m']:.3f} / {m['fscore']:.3f} / "
            f"{m['drop_agreement']:.3f} / {q['spearman']:.3f} / {q['rmse']:.3f} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main())
