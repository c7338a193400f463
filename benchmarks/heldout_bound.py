"""Upper bounds on rendered scenes: how well the *true* reflectance ranks the physical intensity.

``python benchmarks/heldout_bound.py TRAIN_DATA TEST_DATA``

``TRAIN_DATA`` and ``TEST_DATA`` are rendered datasets of ``python -m nidar_mi.dataset --scenes``
(e.g. ``data_sim`` and the held-out-material scenes rendered the same way). At every
camera-visible return with a surface (``R_true >= 1e-3``) of every ``TEST_DATA`` frame it scores,
against the frame's range-compensated intensity (Spearman per frame and over all returns):

* the true reflectance at the LiDAR wavelength ``R_true`` (clipped to [0, 1]);
* ``R_true`` through a ``gbm`` profile (value, range, elevation) fitted on ``TRAIN_DATA``'s
  ``train`` frames;
* ``cos θ`` alone: the incidence of the LiDAR ray on the surface whose normal comes from the
  depth map (finite differences of the back-projected pixels);
* ``R_true · cos θ``;
* ``R_true`` through an incidence-aware ``gbm`` profile (value, range, elevation, ``cos θ``)
  fitted on ``TRAIN_DATA``'s ``train`` frames;
* ``R_true`` through a value-and-incidence ``gbm`` profile (value, ``cos θ``; the form of the
  shipped ``sim-905``) fitted on the same frames.

No network is involved: these bound any method that estimates reflectance from the camera image
and maps it through a profile of range and elevation (and, for the last row, the incidence).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def returns(path: Path) -> dict[str, np.ndarray]:
    """Per-return values of one frame: R_true, range, elevation (deg), cos θ, intensity.

    Pixel ``(u, v)`` has its centre at ``(u, v)`` in the OpenCV convention of ``K``
    (:mod:`nidar_mi.camera`).
    """
    from nidar_mi.training_frames import load_frame

    z = load_frame(path, ("R_true", "mask", "range", "depth", "K", "T_cam_lidar", "intensity"))
    depth, k = z["depth"].astype(np.float64), z["K"]
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w]
    p = np.stack([(u - k[0, 2]) / k[0, 0] * depth, (v - k[1, 2]) / k[1, 1] * depth, depth], -1)
    normal = np.cross(np.gradient(p, axis=1), np.gradient(p, axis=0))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True) + 1e-12
    ray = p - z["T_cam_lidar"][:3, 3]  # from the LiDAR origin, camera frame
    ray /= np.linalg.norm(ray, axis=-1, keepdims=True) + 1e-12
    cos = np.clip(np.abs(np.einsum("hwc,hwc->hw", normal, ray)), 0.0, 1.0)
    sel = z["mask"] & (z["R_true"] >= 1e-3) & np.isfinite(cos)
    lidar_from_cam = np.linalg.inv(z["T_cam_lidar"])
    pts = np.einsum("ij,nj->ni", lidar_from_cam[:3, :3], p[sel]) + lidar_from_cam[:3, 3]
    elevation = np.degrees(np.arctan2(pts[:, 2], np.hypot(pts[:, 0], pts[:, 1])))
    return {
        "r_true": np.clip(z["R_true"][sel], 0.0, 1.0).astype(np.float64),
        "range": z["range"][sel].astype(np.float64),
        "elevation": elevation,
        "cos": cos[sel],
        "intensity": z["intensity"][sel].astype(np.float64),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("train_data", type=Path)
    p.add_argument("test_data", type=Path)
    args = p.parse_args(argv)

    from scipy.stats import spearmanr

    from nidar_mi.errors import NidarError
    from nidar_mi.profiles import fit
    from nidar_mi.training_frames import SPLITS, list_frames, load_meta

    try:
        train = [returns(f) for f in list_frames(args.train_data, "train")]
        tests = [(f.stem, returns(f)) for s in SPLITS for f in list_frames(args.test_data, s)]
        if not train or not tests:
            raise NidarError("no rendered frames in TRAIN_DATA/train or in TEST_DATA")
    except NidarError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    cat = {k: np.concatenate([t[k] for t in train]) for k in train[0]}
    scale = float(load_meta(args.train_data).get("intensity_scale", 1.0))
    reference = np.clip(cat["intensity"] / scale, 0, 1)  # the metric scale of the evaluation
    gbm = fit("gbm", cat["r_true"], cat["range"], reference, elevation_deg=cat["elevation"])
    gbm_inc = fit(
        "gbm",
        cat["r_true"],
        cat["range"],
        reference,
        elevation_deg=cat["elevation"],
        cos_incidence=cat["cos"],
    )
    gbm_vc = fit(
        "gbm", cat["r_true"], cat["range"], reference, cos_incidence=cat["cos"], use_geometry=False
    )

    def values(t):
        return {
            "R_true": t["r_true"],
            "R_true + gbm": gbm(t["r_true"], t["range"], elevation_deg=t["elevation"]),
            "cos": t["cos"],
            "R_true * cos": t["r_true"] * t["cos"],
            "R_true + gbm with incidence": gbm_inc(
                t["r_true"], t["range"], elevation_deg=t["elevation"], cos_incidence=t["cos"]
            ),
            "R_true + gbm of value and incidence": gbm_vc(
                t["r_true"], t["range"], cos_incidence=t["cos"]
            ),
        }

    per_frame: dict[str, list[float]] = {}
    for name, t in tests:
        row = {k: float(spearmanr(v, t["intensity"]).statistic) for k, v in values(t).items()}
        print(name, len(t["intensity"]), {k: round(v, 3) for k, v in row.items()})
        for k, v in row.items():
            per_frame.setdefault(k, []).append(v)
    pooled = {k: np.concatenate([t[k] for _, t in tests]) for k in tests[0][1]}
    print(f"{len(pooled['intensity'])} returns")
    for k, v in values(pooled).items():
        all_rho = spearmanr(v, pooled["intensity"]).statistic
        print(f"{k}: mean over frames {np.mean(per_frame[k]):.3f}, all returns {all_rho:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
