"""How the score of a calibrated sensor profile grows with the frames it is fitted on.

``python benchmarks/calibrate_frames.py [--data DIR] [--ks 1,3,10,all] [--seeds 3] [--weights DIR]``

Leave-one-drive-out over the real KITTI frames under ``--data`` (default: the data root,
``../shared/data``): the groups are ``kitti_raw_0926`` (one drive), each drive of
``kitti_more`` (``rDDDD_*``: drive DDDD), its object frames (``obj*``), its odometry frames
(``o04_*``), and ``kitti`` (scattered frames). For every held-out group and every K, a profile
of the ``kitti-hdl64e`` recipe (``gbm`` of the R branch with the incidence,
:func:`nidar_mi.datasets.profile_fitting.fit_values_profile`) is fitted on K frames drawn at
random (seeded) from the other groups, and scored on every frame of the held-out group, which no
fit ever saw: Spearman's ρ against the stored reflectance and the range-binned Spearman
(:func:`nidar_mi.eval.scan_metrics.binned_spearman`), the mean over the group's frames. K = 0
rows are the generic profiles (closed forms, no fit). A row gives the mean over the groups (each
group counts once) and the spread over the seeds (standard deviation of that mean).

Prints a Markdown table; nothing is written. KITTI is non-commercial data: only numbers are
reported.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from nidar_mi.datasets.paths import data_root
from nidar_mi.datasets.profile_fitting import fit_values_profile, scan_values
from nidar_mi.datasets.scans import load_scans
from nidar_mi.datasets.sensor_profiles import (
    GENERIC_COMPENSATED_PROFILE,
    GENERIC_RAW_PROFILE,
    generic_profile,
)
from nidar_mi.eval.metrics import spearman
from nidar_mi.eval.scan_metrics import binned_spearman
from nidar_mi.nidar.pipeline import NidarModel

SOURCES = ("kitti_raw_0926", "kitti_more", "kitti")


def group_of(name: str) -> str:
    """The drive or group of a frame named ``<source>__<id>``."""
    source, fid = name.split("__", 1)
    if source != "kitti_more":
        return source
    if fid.startswith("r"):
        return fid[:5]
    return "obj" if fid.startswith("obj") else fid.split("_", 1)[0]


def score(profile, scans, values) -> tuple[float, float]:
    """Mean Spearman and range-binned Spearman of ``profile`` over ``scans``."""
    rho, rho_bin = [], []
    for s in scans:
        v = values[s.name]
        ok = np.isfinite(v)
        cos = s.cos_incidence[ok] if profile.uses_incidence else None
        pred = profile(
            v[ok],
            s.range_m[ok],
            ring=s.ring[ok] if np.all(s.ring >= 0) else None,
            elevation_deg=s.elevation_deg[ok],
            cos_incidence=cos,
        )
        rho.append(spearman(pred, s.intensity[ok]))
        rho_bin.append(binned_spearman(pred, s.intensity[ok], s.range_m[ok]))
    return float(np.nanmean(rho)), float(np.nanmean(rho_bin))


def fitted(train, values, seed: int):
    return fit_values_profile(
        train,
        lambda s: values[s.name],
        name=f"k{len(train)}-s{seed}",
        sensor="KITTI HDL-64E",
        input="nidar:R",
        incidence=True,
        seed=seed,
    )


def rows(groups, values, ks, seeds):
    """Yield ``(label, K, [(spearman, binned) per seed])`` (means over the held-out groups)."""
    names = sorted(groups)
    for gen in (GENERIC_COMPENSATED_PROFILE, GENERIC_RAW_PROFILE):
        prof = generic_profile(gen)
        per = [score(prof, groups[g], values) for g in names]
        yield gen, 0, [tuple(np.mean(per, axis=0))]
    for k in ks:
        runs = []
        for seed in range(1 if k is None else seeds):
            per = []
            for g in names:
                pool = [s for h in names if h != g for s in groups[h]]
                rng = np.random.default_rng(seed)
                pick = pool if k is None else [pool[i] for i in rng.permutation(len(pool))[:k]]
                per.append(score(fitted(pick, values, seed), groups[g], values))
            runs.append(tuple(np.mean(per, axis=0)))
        yield "gbm + incidence (kitti-hdl64e recipe)", ("all" if k is None else k), runs


def _cell(runs, column: int) -> str:
    """``mean ± sd`` over the seeds (the mean alone for one run)."""
    a = np.asarray(runs)[:, column]
    return f"{a.mean():.3f}" + (f" ± {a.std():.3f}" if a.size > 1 else "")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--data", default=None, help="folder holding the KITTI folders")
    ap.add_argument("--ks", default="1,3,10,all", help="frame counts (all: the whole pool)")
    ap.add_argument("--seeds", type=int, default=3, help="random draws of the K frames")
    ap.add_argument("--weights", default=None, help="NIDAR weights (default: the shipped)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    root = Path(args.data) if args.data else data_root()
    dirs = [root / s for s in SOURCES if (root / s / "velodyne").is_dir()]
    if not dirs:
        print(f"no KITTI folders under {root}", file=sys.stderr)
        return 2
    scans = load_scans(dirs, progress=False)
    model = NidarModel.load(args.weights, device="cpu")
    values = {s.name: scan_values(model, s, "R") for s in scans}
    groups: dict[str, list] = {}
    for s in scans:
        groups.setdefault(group_of(s.name), []).append(s)
    ks = [None if k == "all" else int(k) for k in args.ks.split(",")]
    sizes = ", ".join(f"{g} {len(v)}" for g, v in sorted(groups.items()))
    print(f"{len(scans)} frames in {len(groups)} held-out groups ({sizes})\n")
    print("| profile | K frames | Spearman | range-binned Spearman | seeds |")
    print("| --- | --- | --- | --- | --- |")
    for label, k, runs in rows(groups, values, ks, args.seeds):
        print(f"| {label} | {k} | {_cell(runs, 0)} | {_cell(runs, 1)} | {len(runs)} |", flush=True)
    print(f"\nwall time {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
