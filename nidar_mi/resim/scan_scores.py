"""Scores of a re-simulated scan against the real scan of the same (held-out) frame, and the
copy baselines.

Geometry, between the real returns ``A`` and the re-simulated ``B`` (both in the LiDAR frame,
closer than ``range_min`` left out):

* ``chamfer_m``: ``mean_a min_b |a - b| + mean_b min_a |a - b|`` (m);
* ``chamfer_sq``: the same with squared distances (m², the convention of LiDAR-NeRF's and
  LiDAR4D's tables);
* ``fscore``: ``2PR / (P + R)`` with P the share of ``B`` within 0.1 m of ``A`` and R the share
  of ``A`` within 0.1 m of ``B``; ``fscore_sq``: the same at squared distance 0.05 m² (~0.22 m),
  LiDAR-NeRF's threshold.

Intensity at matched points: each real return whose nearest re-simulated return lies within
:data:`MATCH_M` is matched to it; ``spearman`` and ``rmse`` (KITTI's [0, 1] scale) over the
matched returns, ``matched`` their share. Every method of one frame is scored on the same
matched returns.

Ray drop: over the beams (ring, column) of the scan's coverage, ``drop_agreement`` is the share
where the real and the re-simulated scan agree on return/no return; ``drop_iou`` the
intersection over union of their no-return beams.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "MATCH_M",
    "geometry_metrics",
    "matches",
    "intensity_metrics",
    "drop_metrics",
    "copy_intensity",
]

#: A real return is matched to the nearest re-simulated one closer than this, m.
MATCH_M = 0.1


def _nearest(a: np.ndarray, b: np.ndarray):
    from scipy.spatial import cKDTree

    return cKDTree(b).query(a, k=1)


def geometry_metrics(real: np.ndarray, sim: np.ndarray) -> dict[str, float]:
    """Chamfer distances and F-scores between (N, 3) real and (M, 3) re-simulated returns."""
    if len(real) == 0 or len(sim) == 0:
        nan = float("nan")
        return {"chamfer_m": nan, "chamfer_sq": nan, "fscore": 0.0, "fscore_sq": 0.0}
    d_rs, _ = _nearest(real, sim)
    d_sr, _ = _nearest(sim, real)

    def f(th, a, b):
        p, r = float(np.mean(b < th)), float(np.mean(a < th))
        return 2 * p * r / (p + r) if p + r > 0 else 0.0

    return {
        "chamfer_m": float(d_rs.mean() + d_sr.mean()),
        "chamfer_sq": float(np.mean(d_rs**2) + np.mean(d_sr**2)),
        "fscore": f(0.1, d_rs, d_sr),
        "fscore_sq": f(0.05, d_rs**2, d_sr**2),
    }


def matches(real: np.ndarray, sim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(matched, index)``: (N,) bool, real returns with a re-simulated one within
    :data:`MATCH_M`, and (N,) the index of that return (0 where none)."""
    if len(sim) == 0:
        return np.zeros(len(real), bool), np.zeros(len(real), np.int64)
    d, idx = _nearest(real, sim)
    ok = d <= MATCH_M
    return ok, np.where(ok, idx, 0)


def intensity_metrics(pred: np.ndarray, real: np.ndarray) -> dict[str, float]:
    """Spearman and RMSE of (K,) predicted against (K,) real intensities (predictions clipped
    to [0, 1], as KITTI stores them)."""
    from ..eval.metrics import rmse, spearman

    if len(real) < 3:
        return {"spearman": float("nan"), "rmse": float("nan")}
    p = np.clip(np.asarray(pred, dtype=np.float64), 0.0, 1.0)
    return {"spearman": spearman(p, real), "rmse": rmse(p, real)}


def drop_metrics(real_occ: np.ndarray, sim_occ: np.ndarray, coverage: np.ndarray) -> dict:
    """Ray-drop agreement over the (R, C) beams of the coverage (C,) columns."""
    r, s = real_occ[:, coverage], sim_occ[:, coverage]
    both_drop = np.sum(~r & ~s)
    any_drop = np.sum(~r | ~s)
    return {
        "drop_agreement": float(np.mean(r == s)) if r.size else float("nan"),
        "drop_iou": float(both_drop / any_drop) if any_drop else float("nan"),
    }


def copy_intensity(query_world: np.ndarray, source_world: np.ndarray, source_i: np.ndarray):
    """(N,) the intensity of the nearest source return of each query point (world frame)."""
    if len(source_world) == 0:
        return np.zeros(len(query_world))
    _, idx = _nearest(query_world, source_world)
    return np.asarray(source_i)[idx]
