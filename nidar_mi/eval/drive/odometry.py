"""Trajectory errors: ATE after SE(3) alignment and the KITTI odometry devkit's relative error.

Poses are (N, 4, 4) float64 homogeneous transforms ``T_world_sensor`` (m), estimate and ground
truth frame by frame.

* :func:`umeyama`: the rotation and translation (and optionally scale) that best map one point
  set onto another in least squares (Umeyama 1991, "Least-squares estimation of transformation
  parameters between two point patterns", eqs. 34-42).
* :func:`ate`: absolute trajectory error, the RMSE of the position differences after aligning
  the estimated positions to the true ones with :func:`umeyama` (SE(3), no scale), as defined by
  Sturm et al. (2012) for the TUM RGB-D benchmark.
* :func:`rpe_kitti`: the relative error of the KITTI odometry devkit (``evaluate_odometry.cpp``):
  every 10th frame starts segments of each length (m of true path); the error of a segment is
  ``inv(inv(E_a) E_b) · inv(G_a) G_b``, its translation norm and rotation angle divided by the
  length; the result is the mean over all segments, in % and deg/m.
* :func:`end_drift`: the end-point error of the estimate (both trajectories expressed relative
  to their first pose, no alignment) as a fraction of the path length.
"""

from __future__ import annotations

import numpy as np

__all__ = ["KITTI_LENGTHS_M", "umeyama", "ate", "rpe_kitti", "end_drift", "path_length"]

#: Segment lengths of the KITTI odometry benchmark, m.
KITTI_LENGTHS_M = (100, 200, 300, 400, 500, 600, 700, 800)


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = False):
    """(R, t, s) minimising ``sum |dst_i - (s R src_i + t)|²``.

    Args:
        src, dst: (N, 3) corresponding points (N >= 3, not collinear for a unique rotation).
        with_scale: also estimate the scale (else s = 1).

    Returns:
        R (3, 3) rotation (det +1), t (3,), s float.
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    cov = xd.T @ xs / len(src)
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1.0
    R = U @ S @ Vt
    s = float(np.trace(np.diag(D) @ S) / (xs**2).sum(1).mean()) if with_scale else 1.0
    t = mu_d - s * R @ mu_s
    return R, t, s


def ate(gt: np.ndarray, est: np.ndarray) -> dict:
    """Absolute trajectory error after aligning ``est`` to ``gt`` (SE(3), Umeyama).

    Returns:
        ``rmse``, ``mean``, ``median``, ``max`` (m) of the position errors, and ``aligned``:
        (N, 4, 4) the estimate after alignment.
    """
    gt, est = _check(gt, est)
    R, t, _ = umeyama(est[:, :3, 3], gt[:, :3, 3])
    A = np.eye(4)
    A[:3, :3], A[:3, 3] = R, t
    aligned = A @ est
    e = np.linalg.norm(aligned[:, :3, 3] - gt[:, :3, 3], axis=1)
    return {
        "rmse": float(np.sqrt(np.mean(e**2))),
        "mean": float(e.mean()),
        "median": float(np.median(e)),
        "max": float(e.max()),
        "aligned": aligned,
    }


def path_length(poses: np.ndarray) -> np.ndarray:
    """(N,) distance travelled up to each pose, m."""
    p = np.asarray(poses)[:, :3, 3]
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def _rotation_angle(R: np.ndarray) -> float:
    d = 0.5 * (np.trace(R) - 1.0)
    return float(np.arccos(np.clip(d, -1.0, 1.0)))


def rpe_kitti(gt: np.ndarray, est: np.ndarray, lengths=KITTI_LENGTHS_M, step: int = 10) -> dict:
    """Relative error over fixed path lengths, as the KITTI odometry devkit computes it.

    Args:
        gt, est: (N, 4, 4) poses.
        lengths: segment lengths in m of the true path.
        step: frames between segment starts (the devkit's 10).

    Returns:
        ``t_err_pct`` (mean translation error, % of the length), ``r_err_deg_per_m``,
        ``segments`` (how many), and ``per_length``: {length: (t %, deg/m, count)} for the
        lengths that fit in the drive. NaN-free: with no segment at all the errors are None.
    """
    gt, est = _check(gt, est)
    dist = path_length(gt)
    rows = []
    for first in range(0, len(gt), step):
        for L in lengths:
            later = np.nonzero(dist > dist[first] + L)[0]
            if len(later) == 0:
                continue
            last = int(later[0])
            d_gt = np.linalg.inv(gt[first]) @ gt[last]
            d_est = np.linalg.inv(est[first]) @ est[last]
            err = np.linalg.inv(d_est) @ d_gt
            rows.append((L, np.linalg.norm(err[:3, 3]) / L, _rotation_angle(err[:3, :3]) / L))
    if not rows:
        return {"t_err_pct": None, "r_err_deg_per_m": None, "segments": 0, "per_length": {}}
    arr = np.array(rows)
    per = {}
    for L in lengths:
        m = arr[:, 0] == L
        if m.any():
            per[int(L)] = (
                float(arr[m, 1].mean() * 100),
                float(np.degrees(arr[m, 2].mean())),
                int(m.sum()),
            )
    return {
        "t_err_pct": float(arr[:, 1].mean() * 100),
        "r_err_deg_per_m": float(np.degrees(arr[:, 2].mean())),
        "segments": len(rows),
        "per_length": per,
    }


def end_drift(gt: np.ndarray, est: np.ndarray) -> dict:
    """End-point drift: both trajectories relative to their first pose, no alignment.

    Returns:
        ``error_m`` (position error of the last pose), ``path_m`` (true path length) and
        ``pct`` (their ratio, %).
    """
    gt, est = _check(gt, est)
    g = np.linalg.inv(gt[0]) @ gt[-1]
    e = np.linalg.inv(est[0]) @ est[-1]
    err = float(np.linalg.norm(g[:3, 3] - e[:3, 3]))
    L = float(path_length(gt)[-1])
    return {"error_m": err, "path_m": L, "pct": 100.0 * err / L if L > 0 else None}


def _check(gt, est) -> tuple[np.ndarray, np.ndarray]:
    gt = np.asarray(gt, dtype=np.float64)
    est = np.asarray(est, dtype=np.float64)
    if gt.shape != est.shape or gt.ndim != 3 or gt.shape[1:] != (4, 4) or len(gt) < 2:
        raise ValueError(f"expected two (N>=2, 4, 4) pose arrays, got {gt.shape} and {est.shape}")
    if not (np.isfinite(gt).all() and np.isfinite(est).all()):
        raise ValueError("poses must be finite")
    return gt, est
