"""What the camera image shows around a LiDAR return: colour, context and texture at its pixel.

:func:`image_context` reads an 8-bit sRGB image at given pixel positions (the returns a camera
sees, :func:`nidar_mi.geometry.locate_in_cameras`; an occluded return never reaches it) and
gives, per position, the features of :data:`IMAGE_FEATURES`:

* ``r_lin``, ``g_lin``, ``b_lin``: the pixel's linear RGB in [0, 1] (sRGB decoded,
  :func:`nidar_mi.io.images.srgb_to_linear`);
* ``lum_log``: ``log((Y + ε) / (Ȳ + ε))``, the Rec. 709 luminance ``Y`` of the pixel against
  the image's mean ``Ȳ`` (the exposure divided out), ``ε`` = :data:`EPS`;
* ``chroma_r``, ``chroma_g``: chromaticity ``r / (r + g + b + ε)``, ``g / (...)`` of the linear
  colour (shading-free);
* ``hue``, ``sat``, ``val``: HSV of the encoded sRGB pixel (hue in [0, 1), 0 for a grey);
* ``{r,g,b}_mean{w}``: the mean linear colour over the ``w × w`` window centred on the pixel,
  for ``w`` in :data:`WINDOWS` (the part of the window inside the image);
* ``lum_sd{w}``: the standard deviation of ``Y`` over the window, ``w`` in :data:`SD_WINDOWS`;
* ``sobel``, ``laplacian``: the 3 × 3 Sobel gradient magnitude and the 4-neighbour Laplacian of
  ``Y`` at the pixel (edge pixels repeated beyond the image);
* ``contrast``: ``log((Ȳ_5 + ε) / (Ȳ_61 + ε))``, the 5-pixel window's luminance against the
  61-pixel one (local contrast);
* the same with the exposure divided out (:data:`RELATIVE_FEATURES`): ``{r,g,b}_rel``,
  ``{r,g,b}_rel{w}``, ``lum_rel_sd{w}``, ``sobel_rel`` and ``laplacian_rel`` are the pixel's
  linear colour, the window means, the spreads and the texture over the image's mean
  luminance ``Ȳ + ε`` (a camera's gain or exposure time scales them all alike; chromaticity,
  hue, saturation, ``lum_log`` and ``contrast`` do not depend on it already).

The windows are box sums of summed-area tables (one per linear channel and ``Y²``, float64) over the image rows the positions reach, so a window costs four look-ups per position
whatever its size: the features of ~20 000 returns in a 1242 × 375 image take a few
milliseconds, with no full-image filter. A position is taken at its nearest pixel.
"""

from __future__ import annotations

import functools

import numpy as np

from ..errors import NidarError

__all__ = ["EPS", "IMAGE_FEATURES", "RELATIVE_FEATURES", "SD_WINDOWS", "WINDOWS", "image_context"]

#: Side lengths of the windows of the mean colour, pixels (odd).
WINDOWS = (5, 15, 31, 61)
#: Side lengths of the windows of the luminance spread, pixels (odd).
SD_WINDOWS = (5, 15)
#: Floor of the luminance and colour sums in the logarithms and ratios.
EPS = 1e-3
#: The features of :func:`image_context`, in order.
IMAGE_FEATURES = (
    "r_lin",
    "g_lin",
    "b_lin",
    "lum_log",
    "chroma_r",
    "chroma_g",
    "hue",
    "sat",
    "val",
    *(f"{c}_mean{w}" for w in WINDOWS for c in "rgb"),
    *(f"lum_sd{w}" for w in SD_WINDOWS),
    "sobel",
    "laplacian",
    "contrast",
)
#: The exposure-free counterparts of the features that scale with the exposure (module
#: docstring), in order; :func:`image_context` gives them after :data:`IMAGE_FEATURES`.
RELATIVE_FEATURES = (
    "r_rel",
    "g_rel",
    "b_rel",
    *(f"{c}_rel{w}" for w in WINDOWS for c in "rgb"),
    *(f"lum_rel_sd{w}" for w in SD_WINDOWS),
    "sobel_rel",
    "laplacian_rel",
)
#: Each relative feature's absolute one.
_ABSOLUTE = dict(
    zip(
        RELATIVE_FEATURES,
        (
            "r_lin",
            "g_lin",
            "b_lin",
            *(f"{c}_mean{w}" for w in WINDOWS for c in "rgb"),
            *(f"lum_sd{w}" for w in SD_WINDOWS),
            "sobel",
            "laplacian",
        ),
        strict=True,
    )
)
_LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709, as nidar_mi.io.images.REC709_LUMA


