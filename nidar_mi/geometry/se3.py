"""Rigid motions: SE(3) exponential and logarithm, poses interpolated along a trajectory, and a
Mitsuba transform as a NumPy pose (:func:`transform_matrix`).

Between two poses ``T0`` and ``T1`` the interpolated pose at fraction ``s`` is the constant-twist
(screw) motion ``T(s) = T0 · exp(s · log(T0⁻¹ T1))``: a vehicle turning at constant yaw rate and
speed moves along the arc, not the chord. Poses are (4, 4) float64 homogeneous matrices
(``[R | t; 0 0 0 1]``); twists are (6,) ``(ρ, ω)``, translation part first.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "POSE_TOLERANCE",
    "se3_exp",
    "se3_log",
    "interpolate_poses",
    "rigid_pose_problem",
    "transform_matrix",
]

#: How far a pose's rotation block may be from a rotation: |RᵀR − I| and |det R − 1| at most
#: this (poses are float32 in the renderer: ~1e-7 relative; a text matrix rounded to 6
#: digits stays well inside), and the bottom row from (0, 0, 0, 1).
POSE_TOLERANCE = 1e-4


def transform_matrix(transform) -> np.ndarray:
    """(4, 4) float64 matrix of a Mitsuba transform (``mi.Transform4f``, ``AffineTransform4f``
    or anything with ``.matrix.numpy()``), e.g. a sensor's ``world_transform()``."""
    return np.array(transform.matrix.numpy(), dtype=np.float64).reshape(4, 4)


def _hat(w: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) skew-symmetric matrices."""
    z = np.zeros(w.shape[:-1])
    return np.stack(
        [
            np.stack([z, -w[..., 2], w[..., 1]], -1),
            np.stack([w[..., 2], z, -w[..., 0]], -1),
            np.stack([-w[..., 1], w[..., 0], z], -1),
        ],
        -2,
    )


def _v_matrix(w: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3): the left Jacobian V of SO(3), ``t = V ρ``."""
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    W = _hat(w)
    small = theta < 1e-6
    th = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(th)) / th**2)
    b = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (th - np.sin(th)) / th**3)
    return np.eye(3) + a * W + b * (W @ W)


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """(..., 6) twists ``(ρ, ω)`` -> (..., 4, 4) poses."""
    from scipy.spatial.transform import Rotation

    xi = np.asarray(xi, dtype=np.float64)
    rho, w = xi[..., :3], xi[..., 3:]
    out = np.zeros(xi.shape[:-1] + (4, 4))
    out[..., :3, :3] = Rotation.from_rotvec(w.reshape(-1, 3)).as_matrix().reshape(w.shape + (3,))
    out[..., :3, 3] = np.einsum("...ij,...j->...i", _v_matrix(w), rho)
    out[..., 3, 3] = 1.0
    return out


def se3_log(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) poses -> (..., 6) twists ``(ρ, ω)`` (rotation angle in [0, π])."""
    from scipy.spatial.transform import Rotation

    T = np.asarray(T, dtype=np.float64)
    R = T[..., :3, :3]
    w = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(R.shape[:-2] + (3,))
    rho = np.linalg.solve(_v_matrix(w), T[..., :3, 3][..., None])[..., 0]
    return np.concatenate([rho, w], axis=-1)


def interpolate_poses(times: np.ndarray, poses: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Poses at ``query`` times, SE(3)-interpolated between the two samples around each.

    Args:
        times: (K,) strictly increasing sample times, s.
        poses: (K, 4, 4) poses at those times.
        query: (M,) times inside ``[times[0], times[-1]]``.

    Returns:
        (M, 4, 4) float64 poses; a query equal to a sample time returns that sample exactly.

    Raises:
        ValueError: a query outside the sampled interval.
    """
    times = np.asarray(times, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    query = np.asarray(query, dtype=np.float64)
    if query.size and (query.min() < times[0] or query.max() > times[-1]):
        raise ValueError(
            f"time {query.min() if query.min() < times[0] else query.max():.6g} s is outside the "
            f"trajectory ({times[0]:.6g} .. {times[-1]:.6g} s)"
        )
    if len(times) == 1:
        return np.repeat(poses[:1], len(query), axis=0)
    i = np.clip(np.searchsorted(times, query, side="right") - 1, 0, len(times) - 2)
    s = (query - times[i]) / (times[i + 1] - times[i])
    T0, T1 = poses[i], poses[i + 1]
    xi = se3_log(np.linalg.inv(T0) @ T1)
    out = T0 @ se3_exp(s[:, None] * xi)
    exact0, exact1 = s == 0.0, s == 1.0
    out[exact0] = T0[exact0]
    out[exact1] = T1[exact1]
    return out


def rigid_pose_problem(T: np.ndarray, tol: float = POSE_TOLERANCE) -> str | None:
    """Why the (4, 4) matrix ``T`` is not a rigid pose (a rotation and a translation), in
    words, or None when it is one within ``tol`` (:data:`POSE_TOLERANCE`).

    Returns:
        e.g. ``holds NaN or infinite values``, ``scales by 2``, ``mirrors (det -1)``,
        ``shears or scales unevenly``, ``is not affine (bottom row ...)``.
    """
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        return f"is not a 4x4 matrix (shape {T.shape})"
    if not np.isfinite(T).all():
        return "holds NaN or infinite values"
    if np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max() > tol:
        return f"is not affine (bottom row {np.round(T[3], 6).tolist()})"
    R = T[:3, :3]
    det = float(np.linalg.det(R))
    scales = np.linalg.svd(R, compute_uv=False)
    if scales.min() <= tol:
        return "collapses space (scale 0)"
    if np.abs(R.T @ R - np.eye(3)).max() <= tol and abs(det - 1.0) <= tol:
        return None
    if det < 0 and np.abs(scales - 1.0).max() <= tol:
        return f"mirrors (det {det:.3g})"
    if np.ptp(scales) <= tol * scales.max():
        return f"scales by {scales.mean():.6g}"
    return f"shears or scales unevenly (scales {', '.join(f'{v:.4g}' for v in scales)})"
