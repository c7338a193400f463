"""KISS-ICP (Vizzo et al., RA-L 2023; the ``kiss-icp`` package) on the frames of a drive.

:func:`run_odometry` feeds frames to :class:`kiss_icp.kiss_icp.KissICP` with its default
configuration (``max_range`` 100 m, voxel size 1 m, adaptive threshold) and returns its pose after
every frame: ``T_{lidar_0 <- lidar_k}``. With per-point times and ``deskew`` the times are scaled
to [0, 1] over the sweep, the form KISS-ICP's de-skewing expects; it then corrects every point to
the middle of the sweep, so its pose of frame k is the pose at mid-sweep.

KISS-ICP is used through its public odometry class (``KissICP(config).register_frame``,
``last_pose``) and its configuration only.

:func:`register_pair` aligns one scan to another for loop constraints, from an initial guess,
with this module's own ICP in KISS-ICP's formulation (point to point, Geman-McClure kernel,
Gauss-Newton on SE(3), voxel-downsampled scans) over correspondence distances from coarse to
fine; :func:`aligned_overlap` is the fraction of aligned points that land within a distance of the
target (the check a loop must pass).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = [
    "GROUND_Z_M",
    "icp",
    "kiss_config",
    "run_odometry",
    "register_pair",
    "aligned_overlap",
    "remove_ground",
    "voxel_down_sample",
]


def kiss_config(deskew: bool, threads: int = 2):
    """KISS-ICP's default configuration, with de-skewing on or off and a thread limit."""
    from kiss_icp.config import load_config

    cfg = load_config(None)
    cfg.data.deskew = bool(deskew)
    cfg.registration.max_num_threads = int(threads)
    return cfg


def run_odometry(
    load: Callable[[int], tuple[np.ndarray, np.ndarray | None]],
    frames: int,
    *,
    deskew: bool = True,
    progress: bool = True,
) -> np.ndarray:
    """KISS-ICP's pose after each frame.

    Args:
        load: ``load(k) -> (xyz (N, 3) m, t (N,) s since the sweep's start, or None)``.
        frames: how many frames.
        deskew: let KISS-ICP de-skew (only meaningful with per-point times).
        progress: progress bar on stderr.

    Returns:
        (frames, 4, 4) float64 ``T_{lidar_0 <- lidar_k}``.
    """
    from kiss_icp.kiss_icp import KissICP

    from ...progress import progress_bar

    odom = KissICP(kiss_config(deskew))
    poses = np.zeros((frames, 4, 4))
    for k in progress_bar(range(frames), show=progress, desc="KISS-ICP", unit="frame"):
        xyz, t = load(k)
        stamps = np.zeros(0)
        if t is not None and len(t):
            span = float(t.max() - t.min())
            stamps = (t - t.min()) / span if span > 0 else np.full(len(t), 0.5)
        odom.register_frame(np.asarray(xyz, dtype=np.float64), stamps.astype(np.float64))
        poses[k] = odom.last_pose
    return poses


#: Points lower than this in the LiDAR frame (m) are ground and left out of loop registration.
GROUND_Z_M = -1.3


def _above_ground(xyz: np.ndarray) -> np.ndarray:
    xyz = np.asarray(xyz, np.float64)
    return xyz[xyz[:, 2] > GROUND_Z_M]


def remove_ground(xyz: np.ndarray, height_m: float = 1.73, band_m: float = 0.3) -> np.ndarray:
    """The points of a sweep that are not on the ground plane.

    The plane ``z = a x + b y + c`` is fitted by least squares to the points below the sensor
    (z < 0.6 - ``height_m``) within 25 m, refitted to those within 0.15 m of the first fit; points
    within ``band_m`` of it are removed (road, sidewalks, kerbs). The fit follows the body's roll
    and pitch, which a fixed height cut would not.

    Args:
        xyz: (N, 3) points in the LiDAR frame, m.
        height_m: the LiDAR's height above the road, m.
        band_m: half-thickness of the removed band, m.
    """
    xyz = np.asarray(xyz)
    r = np.hypot(xyz[:, 0], xyz[:, 1])
    low = (xyz[:, 2] < 0.6 - height_m) & (r < 25.0)
    if low.sum() < 10:
        return xyz
    A = np.column_stack([xyz[:, 0], xyz[:, 1], np.ones(len(xyz))])
    coef = np.linalg.lstsq(A[low], xyz[low, 2], rcond=None)[0]
    near = low & (np.abs(A @ coef - xyz[:, 2]) < 0.15)
    if near.sum() >= 10:
        coef = np.linalg.lstsq(A[near], xyz[near, 2], rcond=None)[0]
    return xyz[np.abs(xyz[:, 2] - A @ coef) > band_m]


