"""Metrics of a prediction at a scan's camera-visible returns (a :class:`ScanFrame`).

For one frame and one prediction (an intensity per return on the [0, 1] scale; values outside
are clipped first), against the sensor's own intensity:

* ``spearman``, ``rmse``: over the returns (:func:`nidar_mi.eval.metrics.spearman`,
  :func:`~nidar_mi.eval.metrics.rmse`).
* ``ssim_cam``: SSIM of the sparse camera maps (each return splatted to its nearest pixel,
  nearest return wins; :func:`nidar_mi.geometry.splat_points`), averaged over the occupied
  pixels; with several cameras, the mean over the cameras that see returns.
* ``ssim_ri``: SSIM of the LiDAR range images, averaged over the occupied cells. Rows are the
  rings when every return has one, else :data:`RI_ROWS` elevation bins over the returns'
  elevation range; columns are :data:`RI_COLUMNS` azimuth bins over 360° (column 0 at +180°,
  azimuth decreasing to the right, as a spinning sensor's range image), cropped to the occupied
  columns plus :data:`RI_MARGIN` on each side; the nearest return wins a cell.
* ``spearman_bin``: Spearman's ρ within range bins of :data:`BIN_M` m (``[0, 2)``, ``[2, 4)``,
  ...), pooled as the mean over the bins with at least :data:`BIN_MIN_POINTS` returns, each
  weighted by its number of returns (bins where either side is constant are left out). It
  separates the ranking of surfaces at one distance, which should transfer between sensors, from
  the sensor's own range response, which does not.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import NidarError
from .metrics import rmse, spearman, ssim

__all__ = [
    "BIN_M",
    "BIN_MIN_POINTS",
    "RI_COLUMNS",
    "RI_MARGIN",
    "RI_ROWS",
    "SCAN_METRICS",
    "binned_spearman",
    "range_image",
    "scan_metrics",
]

#: Width of the range bins of ``spearman_bin``, m.
BIN_M = 2.0
#: Fewest returns for a range bin to count in ``spearman_bin``.
BIN_MIN_POINTS = 50
#: Azimuth columns of the range image (over 360°).
RI_COLUMNS = 2048
#: Rows of the range image when the returns have no rings (elevation bins).
RI_ROWS = 64
#: Empty columns kept on each side of the occupied ones.
RI_MARGIN = 8
#: (key, header, decimals, best) of the metric columns.
SCAN_METRICS = (
    ("spearman", "Spearman↑", 3, "max"),
    ("rmse", "RMSE↓", 4, "min"),
    ("ssim_cam", "SSIM map↑", 4, "max"),
    ("ssim_ri", "SSIM range image↑", 4, "max"),
    ("spearman_bin", "Spearman in 2 m bins↑", 3, "max"),
)


def binned_spearman(
    pred: Any, gt: Any, range_m: Any, width: float = BIN_M, min_points: int = BIN_MIN_POINTS
) -> float:
    """Count-weighted mean of Spearman's ρ within range bins (module docstring); NaN if no bin
    counts."""
    p = np.asarray(pred, dtype=np.float64)
    g = np.asarray(gt, dtype=np.float64)
    b = np.floor(np.asarray(range_m, dtype=np.float64) / width).astype(np.int64)
    num, den = 0.0, 0
    for k in np.unique(b):
        s = b == k
        n = int(s.sum())
        if n < min_points:
            continue
        rho = spearman(p[s], g[s])
        if np.isfinite(rho):
            num += rho * n
            den += n
    return num / den if den else float("nan")


def range_image(
    xyz: np.ndarray, ring: np.ndarray, values: dict[str, np.ndarray]
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Range images of per-return values (module docstring for the grid).

    Args:
        xyz: (N, 3) returns, sensor frame, m.
        ring: (N,) rings (-1 unknown; any -1 switches to elevation rows).
        values: name -> (N,) values.

    Returns:
        ``(images, mask)``: name -> (rows, columns) float64 image, and the occupied cells.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    rng = np.linalg.norm(xyz, axis=1)
    az = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    col = np.floor((180.0 - az) / 360.0 * RI_COLUMNS).astype(np.int64) % RI_COLUMNS
    ring = np.asarray(ring, dtype=np.int64)
    if ring.size and ring.min() >= 0:
        row, rows = ring, int(ring.max()) + 1
    else:
        el = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
        lo, hi = float(el.min()), float(el.max()) + 1e-9
        row = np.minimum(((hi - el) / (hi - lo) * RI_ROWS).astype(np.int64), RI_ROWS - 1)
        rows = RI_ROWS
    pix = row * RI_COLUMNS + col
    order = np.argsort(rng, kind="stable")
    _, first = np.unique(pix[order], return_index=True)
    keep = order[first]
    mask = np.zeros(rows * RI_COLUMNS, dtype=bool)
    mask[pix[keep]] = True
    mask = mask.reshape(rows, RI_COLUMNS)
    used = np.flatnonzero(mask.any(0))
    lo_c, hi_c = (
        max(int(used.min()) - RI_MARGIN, 0),
        min(int(used.max()) + RI_MARGIN + 1, RI_COLUMNS),
    )
    out = {}
    for name, v in values.items():
        img = np.zeros(rows * RI_COLUMNS)
        img[pix[keep]] = np.asarray(v, dtype=np.float64)[keep]
        out[name] = img.reshape(rows, RI_COLUMNS)[:, lo_c:hi_c]
    return out, mask[:, lo_c:hi_c]


def scan_metrics(scan, pred: Any) -> dict[str, float]:
    """The metrics of the module docstring for one frame.

    Args:
        scan: a :class:`~nidar_mi.datasets.scans.ScanFrame`.
        pred: (N,) prediction at its returns.

    Raises:
        NidarError: a prediction of the wrong length or with non-finite values.
    """
    from ..geometry import splat_points

    p = np.asarray(pred, dtype=np.float64).reshape(-1)
    g = np.asarray(scan.intensity, dtype=np.float64)
    if p.shape != g.shape:
        raise NidarError(f"{scan.name}: {p.size} predictions for {g.size} returns")
    if not np.all(np.isfinite(p)):
        raise NidarError(f"{scan.name}: the prediction has non-finite values")
    p = np.clip(p, 0.0, 1.0)
    cams = []
    for cam in scan.cameras:
        maps, mask = splat_points(scan.xyz, {"p": p, "g": g}, cam)
        if mask.any():
            cams.append(ssim(maps["p"], maps["g"], mask))
    ri, ri_mask = range_image(scan.xyz, scan.ring, {"p": p, "g": g})
    return {
        "spearman": spearman(p, g),
        "rmse": rmse(p, g),
        "ssim_cam": float(np.mean(cams)) if cams else float("nan"),
        "ssim_ri": ssim(ri["p"], ri["g"], ri_mask),
        "spearman_bin": binned_spearman(p, g, scan.range_m),
    }
