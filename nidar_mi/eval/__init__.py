"""Evaluation: intensity metrics on maps and points, and the baselines NIDAR is compared with.

* :mod:`~nidar_mi.eval.metrics`: RMSE, MedAE, PSNR, SSIM, LPIPS on projected maps; RMSE, MAE,
  Spearman on points; intensity scaling to [0, 1].
* :mod:`~nidar_mi.eval.baselines`: RGB-asset physics (the RGB-only twin), luminance as ρ,
  a constant per class, CARLA's exponential, (h) linear colour + distance, (i) the linear
  RGB -> NIR map.

* :mod:`~nidar_mi.eval.rendered` / :mod:`~nidar_mi.eval.heldout`: every method's prediction on
  the camera-visible returns of rendered frames, and their metric tables.
* :mod:`~nidar_mi.eval.loo`, :mod:`~nidar_mi.eval.scan_metrics`: the leave-one-frame-out
  protocol on a sensor's real scans for any method, and its metrics; :mod:`~nidar_mi.eval.real`
  runs it on KITTI.
* :mod:`~nidar_mi.eval.photos`: pseudo-NIR against real NIR photos.
* :mod:`~nidar_mi.eval.ablation`: the paper's IRNet structure and pseudo-NIR-vs-RGB ablations.
* :mod:`~nidar_mi.eval.figures`, :mod:`~nidar_mi.eval.tables`: figures and tables.

``python -m nidar_mi.evaluate`` is the thin command line over these.
"""

from .baselines import ClassConstant, carla, luminance_rho, rgb_twin_scan
from .metrics import (
    lpips_alex,
    lpips_unavailable_reason,
    map_metrics,
    point_metrics,
    scale_intensity,
    spearman,
    ssim,
)

__all__ = [
    "ClassConstant",
    "carla",
    "luminance_rho",
    "rgb_twin_scan",
    "lpips_alex",
    "lpips_unavailable_reason",
    "map_metrics",
    "point_metrics",
    "scale_intensity",
    "spearman",
    "ssim",
]
