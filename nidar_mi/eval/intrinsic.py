"""How well IRNet's decomposition separates reflectance from shading, on rendered frames.

Rendered frames carry the true reflectance at the LiDAR wavelength (``R_true``) and the true
shading (``S_true``: irradiance, so cast shadows and incidence; :mod:`nidar_mi.training_frames`). A
decomposition whose ``R`` still carries shadows correlates with ``S_true``; one that recovers the
material correlates with ``R_true``. :func:`intrinsic_scores` measures both on the pixels with a
surface (``R_true >= 1e-3``; ``R_true`` clipped to [0, 1] as in training):

* ``r_R_shading``: Pearson r of ``R`` and ``S_true`` (0 if ``R`` carries no shading; the true
  maps' own ``r_true_shading`` is the value of a perfect ``R``, not 0, where bright materials
  happen to be lit);
* ``r_input_shading``: the same for the network's input image (pseudo-NIR), for reference;
* ``r_R_reflectance`` and ``spearman_R_reflectance``: ``R`` against ``R_true``;
* ``r_R_S``: Pearson r of the predicted ``R`` and ``S`` (a degenerate decomposition has both
  follow the image).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import NidarError
from ..training_frames import load_frame

__all__ = ["INTRINSIC_KEYS", "intrinsic_frame_scores", "intrinsic_scores"]

INTRINSIC_KEYS = (
    "r_R_shading",
    "r_true_shading",
    "r_input_shading",
    "r_R_reflectance",
    "spearman_R_reflectance",
    "r_R_S",
)


def _pearson(a: np.ndarray, b: np.ndarray) -> float:
    a = a.astype(np.float64) - a.mean()
    b = b.astype(np.float64) - b.mean()
    den = np.sqrt((a * a).sum() * (b * b).sum())
    return float((a * b).sum() / den) if den > 0 else float("nan")


def intrinsic_frame_scores(
    maps: dict[str, np.ndarray], r_true: np.ndarray, s_true: np.ndarray
) -> dict[str, float]:
    """Scores of one frame's predicted maps against its true ones.

    Args:
        maps: ``R``, ``S`` and ``pseudo_nir`` ``(H, W)`` (as from
            :meth:`~nidar_mi.nidar.pipeline.NidarModel.predict_image`).
        r_true, s_true: ``(H, W)`` true reflectance and shading of the frame.

    Returns:
        ``{key: value}`` for :data:`INTRINSIC_KEYS` (NaN where a map is constant on the
        surface pixels), plus ``pixels``.

    Raises:
        NidarError: shapes differ, or no pixel has a surface.
    """
    from .metrics import spearman

    shape = np.shape(r_true)
    for name in ("R", "S", "pseudo_nir"):
        if np.shape(maps[name]) != shape:
            raise NidarError(f"map {name} has shape {np.shape(maps[name])}, the frame {shape}")
    valid = np.asarray(r_true) >= 1e-3
    if not valid.any():
        raise NidarError("no pixel with a surface (R_true >= 1e-3)")
    rt = np.clip(np.asarray(r_true)[valid], 0.0, 1.0)
    st = np.asarray(s_true)[valid]
    r, s = np.asarray(maps["R"])[valid], np.asarray(maps["S"])[valid]
    x = np.asarray(maps["pseudo_nir"])[valid]
    return {
        "r_R_shading": _pearson(r, st),
        "r_true_shading": _pearson(rt, st),
        "r_input_shading": _pearson(x, st),
        "r_R_reflectance": _pearson(r, rt),
        "spearman_R_reflectance": spearman(r, rt),
        "r_R_S": _pearson(r, s),
        "pixels": int(valid.sum()),
    }


def intrinsic_scores(model, frames: Sequence[str | Path], scale: float | None = None) -> dict:
    """:func:`intrinsic_frame_scores` of ``model`` on rendered frame files, and their means.

    Args:
        model: a :class:`~nidar_mi.nidar.pipeline.NidarModel` (the maps come back at the
            frame's size).
        frames: frame files carrying ``rgb``, ``R_true`` and ``S_true``.
        scale: inference resolution relative to the frames (None: the model's default).

    Returns:
        ``{"rows": [{"frame": stem, **scores}], "mean": {key: mean over frames}, "scale":
        the inference scale used}``.
    """
    rows = []
    for path in frames:
        arrays = load_frame(path, ("rgb", "R_true", "S_true"))
        maps = model.predict_image(arrays["rgb"], scale=scale)
        scores = intrinsic_frame_scores(maps, arrays["R_true"], arrays["S_true"])
        rows.append({"frame": Path(path).stem, **scores})
    if not rows:
        raise NidarError("no frames to score the decomposition on")
    mean = {k: float(np.nanmean([r[k] for r in rows])) for k in INTRINSIC_KEYS}
    used = float(model.scale if scale is None else scale)
    return {"rows": rows, "mean": mean, "scale": used}
