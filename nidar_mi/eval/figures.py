"""Evaluation figures (matplotlib, Agg backend): intensity maps, error maps, GT-vs-predicted scatter.

* :func:`maps_figure`: one frame; GT and every method's intensity at the camera-visible returns,
  drawn at their pixel positions over the dimmed camera image (top row), and the absolute error
  ``|pred - GT|`` (bottom row).
* :func:`scatter_figure`: per method, a 2-D histogram of predicted vs GT intensity pooled over
  frames, with the identity line.

Intensities are on the metric [0, 1] scale (``clip(I / intensity_scale, 0, 1)``). PNGs are
written atomically.
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["maps_figure", "scatter_figure"]


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: str | os.PathLike, dpi: int) -> None:
    from PIL import Image

    from ..io.atomic import atomic_path

    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png", bbox_inches="tight")
    # a 256-colour palette keeps the files small (the colormaps have 256 entries anyway)
    img = Image.open(io.BytesIO(buf.getvalue())).convert("RGB").quantize(256)
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG", optimize=True)


def maps_figure(
    rgb: np.ndarray,
    uv: np.ndarray,
    gt: np.ndarray,
    preds: Mapping[str, np.ndarray],
    path: str | os.PathLike,
    *,
    labels: Mapping[str, str] | None = None,
    title: str = "",
    dpi: int = 80,
) -> None:
    """GT vs predicted intensity at the projected points, and the absolute error.

    Args:
        rgb: (H, W, 3) uint8 camera image (drawn dimmed, in grey, as context).
        uv: (N, 2) pixel coordinates of the points.
        gt: (N,) GT intensity in [0, 1].
        preds: method -> (N,) predicted intensity in [0, 1].
        path: output PNG.
        labels: method -> panel title.
        title: figure title.
        dpi: resolution.
    """
    plt = _plt()
    labels = dict(labels or {})
    H, W = rgb.shape[:2]
    grey = rgb.astype(np.float64).mean(axis=2) / 255.0 * 0.35
    cols = 1 + len(preds)
    fig, axes = plt.subplots(
        2, cols, figsize=(2.6 * cols, 2.6 * 2 * H / W + 0.9), squeeze=False, layout="constrained"
    )
    size = max(0.5, 2.0 * W / 640.0)
    panels = [("GT (scaled compensated intensity)", gt, None)] + [
        (labels.get(k, k), v, np.abs(v - gt)) for k, v in preds.items()
    ]
    im_i = im_e = None
    for j, (name, val, err) in enumerate(panels):
        for i in range(2):
            ax = axes[i, j]
            ax.imshow(grey, cmap="gray", vmin=0, vmax=1, extent=(-0.5, W - 0.5, H - 0.5, -0.5))
            ax.set_xticks([])
            ax.set_yticks([])
        im_i = axes[0, j].scatter(
            uv[:, 0], uv[:, 1], c=val, s=size, cmap="viridis", vmin=0, vmax=1, linewidths=0
        )
        axes[0, j].set_title(name, fontsize=8)
        if err is None:
            axes[1, j].set_title("|error| of each method below", fontsize=7)
            axes[1, j].axis("off")
        else:
            im_e = axes[1, j].scatter(
                uv[:, 0], uv[:, 1], c=err, s=size, cmap="magma", vmin=0, vmax=0.5, linewidths=0
            )
            axes[1, j].set_title(f"|pred - GT|, mean {err.mean():.3f}", fontsize=7)
    axes[0, 0].set_ylabel("intensity [0, 1]", fontsize=8)
    axes[1, 1].set_ylabel("absolute error", fontsize=8)
    if im_i is not None:
        fig.colorbar(im_i, ax=axes[0, :].tolist(), shrink=0.8, label="intensity (scaled, 1)")
    if im_e is not None:
        fig.colorbar(im_e, ax=axes[1, :].tolist(), shrink=0.8, label="|pred - GT| (scaled, 1)")
    if title:
        fig.suptitle(title, fontsize=9)
    _save(fig, path, dpi)
    plt.close(fig)


def scatter_figure(
    gt: np.ndarray,
    preds: Mapping[str, np.ndarray],
    path: str | os.PathLike,
    *,
    labels: Mapping[str, str] | None = None,
    title: str = "",
    bins: int = 50,
    dpi: int = 80,
    order: Sequence[str] | None = None,
) -> None:
    """Per-method 2-D histogram (log counts) of predicted vs GT intensity, identity line.

    Args:
        gt: (N,) pooled GT intensity in [0, 1].
        preds: method -> (N,) predictions in [0, 1] at the same points.
        path: output PNG.
        labels: method -> panel title.
        title: figure title.
        bins: histogram bins per axis.
        dpi: resolution.
        order: panel order (default: ``preds``' order).
    """
    from matplotlib.colors import LogNorm

    plt = _plt()
    labels = dict(labels or {})
    keys = list(order or preds)
    n = len(keys)
    ncols = min(4, n)
    nrows = (n + ncols - 1) // ncols
    fig, axes = plt.subplots(
        nrows, ncols, figsize=(2.8 * ncols, 2.7 * nrows), squeeze=False, layout="constrained"
    )
    edges = np.linspace(0.0, 1.0, bins + 1)
    for ax, k in zip(axes.flat, keys):
        h, _, _ = np.histogram2d(gt, preds[k], bins=(edges, edges))
        ax.imshow(
            np.where(h > 0, h, np.nan).T,
            origin="lower",
            extent=(0, 1, 0, 1),
            cmap="viridis",
            norm=LogNorm(vmin=1, vmax=max(h.max(), 2)),
            aspect="equal",
        )
        ax.plot([0, 1], [0, 1], color="red", lw=0.8)
        ax.set_title(labels.get(k, k), fontsize=8)
        ax.set_xlabel("GT intensity (scaled, 1)", fontsize=7)
        ax.set_ylabel("predicted (scaled, 1)", fontsize=7)
        ax.tick_params(labelsize=6)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    if title:
        fig.suptitle(title, fontsize=9)
    _save(fig, path, dpi)
    plt.close(fig)
