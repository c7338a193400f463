"""Range-image previews: a scan's (ring, column) image as a PNG a person can read.

The range image itself (``range_image.exr``) keeps the sensor's order: row = ring (ring 0 the
highest beam), column = firing index. A preview reorders the columns so that it reads like a
camera looking forward: azimuth (counter-clockwise from the sensor's +x axis, wrapped to
(-180°, 180°]) *decreases* from left to right, so the vehicle's left is on the left, and on a
360° scan straight ahead (0°) is in the middle with the rear at both edges. Below the image an
azimuth axis and a colour bar with the quantity and its unit; pixels without a return are black.
By default the colours span the 1st to 99th percentile of the values: the colour bar then says
so, with the data's full range, and its ends point out (arrows) where values lie beyond them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import NidarError
from .atomic import atomic_path

__all__ = ["ColourRange", "colour_range", "preview_columns", "write_range_preview"]


def preview_columns(azimuth_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The column order of a preview.

    Args:
        azimuth_deg: (C,) azimuth of each column of the range image, degrees, counter-clockwise
            from the sensor's +x axis (any range; wrapped here).

    Returns:
        ``(order, azimuth)``: (C,) indices such that ``image[:, order]`` is the preview, and the
        (C,) wrapped azimuths of the preview's columns, in (-180, 180], decreasing.
    """
    az = np.asarray(azimuth_deg, dtype=np.float64)
    wrapped = 180.0 - np.mod(180.0 - az, 360.0)  # (-180, 180]
    order = np.argsort(-wrapped, kind="stable")
    return order, wrapped[order]


@dataclass(frozen=True)
class ColourRange:
    """The values a preview's colours span, and what lies beyond them.

    Attributes:
        lo, hi: the values at the colour bar's two ends (``hi > lo``).
        extend: matplotlib's colour bar ``extend``: ``"neither"``, ``"min"``, ``"max"`` or
            ``"both"`` (values below ``lo`` / above ``hi`` shown in the end colour).
        note: what the colour bar's caption adds about the clipping ("" when none).
    """

    lo: float
    hi: float
    extend: str
    note: str


def colour_range(
    values: np.ndarray, vmin: float | None = None, vmax: float | None = None
) -> ColourRange:
    """The colour range of a preview of ``values``: ``vmin``/``vmax``, or by default the 1st and
    99th percentile of the finite ``values`` (N,), with a note naming the clip and the full
    range of the data when values lie beyond it (e.g. "colours clipped to the 1st-99th
    percentile, 1.2-29; data 0.8-69.9")."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    v = v[np.isfinite(v)]
    if v.size == 0:
        lo, hi = (0.0, 1.0) if vmin is None or vmax is None else (float(vmin), float(vmax))
        return ColourRange(lo, hi if hi > lo else lo + 1.0, "neither", "")
    lo = float(np.percentile(v, 1)) if vmin is None else float(vmin)
    hi = float(np.percentile(v, 99)) if vmax is None else float(vmax)
    hi = hi if hi > lo else lo + 1.0
    below, above = bool(v.min() < lo), bool(v.max() > hi)
    extend = {(False, False): "neither", (True, False): "min", (False, True): "max"}.get(
        (below, above), "both"
    )
    auto = [
        p
        for p, default, out in (("1st", vmin, below), ("99th", vmax, above))
        if default is None and out
    ]
    note = ""
    if below or above:
        which = "-".join(auto) + (" percentile" if auto else "")
        clip = f"{lo:.3g}-{hi:.3g}"
        note = f"colours clipped to the {which}, {clip}" if auto else f"colours clipped to {clip}"
        note += f"; data {v.min():.3g}-{v.max():.3g}"
    return ColourRange(lo, hi, extend, note)


def _tick_label(a: float) -> str:
    names = {0: "forward", 90: "left", -90: "right", 180: "rear", -180: "rear"}
    word = names.get(int(round(a)))
    return f"{a:+.0f}°" + (f"\n{word}" if word else "")


def write_range_preview(
    path: str | os.PathLike,
    image: np.ndarray,
    valid: np.ndarray,
    azimuth_deg: np.ndarray,
    *,
    label: str,
    cmap: str = "turbo",
    vmin: float | None = None,
    vmax: float | None = None,
) -> None:
    """Write a range-image preview with an azimuth axis and a colour bar.

    Args:
        path: output PNG.
        image: (R, C) values (e.g. range in m), rows = rings from the highest beam down.
        valid: (R, C) bool, a return; other pixels are black.
        azimuth_deg: (C,) azimuth of each column, degrees (see :func:`preview_columns`).
        label: the colour bar's caption, quantity and unit, e.g. ``"range (m)"``.
        cmap: matplotlib colour map.
        vmin, vmax: colour range; default: 1st and 99th percentile of the valid values
            (:func:`colour_range`; the colour bar's caption states the clip).

    Raises:
        NidarError: shapes that do not agree, an unknown colour map, or a write failure.
    """
    import matplotlib
    from matplotlib.figure import Figure

    image = np.asarray(image, dtype=np.float64)
    valid = np.asarray(valid, dtype=bool) & np.isfinite(image)
    az = np.asarray(azimuth_deg, dtype=np.float64)
    if image.ndim != 2 or valid.shape != image.shape or az.shape != (image.shape[1],):
        raise NidarError(
            f"range preview needs (R,C) image and mask and (C,) azimuths, got "
            f"{image.shape}, {valid.shape}, {az.shape}"
        )
    try:
        colormap = matplotlib.colormaps[cmap].with_extremes(bad="black")
    except KeyError:
        raise NidarError(f"unknown colour map {cmap!r}") from None
    order, az_sorted = preview_columns(az)
    shown = np.ma.masked_array(image[:, order], mask=~valid[:, order])
    colours = colour_range(image[valid], vmin, vmax)
    lo, hi = colours.lo, colours.hi

    rings, cols = image.shape
    dpi = 100
    w_px = max(cols, 640)
    h_px = max(rings, min(w_px // 6, rings * 8))
    margin_top, axis_px, bar_px, bottom_px = 8, 44, 14, 38
    total_h = margin_top + h_px + axis_px + bar_px + bottom_px
    fig = Figure(figsize=((w_px + 80) / dpi, total_h / dpi), dpi=dpi)
    left = 40 / (w_px + 80)
    width = w_px / (w_px + 80)
    ax = fig.add_axes((left, 1 - (margin_top + h_px) / total_h, width, h_px / total_h))
    # extent in azimuth: the left edge is the largest azimuth
    step = (az_sorted[0] - az_sorted[-1]) / max(cols - 1, 1) if cols > 1 else 1.0
    extent = (az_sorted[0] + step / 2, az_sorted[-1] - step / 2, rings, 0)
    im = ax.imshow(
        shown,
        cmap=colormap,
        vmin=lo,
        vmax=hi,
        aspect="auto",
        interpolation="nearest",
        extent=extent,
    )
    ticks = [t for t in range(-180, 181, 45) if min(extent[:2]) <= t <= max(extent[:2])]
    ax.set_xticks(ticks, [_tick_label(t) for t in ticks], fontsize=7)
    ax.set_yticks([])
    ax.set_ylabel("rings", fontsize=7)
    ax.set_xlim(extent[0], extent[1])
    cax = fig.add_axes(
        (left, bottom_px / total_h, width, bar_px / total_h),
    )
    bar = fig.colorbar(im, cax=cax, orientation="horizontal", extend=colours.extend)
    bar.ax.tick_params(labelsize=7)
    note = f"; {colours.note}" if colours.note else ""
    bar.set_label(f"{label}  (black: no return{note})", fontsize=8)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
