"""Pseudo-NIR against real NIR photos: the held-out RGB/NIR table.

Each method maps an 8-bit sRGB photo to an (H, W) NIR-like image. It is compared with the
pixel-aligned NIR photo of the same scene (:mod:`nidar_mi.datasets.rgbnir`), both in the linear
domain (the 8-bit NIR photo decoded with the sRGB transfer function), on the held-out pairs
only:

* ``r``: Pearson's correlation over all pixels of the image;
* ``ssim``: SSIM (:func:`nidar_mi.eval.metrics.ssim`, whole image) after the per-image
  least-squares gain and offset that best maps the prediction onto the NIR photo (so neither
  exposure nor an offset is scored; the result is not clipped).

Tables give the unweighted mean over the held-out images, and per category.

Methods (:func:`standard_photo_methods`): Rec. 709 luminance of the linear RGB; the 4-parameter
linear RGB -> NIR map (:class:`~nidar_mi.eval.baselines.LinearNIR`) fitted on the training
photos; and any pseudo-NIR network (e.g. the STN of a weights folder,
:func:`nidar_mi.nidar.infer.pseudo_nir_linear`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import NidarError

__all__ = ["PHOTO_METRICS", "image_scores", "photo_table", "standard_photo_methods"]

#: (key, header, decimals) of the photo table's metric columns.
PHOTO_METRICS = (("r", "Pearson r↑", 3), ("ssim", "SSIM (gain/offset)↑", 3))


def image_scores(pred: Any, nir_linear: Any) -> dict[str, float]:
    """Pearson r and SSIM after the least-squares gain/offset (module docstring).

    Args:
        pred: (H, W) prediction (any scale).
        nir_linear: (H, W) linear NIR photo in [0, 1].

    Raises:
        NidarError: different shapes or non-finite values.
    """
    from .metrics import ssim

    p = np.asarray(pred, dtype=np.float64)
    t = np.asarray(nir_linear, dtype=np.float64)
    if p.shape != t.shape or p.ndim != 2:
        raise NidarError(f"prediction {p.shape} and NIR photo {t.shape} differ")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(t))):
        raise NidarError("prediction or NIR photo has non-finite values")
    pc, tc = p - p.mean(), t - t.mean()
    var_p, var_t = float(np.mean(pc * pc)), float(np.mean(tc * tc))
    cov = float(np.mean(pc * tc))
    r = cov / np.sqrt(var_p * var_t) if var_p > 0 and var_t > 0 else float("nan")
    gain = cov / var_p if var_p > 0 else 0.0
    fitted = gain * pc + t.mean()
    return {"r": float(r), "ssim": ssim(fitted, t)}


def photo_table(
    pairs: Sequence[Any],
    names: Sequence[str],
    methods: Mapping[str, tuple[str, Callable[[np.ndarray], np.ndarray]]],
    *,
    progress: bool = True,
) -> dict[str, Any]:
    """Score every method on the named pairs.

    Args:
        pairs: :class:`~nidar_mi.datasets.rgbnir.PhotoPair` list (at least the named ones).
        names: the held-out pair names to score.
        methods: key -> ``(label, fn)``, ``fn(rgb uint8 (H, W, 3)) -> (H, W)``.
        progress: show a progress bar.

    Returns:
        ``{"images": names, "rows": one per image and method, "mean": one per method,
        "per_category": {method: {category: {"r", "ssim"}}}}``.
    """
    from ..datasets.rgbnir import load_pair
    from ..io.images import srgb_to_linear
    from ..progress import progress_bar

    by_name = {p.name: p for p in pairs}
    missing = [n for n in names if n not in by_name]
    if missing:
        raise NidarError(f"photo pair(s) not found: {', '.join(missing[:5])}")
    rows = []
    for name in progress_bar(names, show=progress, desc="photos", unit="pair"):
        rgb, nir = load_pair(by_name[name])
        target = srgb_to_linear(nir.astype(np.float64) / 255.0)
        for key, (label, fn) in methods.items():
            scores = image_scores(fn(rgb), target)
            rows.append(
                {"image": name, "category": by_name[name].category, "method": key, "label": label}
                | scores
            )
    mean, per_cat = [], {}
    for key, (label, _) in methods.items():
        r = [row for row in rows if row["method"] == key]
        mean.append(
            {"method": key, "label": label, "images": len(r)}
            | {m: float(np.nanmean([x[m] for x in r])) for m, *_ in PHOTO_METRICS}
        )
        cats = sorted({x["category"] for x in r})
        per_cat[key] = {
            c: {
                m: float(np.nanmean([x[m] for x in r if x["category"] == c]))
                for m, *_ in PHOTO_METRICS
            }
            for c in cats
        }
    return {"images": list(names), "rows": rows, "mean": mean, "per_category": per_cat}


def standard_photo_methods(linear_nir=None, model=None) -> dict[str, tuple[str, Callable]]:
    """Luminance, the linear map (if given) and a model's pseudo-NIR (if given)."""
    from ..io.images import REC709_LUMA, srgb_to_linear

    luma = np.asarray(REC709_LUMA, dtype=np.float32)
    methods = {
        "luminance": (
            "Rec. 709 luminance",
            lambda rgb: srgb_to_linear(rgb.astype(np.float32) / 255.0) @ luma,
        )
    }
    if linear_nir is not None:
        methods["linear"] = ("linear RGB→NIR map (4 parameters)", linear_nir)
    if model is not None and model.stn is not None:
        from ..nidar.infer import pseudo_nir_linear

        methods["stn"] = (
            f"pseudo-NIR, STN of {model.weights_dir.name}",
            lambda rgb: pseudo_nir_linear(model.stn, rgb, scale=model.scale),
        )
    return methods
