"""Small synthetic frames in the NIDAR training-data format, for tests.

A frame is a mosaic of rectangular "materials", each with a linear RGB albedo and an NIR
reflectance ``rho``, lit by a smooth shading field. The RGB image is ``albedo * shading``
encoded as 8-bit sRGB, the NIR image ``rho * shading``, and the LiDAR intensity
``intensity_scale * rho * shading`` on every third row of the lower two thirds of the image
(a scan pattern only partly overlapping the camera's view; each such row is one ring, and each
return lies on the surface at the pixel's ``depth``). ``R_true = rho`` and ``S_true = π ·
shading`` (so that ``S_true = π · nir / R_true``, as for rendered frames), ``R_surface = rho`` and
``A_true`` the albedo (no gloss: the surface and monostatic reflectances agree). The format is the one
:mod:`nidar_mi.nidar.data` reads; the content only has to be learnable, not realistic.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from nidar_mi.io.images import linear_to_srgb

__all__ = ["synthetic_frame", "write_synthetic_dataset"]


def _linear_to_srgb8(lin: np.ndarray) -> np.ndarray:
    return np.round(linear_to_srgb(lin) * 255.0).astype(np.uint8)


def synthetic_frame(
    rng: np.random.Generator, height: int = 48, width: int = 64, intensity_scale: float = 255.0
) -> dict[str, np.ndarray]:
    """One frame with every key of the training-data format.

    Args:
        rng: random generator.
        height, width: image size in pixels.
        intensity_scale: intensity of a white (``rho = 1``), fully lit surface.

    Returns:
        Dict of arrays with the dtypes and shapes of :data:`nidar_mi.training_frames.FRAME_KEYS`.
    """
    n_mat = 6
    albedo = rng.uniform(0.05, 0.9, size=(n_mat, 3))
    # NIR reflectance loosely tied to red (vegetation-like materials: dark red, bright NIR).
    rho = np.clip(0.6 * albedo[:, 0] + rng.uniform(0.0, 0.5, n_mat), 0.02, 1.0)
    labels = np.zeros((height, width), dtype=np.int64)
    for _ in range(8):
        y0, x0 = rng.integers(0, height - 4), rng.integers(0, width - 4)
        h, w = rng.integers(4, height // 2 + 1), rng.integers(4, width // 2 + 1)
        labels[y0 : y0 + h, x0 : x0 + w] = rng.integers(0, n_mat)
    yy, xx = np.mgrid[0:height, 0:width] / np.array([height, width])[:, None, None]
    phase = rng.uniform(0, 2 * np.pi)
    shading = 0.55 + 0.35 * np.cos(2.0 * xx + 1.5 * yy + phase) * (0.8 + 0.2 * yy)
    rgb_lin = albedo[labels] * shading[..., None]
    nir = (rho[labels] * shading).astype(np.float32)
    mask = np.zeros((height, width), dtype=bool)
    mask[height // 3 :: 3] = True
    mask &= rng.random((height, width)) > 0.1
    intensity = np.where(mask, intensity_scale * nir, 0.0).astype(np.float32)
    depth = (4.0 + 20.0 * (1.0 - yy)).astype(np.float32)
    f = 0.8 * width
    k = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]], dtype=np.float64)
    # LiDAR x forward, y left, z up -> camera x right, y down, z forward.
    t = np.eye(4)
    t[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
    t[:3, 3] = [0.0, 0.3, -0.1]
    # the returns: every masked pixel's surface point, back in the LiDAR frame
    rows, cols = np.nonzero(mask)
    z = depth[rows, cols].astype(np.float64)
    cam_pts = np.stack([(cols - k[0, 2]) / f * z, (rows - k[1, 2]) / f * z, z], 1)
    xyz = (cam_pts - t[:3, 3]) @ t[:3, :3]
    ring = np.searchsorted(np.unique(rows), rows)
    return {
        "rgb": _linear_to_srgb8(rgb_lin),
        "nir": nir,
        "intensity": intensity,
        "mask": mask,
        "depth": depth,
        "range": np.where(mask, depth, 0.0).astype(np.float32),
        "reflectance": np.where(mask, rho[labels], 0.0).astype(np.float32),
        "K": k,
        "T_cam_lidar": t,
        "R_true": rho[labels].astype(np.float32),
        "S_true": (np.pi * shading).astype(np.float32),
        "R_surface": rho[labels].astype(np.float32),
        "A_true": albedo[labels].astype(np.float32),
        "points_xyz": xyz.astype(np.float32),
        "points_intensity": intensity[rows, cols],
        "points_ring": ring.astype(np.int16),
    }


def write_synthetic_dataset(
    root: str | Path,
    counts: dict[str, int] | None = None,
    height: int = 48,
    width: int = 64,
    seed: int = 0,
    intensity_scale: float = 255.0,
) -> Path:
    """Write ``root/meta.json`` and ``root/<split>/frame_NNNN.npz`` frames.

    Args:
        root: output directory (created).
        counts: frames per split; default ``{"train": 4, "val": 2, "test": 1}``.
        height, width: image size.
        seed: seed of the content.
        intensity_scale: stored in ``meta.json`` and used for the intensities.

    Returns:
        ``root`` as a Path.
    """
    root = Path(root)
    counts = counts or {"train": 4, "val": 2, "test": 1}
    rng = np.random.default_rng(seed)
    splits = {}
    for split, n in counts.items():
        (root / split).mkdir(parents=True, exist_ok=True)
        names = []
        for i in range(n):
            name = f"frame_{i:04d}"
            frame = synthetic_frame(rng, height, width, intensity_scale)
            np.savez_compressed(root / split / f"{name}.npz", **frame)
            names.append(name)
        splits[split] = names
    meta = {
        "intensity_scale": float(intensity_scale),
        "wavelength_nm": 905,
        "splits": splits,
        "source": "render",
        "generator": "tests.helpers.synthetic_frames",
    }
    (root / "meta.json").write_text(json.dumps(meta, indent=2))
    return root
