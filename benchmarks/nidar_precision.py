"""NIDAR's outputs under a GPU's reduced convolution precision (TF32, bf16), emulated on the CPU.

``python benchmarks/nidar_precision.py [--kitti DIR ...] [--frames N] [--json out.json]``

For real KITTI frames (default: ``../shared/data/kitti`` and ``../shared/data/kitti_more``; a
missing folder is skipped with a message), the shipped model is run with exact float32
convolutions and with the inputs and weights of every convolution rounded as a GPU's tensor cores
round them (:func:`nidar_mi.nidar.precision.emulated_convolutions`). Printed per format: the
largest change of the R map (|ΔR|, R in [0, 1]), the mean and largest change of
``intensity_nidar`` at the observed points, and the median over frames of the Spearman correlation
of ``intensity_nidar`` with the KITTI reflectance. docs/BENCHMARKS.md ("NIDAR under TF32") holds
the numbers and the decision taken from them.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from nidar_mi.datasets.kitti_objects import frame_ids, load_kitti_frame
from nidar_mi.nidar.pipeline import NidarModel
from nidar_mi.nidar.precision import emulated_convolutions

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
FORMATS = ("float32", "tf32", "bf16")


def _frames(dirs: list[Path], limit: int):
    out = []
    for d in dirs:
        if not (d / "velodyne").is_dir():
            print(f"skipped {d}: no KITTI frames there", file=sys.stderr)
            continue
        out += [(d, fid) for fid in frame_ids(d)]
    return out[:limit]


def measure(model: NidarModel, frames) -> dict[str, dict[str, float]]:
    """Per format: max |ΔR|, mean / max |Δ intensity| at the points, median Spearman."""
    rows = {f: {"dR_max": 0.0, "dI_mean": [], "dI_max": 0.0, "spearman": []} for f in FORMATS}
    for d, fid in frames:
        fr = load_kitti_frame(d, fid)
        ref = None
        for fmt in FORMATS:
            with emulated_convolutions(fmt):
                maps = model.predict_image(fr.rgb)
            res = model.point_intensity(fr.xyz, [fr.camera], [fr.rgb], maps=[maps])
            obs = res.observed
            row = rows[fmt]
            row["spearman"].append(spearmanr(res.intensity[obs], fr.intensity[obs])[0])
            if ref is None:
                ref = (maps["R"], res.intensity, obs)
                continue
            both = obs & ref[2]
            d_int = np.abs(res.intensity[both] - ref[1][both])
            row["dR_max"] = max(row["dR_max"], float(np.abs(maps["R"] - ref[0]).max()))
            row["dI_mean"].append(float(d_int.mean()))
            row["dI_max"] = max(row["dI_max"], float(d_int.max()))
    for row in rows.values():
        row["dI_mean"] = statistics.fmean(row["dI_mean"]) if row["dI_mean"] else 0.0
        row["spearman"] = statistics.median(row["spearman"])
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kitti", action="append", type=Path, help="KITTI folder (repeatable)")
    ap.add_argument("--frames", type=int, default=12, help="at most this many frames")
    ap.add_argument("--json", type=Path, help="also write the table here")
    args = ap.parse_args(argv)
    dirs = args.kitti or [SHARED / "kitti", SHARED / "kitti_more"]
    frames = _frames(dirs, args.frames)
    if not frames:
        print("no KITTI frames found; pass --kitti DIR", file=sys.stderr)
        return 2
    rows = measure(NidarModel.load(device="cpu"), frames)
    print(f"{len(frames)} frames; differences against exact float32 convolutions")
    print("| format | max abs dR | mean abs dI | max abs dI | Spearman (median) |")
    print("|---|---|---|---|---|")
    for f, r in rows.items():
        print(
            f"| {f} | {r['dR_max']:.2e} | {r['dI_mean']:.2e} | {r['dI_max']:.2e} "
            f"| {r['spearman']:.4f} |"
        )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