@functools.lru_cache(maxsize=1)
def _decode_table() -> np.ndarray:
    """(256,) float64 linear value of each 8-bit sRGB code."""
    from ..io.images import srgb_to_linear

    return srgb_to_linear(np.arange(256, dtype=np.float64) / 255.0)


def _hsv(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hue in [0, 1), saturation and value of (M, 3) colours in [0, 1]."""
    mx, mn = rgb.max(axis=1), rgb.min(axis=1)
    d = mx - mn
    safe = np.where(d > 0, d, 1.0)
    r, g, b = rgb.T
    h = np.where(
        mx == r, (g - b) / safe % 6.0, np.where(mx == g, (b - r) / safe + 2.0, (r - g) / safe + 4.0)
    )
    h = np.where(d > 0, h / 6.0, 0.0)
    s = np.where(mx > 0, d / np.where(mx > 0, mx, 1.0), 0.0)
    return h, s, mx


class _Tables:
    """Summed-area tables of the linear R, G, B and ``Y²`` of an (h, w, 3) linear image (a band
    of rows of the camera image, full width), with a zero row and column in front; ``Y`` is
    the Rec. 709 combination of the first three."""

    def __init__(self, band: np.ndarray):
        h, w, _ = band.shape
        chans = np.empty((4, h, w))
        chans[:3] = band.transpose(2, 0, 1)
        y = band @ _LUMA
        np.multiply(y, y, out=chans[3])
        self.y = y  # (h, w) luminance
        self.sat = np.zeros((4, h + 1, w + 1))
        inner = self.sat[:, 1:, 1:]
        np.cumsum(chans, axis=1, out=inner)
        np.cumsum(inner, axis=2, out=inner)
        self.flat = self.sat.reshape(4, -1)
        self.h, self.w = h, w

    def mean(self, u: np.ndarray, v: np.ndarray, side: int) -> np.ndarray:
        """(5, M) mean R, G, B, ``Y`` and ``Y²`` over the ``side × side`` windows centred on
        pixels ``(u, v)`` (their part inside the image)."""
        r = side // 2
        v0 = np.clip(v - r, 0, self.h)
        v1 = np.clip(v + r + 1, 0, self.h)
        u0 = np.clip(u - r, 0, self.w)
        u1 = np.clip(u + r + 1, 0, self.w)
        stride = self.w + 1
        f = self.flat
        total = (
            np.take(f, v1 * stride + u1, axis=1)
            - np.take(f, v0 * stride + u1, axis=1)
            - np.take(f, v1 * stride + u0, axis=1)
            + np.take(f, v0 * stride + u0, axis=1)
        )
        total /= (v1 - v0) * (u1 - u0)
        return np.concatenate([total[:3], (_LUMA @ total[:3])[None], total[3:]])


def _texture(y: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sobel gradient magnitude and 4-neighbour Laplacian of the (h, w) luminance ``y`` at
    pixels ``(u, v)``, edge pixels repeated beyond the image."""
    h, w = y.shape
    flat = y.reshape(-1)
    rows = {dv: np.clip(v + dv, 0, h - 1) * w for dv in (-1, 0, 1)}
    cols = {du: np.clip(u + du, 0, w - 1) for du in (-1, 0, 1)}
    n = {(du, dv): np.take(flat, rows[dv] + cols[du]) for du in (-1, 0, 1) for dv in (-1, 0, 1)}
    gx = (n[1, -1] + 2 * n[1, 0] + n[1, 1]) - (n[-1, -1] + 2 * n[-1, 0] + n[-1, 1])
    gy = (n[-1, 1] + 2 * n[0, 1] + n[1, 1]) - (n[-1, -1] + 2 * n[0, -1] + n[1, -1])
    lap = n[1, 0] + n[-1, 0] + n[0, 1] + n[0, -1] - 4 * n[0, 0]
    return np.hypot(gx, gy), lap


def image_context(rgb, uv) -> dict[str, np.ndarray]:
    """The image features of :data:`IMAGE_FEATURES` and :data:`RELATIVE_FEATURES` at pixel
    positions (module docstring).

    Args:
        rgb: (H, W, 3) uint8 sRGB image.
        uv: (M, 2) pixel coordinates ``(column, row)`` inside the image, ``[-0.5, W - 0.5) ×
            [-0.5, H - 0.5)`` (pixel centres at integers; each taken at its nearest pixel).

    Returns:
        name -> (M,) float64.

    Raises:
        NidarError: not an 8-bit colour image, or positions not (M, 2), not finite or outside
            the image.
    """
    img = np.asarray(rgb)
    if img.ndim != 3 or img.shape[2] < 3 or img.dtype != np.uint8:
        raise NidarError(
            f"image_context: expected an (H, W, 3) uint8 image, got {img.shape} {img.dtype}"
        )
    img = img[..., :3]
    pos = np.asarray(uv, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 2 or not np.all(np.isfinite(pos)):
        raise NidarError(f"image_context: expected finite (M, 2) pixel positions, got {pos.shape}")
    h, w = img.shape[:2]
    inside = (
        (pos[:, 0] >= -0.5) & (pos[:, 0] < w - 0.5) & (pos[:, 1] >= -0.5) & (pos[:, 1] < h - 0.5)
    )
    if not inside.all():
        raise NidarError("image_context: pixel positions outside the image")
    u = np.clip(np.rint(pos[:, 0]).astype(np.int64), 0, w - 1)
    v = np.clip(np.rint(pos[:, 1]).astype(np.int64), 0, h - 1)
    names = (*IMAGE_FEATURES, *RELATIVE_FEATURES)
    if not len(u):
        return {k: np.zeros(0) for k in names}
    reach = max(max(WINDOWS), max(SD_WINDOWS)) // 2 + 1
    top, bottom = max(int(v.min()) - reach, 0), min(int(v.max()) + reach + 1, h)
    table = _decode_table()
    lin = table[img[top:bottom]]  # the rows the windows reach
    v = v - top
    step = max(1, int(np.sqrt(h * w / 65536)))
    mean_y = float((table[img[::step, ::step]] @ _LUMA).mean())
    out = _pixel_features(img[top:bottom], lin, u, v, mean_y)
    tables = _Tables(lin)
    windows = {side: tables.mean(u, v, side) for side in sorted({*WINDOWS, *SD_WINDOWS})}
    for side in WINDOWS:
        for i, c in enumerate("rgb"):
            out[f"{c}_mean{side}"] = windows[side][i]
    for side in SD_WINDOWS:
        m = windows[side]
        out[f"lum_sd{side}"] = np.sqrt(np.maximum(m[4] - m[3] ** 2, 0.0))
    out["sobel"], out["laplacian"] = _texture(tables.y, u, v)
    out["contrast"] = np.log((windows[5][3] + EPS) / (windows[61][3] + EPS))
    for rel, absolute in _ABSOLUTE.items():
        out[rel] = out[absolute] / (mean_y + EPS)
    return {k: out[k] for k in names}


def _pixel_features(img, lin, u, v, mean_y: float) -> dict[str, np.ndarray]:
    """The features of the pixel itself: linear colour, log luminance, chromaticity, HSV."""
    c = lin[v, u]
    y = c @ _LUMA
    total = c.sum(axis=1) + EPS
    hue, sat, val = _hsv(img[v, u].astype(np.float64) / 255.0)
    return {
        "r_lin": c[:, 0],
        "g_lin": c[:, 1],
        "b_lin": c[:, 2],
        "lum_log": np.log((y + EPS) / (mean_y + EPS)),
        "chroma_r": c[:, 0] / total,
        "chroma_g": c[:, 1] / total,
        "hue": hue,
        "sat": sat,
        "val": val,
    }
