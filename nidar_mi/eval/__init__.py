"""Evaluation: intensity metrics on maps and points, and the baselines NIDAR is compared with.

* :mod:`~nidar_mi.eval.metrics`: RMSE, MedAE, PSNR, SSIM, LPIPS on projected maps; RMSE, MAE,
  Spearman on points; intensity scaling to [0, 1].
* :mod:`~nidar_mi.eval.baselines`: RGB-asset physics (the RGB-only twin), luminance as ρ,
  a constant per class, CARLA's exponential.

Both are plain functions, so an evaluation command is a loop over frames that calls them.
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