def voxel_down_sample(xyz: np.ndarray, size: float) -> np.ndarray:
    """The first point (in the given order) of each occupied cube of side ``size`` m: (M, 3)
    float64, in their order (KISS-ICP's down-sampling)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    if len(xyz) == 0:
        return xyz.reshape(0, 3)
    _, first = np.unique(np.floor(xyz / size).astype(np.int64), axis=0, return_index=True)
    return xyz[np.sort(first)]


def icp(
    source: np.ndarray,
    target: np.ndarray,
    guess: np.ndarray,
    sigma: float,
    *,
    max_iterations: int = 500,
    tolerance: float = 1e-4,
) -> np.ndarray:
    """(4, 4) pose taking ``source`` (N, 3) onto ``target`` (M, 3), refined from ``guess``.

    Point-to-point ICP as KISS-ICP registers a scan to its map: each transformed source point
    pairs with its nearest target point within ``3 sigma`` m; the pairs are weighted by the
    Geman-McClure kernel ``sigma² / (sigma + |r|²)²`` of their residual ``r``; one Gauss-Newton
    step on SE(3) (the update applied on the left) per iteration, until its norm is below
    ``tolerance`` or after ``max_iterations``.
    """
    from pykdtree.kdtree import KDTree

    from ...geometry.se3 import se3_exp

    src = np.ascontiguousarray(source, dtype=np.float64)
    tgt = np.ascontiguousarray(target, dtype=np.float64)
    tree = KDTree(tgt)
    T = np.asarray(guess, dtype=np.float64).copy()
    for _ in range(max_iterations):
        q = np.ascontiguousarray(src @ T[:3, :3].T + T[:3, 3])
        d, j = tree.query(q, k=1, distance_upper_bound=3.0 * sigma)
        ok = np.isfinite(d)
        if ok.sum() < 6:
            break
        q = q[ok]
        r = q - tgt[j[ok]]
        w = sigma**2 / (sigma + (r * r).sum(axis=1)) ** 2
        J = np.zeros((len(q), 3, 6))
        J[:, :, :3] = np.eye(3)
        J[:, :, 3:] = -_hat(q)
        H = np.einsum("n,nai,naj->ij", w, J, J)
        g = np.einsum("n,nai,na->i", w, J, r)
        dx = np.linalg.solve(H, -g)
        T = se3_exp(dx) @ T
        if np.linalg.norm(dx) < tolerance:
            break
    return T


def _hat(v: np.ndarray) -> np.ndarray:
    """(N, 3) -> (N, 3, 3) skew-symmetric matrices, ``hat(a) b = a x b``."""
    z = np.zeros(len(v))
    return np.stack(
        [
            np.stack([z, -v[:, 2], v[:, 1]], -1),
            np.stack([v[:, 2], z, -v[:, 0]], -1),
            np.stack([-v[:, 1], v[:, 0], z], -1),
        ],
        -2,
    )


def register_pair(source: np.ndarray, target: np.ndarray, guess: np.ndarray) -> np.ndarray:
    """(4, 4) transform taking ``source`` points (N, 3) onto ``target`` (M, 3), from ``guess``.

    The target down-sampled to 0.5 m cubes and the source to 1.5 m (KISS-ICP's map and
    keypoints), :func:`icp` with correspondence distances from coarse to fine (sigma 2, 1 and
    0.3 m). Ground points (z < :data:`GROUND_Z_M`) are left out: they agree under any shift
    along the road and would hold the alignment at its guess."""
    tgt = voxel_down_sample(_above_ground(target), 0.5)
    src = voxel_down_sample(_above_ground(source), 1.5)
    T = np.asarray(guess, dtype=np.float64)
    for sigma in (2.0, 1.0, 0.3):  # coarse to fine correspondence distances
        T = icp(src, tgt, T, sigma)
    return T


def aligned_overlap(
    source: np.ndarray, target: np.ndarray, T: np.ndarray, within_m: float = 0.3
) -> float:
    """Fraction of ``source`` points above the ground and within 40 m of its origin that ``T``
    puts within ``within_m`` of a ``target`` point above the ground."""
    from pykdtree.kdtree import KDTree  # the package's k-d tree (geometry/normals.py)

    s = _above_ground(source)
    s = s[np.linalg.norm(s[:, :2], axis=1) < 40.0]
    if len(s) == 0:
        return 0.0
    moved = np.ascontiguousarray(s @ T[:3, :3].T + T[:3, 3])
    tree = KDTree(np.ascontiguousarray(_above_ground(target)))
    d, _ = tree.query(moved, k=1, distance_upper_bound=within_m)
    return float(np.isfinite(d).mean())
