"""Real-data evaluation on KITTI frames: zero-shot NIDAR and the baselines vs the real intensity.

For each frame (``velodyne/ID.bin``, ``image_2/ID.png``, ``calib/ID.txt``; loaded with
:func:`nidar_mi.datasets.kitti.load_frame`) the evaluation points are the Velodyne returns that
camera 2 sees: :meth:`NidarModel.point_intensity` on the whole cloud (in front of the camera,
inside the image, not hidden in the cloud's own z-buffer; KITTI has no rendered depth) marks
them ``observed``. The reference is the Velodyne reflectance channel as stored in the ``.bin``
(already in [0, 1]; no further scaling).

Methods at those points (all on [0, 1]):

* ``luminance`` (b), ``carla`` (d): as on the synthetic scenes.
* ``nidar_no_irnet`` (e), ``nidar_ihat`` (f), ``nidar_full`` (g): NIDAR zero-shot with the
  **source-domain** calibration (fitted on the synthetic training split).
* ``*_loo`` rows: the same branch value, but the quantile map is refitted on the **other**
  KITTI frames (leave-one-out: source = the branch value (distance-encoded for R, as in the
  source calibration), reference = those frames' real intensities). The luminance and CARLA
  baselines get the same leave-one-out remap, so they see the same real data.

Not available on real data: (a) RGB-asset physics (there is no scene to scan) and (c) constant
per class (KITTI's object frames carry no per-point semantic classes).

Metrics: :func:`~nidar_mi.eval.metrics.point_metrics` and
:func:`~nidar_mi.eval.metrics.map_metrics` on the sparse camera projection (each point at its
nearest pixel, nearest point wins).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import NidarError
from .baselines import carla, luminance_rho
from .metrics import map_metrics, point_metrics

__all__ = [
    "KITTI_METHODS",
    "KITTI_UNAVAILABLE",
    "kitti_predictions",
    "loo_remap",
    "evaluate_kitti",
]

KITTI_METHODS = (
    "luminance",
    "carla",
    "nidar_no_irnet",
    "nidar_ihat",
    "nidar_full",
    "luminance_loo",
    "carla_loo",
    "nidar_ihat_loo",
    "nidar_full_loo",
)
"""Row keys of the KITTI table."""

KITTI_UNAVAILABLE = {
    "rgb_twin": "(a) needs the scene's geometry and materials; a real frame has neither",
    "class_const": "(c) needs per-point semantic classes; KITTI object frames have none",
}


def kitti_predictions(
    xyz: np.ndarray, intensity: np.ndarray, rgb: np.ndarray, cam, model, pseudo_calibration=None
) -> dict[str, Any]:
    """Zero-shot predictions of one frame at its camera-visible points.

    Args:
        xyz: (N, 3) Velodyne points, m.
        intensity: (N,) Velodyne reflectance in [0, 1].
        rgb: (H, W, 3) uint8 camera-2 image.
        cam: camera-2 :class:`~nidar_mi.geometry.CameraModel`.
        model: :class:`~nidar_mi.nidar.pipeline.NidarModel` with its source calibration.
        pseudo_calibration: baseline (e)'s calibration (None skips it).

    Returns:
        ``{"xyz", "uv", "range", "gt", "pred": {method: (M,)}, "raw": {branch: (M,)}}`` for the
        M visible points; ``raw`` holds the uncalibrated branch values (``R``, ``I_hat``,
        ``luminance``, ``carla``) that the leave-one-out remap starts from.
    """
    from ..geometry import bilinear_sample, project

    xyz = np.asarray(xyz, dtype=np.float64)
    maps = model.predict_image(rgb)
    res = model.point_intensity(xyz, [cam], [rgb], maps=[maps])
    idx = np.flatnonzero(res.observed)
    p = xyz[idx]
    uv = project(p, cam)[0]
    dist = np.linalg.norm(p, axis=1)
    raw = {
        "R": res.raw_R[idx].astype(np.float64),
        "I_hat": np.clip(bilinear_sample(maps["I_hat"], uv), 0.0, 1.0),
        "luminance": np.clip(luminance_rho(rgb, uv), 0.0, 1.0),
        "carla": carla(dist),
    }
    pred = {"luminance": raw["luminance"], "carla": raw["carla"]}
    if pseudo_calibration is not None and "pseudo_nir" in maps:
        pn = bilinear_sample(maps["pseudo_nir"], uv)
        pred["nidar_no_irnet"] = pseudo_calibration.apply(pn, dist)[0].astype(np.float64)
    pred["nidar_ihat"] = raw["I_hat"]
    pred["nidar_full"] = res.intensity[idx].astype(np.float64)
    gt = np.asarray(intensity, dtype=np.float64)[idx]
    return {"xyz": p, "uv": uv, "range": dist, "gt": gt, "pred": pred, "raw": raw}


def loo_remap(frames: list[dict[str, Any]], calibration) -> None:
    """Add the leave-one-out quantile-remapped rows to every frame's ``pred`` (in place).

    For frame k, a :class:`~nidar_mi.nidar.calibration.QuantileMap` is fitted from the branch
    values of all other frames to their real intensities and applied to frame k. The R branch
    is distance-encoded with the source calibration's parameters first (as NIDAR-Full does).
    """
    from ..nidar.calibration import QuantileMap

    if len(frames) < 2:
        return
    sources = {
        "nidar_full_loo": [calibration.encode(f["raw"]["R"], f["range"]) for f in frames],
        "nidar_ihat_loo": [f["raw"]["I_hat"] for f in frames],
        "luminance_loo": [f["raw"]["luminance"] for f in frames],
        "carla_loo": [f["raw"]["carla"] for f in frames],
    }
    for k, f in enumerate(frames):
        others = [j for j in range(len(frames)) if j != k]
        ref = np.concatenate([frames[j]["gt"] for j in others])
        for key, vals in sources.items():
            qmap = QuantileMap.fit(np.concatenate([vals[j] for j in others]), ref)
            f["pred"][key] = qmap(vals[k])


def evaluate_kitti(
    kitti_dir: str, model, *, pseudo_calibration=None, lpips: bool = False
) -> dict[str, Any]:
    """Every KITTI frame under ``kitti_dir``: predictions, leave-one-out rows and metrics.

    Args:
        kitti_dir: folder with ``velodyne/``, ``image_2/``, ``calib/``.
        model: NIDAR model with its source calibration.
        pseudo_calibration: baseline (e)'s calibration.
        lpips: compute LPIPS on the camera maps.

    Returns:
        ``{"frames": [frame ids], "rows": [one per frame and method], "unavailable": {...}}``.

    Raises:
        NidarError: no complete frame in ``kitti_dir``, or the model has no calibration.
    """
    from ..datasets.kitti import frame_ids, load_frame
    from ..geometry import splat_points

    ids = frame_ids(kitti_dir)
    if not ids:
        raise NidarError(f"{kitti_dir}: no KITTI frame (velodyne/ID.bin + image_2 + calib)")
    if model.calibration is None:
        raise NidarError(f"{model.weights_dir}: no calibration.json beside the weights")
    frames, cams = [], []
    for fid in ids:
        fr = load_frame(kitti_dir, fid)
        frames.append(
            kitti_predictions(fr.xyz, fr.intensity, fr.rgb, fr.camera, model, pseudo_calibration)
        )
        cams.append(fr.camera)
    loo_remap(frames, model.calibration)
    rows = []
    for fid, f, cam in zip(ids, frames, cams):
        keys = [k for k in KITTI_METHODS if k in f["pred"]]
        maps, mask = splat_points(f["xyz"], {"gt": f["gt"], **{k: f["pred"][k] for k in keys}}, cam)
        for k in keys:
            pm = point_metrics(f["pred"][k], f["gt"])
            mm = map_metrics(maps[k], maps["gt"], mask, lpips=lpips)
            rows.append(
                {
                    "group": "kitti",
                    "scene": fid,
                    "camera": "image_2",
                    "method": k,
                    "n_points": pm["n"],
                    "point_rmse": pm["rmse"],
                    "point_mae": pm["mae"],
                    "spearman": pm["spearman"],
                    "map_rmse": mm["rmse"],
                    "map_medae": mm["medae"],
                    "map_psnr": mm["psnr"],
                    "map_ssim": mm["ssim"],
                    "map_lpips": mm["lpips"],
                }
            )
    return {"frames": ids, "rows": rows, "unavailable": dict(KITTI_UNAVAILABLE)}
