"""Images: sRGB transfer functions, Rec. 709 luma, 8-bit PNG, float32 OpenEXR, false-colour PNG.

:func:`read_rgb8` reads a camera image of any PNG colour type as 8-bit sRGB.
Renders are linear (radiance, intensity, depth); :func:`write_srgb_png` encodes a linear RGB
render for display with the sRGB OETF of IEC 61966-2-1, and :func:`write_colormap_png` maps
a scalar image (range, intensity) through a matplotlib colour map. EXR keeps float32 values
exactly, one named channel per image plane.

This module owns the package's sRGB transfer curves (:func:`linear_to_srgb`,
:func:`srgb_to_linear`: colour-science's, imported on first use since colour takes about a
second to import) and its Rec. 709 luma weights (:data:`REC709_LUMA`).
"""

from __future__ import annotations

import functools
import os
import re
import warnings
from contextlib import contextmanager

import numpy as np

from ..errors import NidarError
from .atomic import atomic_path, reading

__all__ = [
    "REC709_LUMA",
    "linear_to_srgb",
    "srgb_to_linear",
    "write_png",
    "read_png",
    "read_rgb8",
    "MAX_IMAGE_PIXELS",
    "open_image",
    "write_exr",
    "read_exr",
    "write_colormap_png",
    "write_srgb_png",
]

REC709_LUMA = (0.2126, 0.7152, 0.0722)
"""Rec. 709 / sRGB luminance weights of linear R, G, B (the Y row of the sRGB-to-XYZ matrix,
rounded as ITU-R BT.709 states them)."""

_EXR_MAGIC = b"\x76\x2f\x31\x01"

#: The most pixels an image read may have: Pillow's own bound (about 89 million pixels, e.g.
#: 10000 x 8900; a 6000 x 4000 photo has 24 million). A larger image is refused from its header,
#: before any pixel is decoded (a decompression bomb would take the machine's memory).
MAX_IMAGE_PIXELS = 89_478_485


@contextmanager
def open_image(path: str | os.PathLike):
    """Pillow's ``Image.open`` of ``path``, refusing an image of more than
    :data:`MAX_IMAGE_PIXELS` from its header.

    Yields:
        The open ``PIL.Image.Image`` (closed after the block).

    Raises:
        NidarError: an image larger than the bound (one line naming the file and its size).
        OSError, PIL.UnidentifiedImageError: what Pillow raises on a file it cannot read.
    """
    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("error", Image.DecompressionBombWarning)
        try:
            im = Image.open(path)
        except (Image.DecompressionBombError, Image.DecompressionBombWarning) as e:
            found = re.search(r"\((\d+) pixels\)", str(e))
            size = f"{int(found.group(1)):,} pixels" if found else "more pixels than that"
            raise NidarError(
                f"{path}: an image of {size}, more than the {MAX_IMAGE_PIXELS:,} an image may "
                "have (a decompression bomb?)"
            ) from None
    with im:
        w, h = im.size
        if w * h > MAX_IMAGE_PIXELS:  # Pillow's bound may have been lifted by someone else
            raise NidarError(
                f"{path}: a {w}x{h} image, more than the {MAX_IMAGE_PIXELS:,} pixels an image may "
                "have (a decompression bomb?)"
            )
        yield im


@functools.cache
def _srgb_curves():
    """colour-science's sRGB EOTF inverse and EOTF, imported on first use (about a second)."""
    from colour.models import eotf_inverse_sRGB, eotf_sRGB

    return eotf_inverse_sRGB, eotf_sRGB


def _float(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x)
    return x.astype(np.result_type(x.dtype, np.float32), copy=False)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """sRGB OETF (IEC 61966-2-1): linear values -> encoded values, both clipped to [0, 1].

    ``12.92 x`` for ``x <= 0.0031308``, else ``1.055 x^(1/2.4) - 0.055``
    (:func:`colour.models.eotf_inverse_sRGB`, evaluated in float64).

    Args:
        x: linear values, any shape (NaN stays NaN).

    Returns:
        Encoded values in [0, 1], same shape, as floats (float32 input stays float32).
    """
    x = np.clip(_float(x), 0.0, 1.0)
    encode, _ = _srgb_curves()
    return np.asarray(encode(x), dtype=x.dtype)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """Inverse sRGB OETF: encoded values in [0, 1] -> linear values in [0, 1].

    ``x / 12.92`` below the break, else ``((x + 0.055) / 1.055)^2.4``
    (:func:`colour.models.eotf_sRGB`, evaluated in float64). The break is the encoded
    value of 0.0031308, 0.040449936, so that this is the exact inverse of
    :func:`linear_to_srgb` (the standard rounds it to 0.04045; the segments meet there
    within 3e-9).

    Args:
        x: encoded values, any shape (NaN stays NaN).

    Returns:
        Linear values in [0, 1], same shape, as floats (float32 input stays float32).
    """
    x = np.clip(_float(x), 0.0, 1.0)
    _, decode = _srgb_curves()
    return np.asarray(decode(x), dtype=x.dtype)


def write_png(path: str | os.PathLike, img: np.ndarray) -> None:
    """Write an 8-bit PNG.

    Args:
        path: output file.
        img: uint8 (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA.

    Raises:
        NidarError: another dtype or shape, or a write failure.
    """
    from PIL import Image

    img = np.asarray(img)
    if img.dtype != np.uint8 or not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] in (3, 4))):
        raise NidarError(f"write_png needs uint8 (H,W) or (H,W,3|4), got {img.dtype} {img.shape}")
    with atomic_path(path) as tmp:
        Image.fromarray(np.ascontiguousarray(img)).save(tmp, format="PNG")


def read_png(path: str | os.PathLike) -> np.ndarray:
    """Read a PNG (or another format Pillow knows).

    Returns:
        uint8 (H, W) for grey, (H, W, 3) RGB or (H, W, 4) RGBA (palette and grey+alpha
        images are expanded to RGB/RGBA); 16-bit grey is returned as its integer array.

    Raises:
        NidarError: missing or unreadable file, or an image of more than
            :data:`MAX_IMAGE_PIXELS`.
    """
    with reading(path) as p, open_image(p) as im:
        if im.mode == "1":
            im = im.convert("L")
        elif im.mode not in ("L", "RGB", "RGBA") and not im.mode.startswith("I"):
            alpha = "A" in im.getbands() or "transparency" in im.info
            im = im.convert("RGBA" if alpha else "RGB")
        return np.array(im)


def read_rgb8(path: str | os.PathLike) -> np.ndarray:
    """Read a camera image as 8-bit sRGB, whatever its PNG colour type.

    8-bit RGB is returned as it is; RGBA and grey+alpha lose the alpha channel; palette and
    1-bit images are expanded; 16-bit grey is reduced to 8 bit (``round(v / 257)``; Pillow
    already reduces 16-bit RGB to its high bytes); a grey image becomes R = G = B, with a
    warning, since a colour camera was expected.

    Returns:
        (H, W, 3) uint8.

    Raises:
        NidarError: missing or unreadable file, a floating-point image, or one of more than
            :data:`MAX_IMAGE_PIXELS`.
    """
    with reading(path) as p, open_image(p) as im:
        mode = im.mode
        if mode == "F":
            raise ValueError("floating-point image; expected an 8- or 16-bit colour image")
        if mode.startswith("I"):
            a = np.asarray(im, dtype=np.float64)  # 16-bit grey (PNG's deepest)
            grey = np.round(np.clip(a, 0, 65535) / 257.0).astype(np.uint8)
        elif mode in ("1", "L", "LA"):
            grey = np.asarray(im.convert("L"))
        else:
            return np.ascontiguousarray(np.asarray(im.convert("RGB")))
    warnings.warn(
        f"{path} is a greyscale image ({mode}): NIDAR, trained on colour images, sees it as "
        "R = G = B",
        RuntimeWarning,
        stacklevel=2,
    )
    return np.repeat(grey[..., None], 3, axis=2)


def write_exr(path: str | os.PathLike, channels: dict[str, np.ndarray]) -> None:
    """Write float32 channels to a scanline OpenEXR file with ZIP compression.

    Args:
        path: output file.
        channels: channel name -> (H, W) array (cast to float32), all the same shape. An RGB
            image is ``{"R": r, "G": g, "B": b}``; an (H, W, 3|4) array under the key
            ``"RGB"`` or ``"RGBA"`` is split into those channels.

    Raises:
        NidarError: no channels, bad shapes, or a write failure.
    """
    import OpenEXR

    planes: dict[str, np.ndarray] = {}
    for name, value in channels.items():
        a = np.asarray(value)
        if name in ("RGB", "RGBA") and a.ndim == 3 and a.shape[2] == len(name):
            planes.update({c: a[..., i] for i, c in enumerate(name)})
        else:
            planes[name] = a
    shapes = {a.shape for a in planes.values()}
    if not planes or len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise NidarError(f"write_exr needs (H,W) channels of one shape, got {sorted(shapes)}")
    pixels = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in planes.items()}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp:
        try:
            OpenEXR.File(header, pixels).write(str(tmp))
        except RuntimeError as e:  # OpenEXR's failures (a full disk among them) are RuntimeErrors
            why = " ".join(str(e).replace(str(tmp), str(path)).split())
            raise NidarError(f"cannot write {path}: {why}") from None


def read_exr(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read every channel of a single-part OpenEXR file.

    Returns:
        Channel name -> (H, W) float32 (half and uint channels are converted).

    Raises:
        NidarError: missing or unreadable file.
    """
    import OpenEXR

    with reading(path) as p:
        with open(p, "rb") as stream:
            if stream.read(4) != _EXR_MAGIC:
                raise ValueError("not an OpenEXR file (no EXR signature)")
        f = OpenEXR.File(str(p), separate_channels=True)
        return {k: np.asarray(c.pixels, dtype=np.float32) for k, c in f.channels().items()}


def write_colormap_png(
    path: str | os.PathLike,
    img: np.ndarray,
    *,
    vmin: float | None = None,
    vmax: float | None = None,
    cmap: str = "turbo",
    invalid: np.ndarray | None = None,
) -> None:
    """Write a scalar image as a false-colour 8-bit RGB PNG.

    Values are mapped linearly from [vmin, vmax] to the colour map and clipped; invalid
    pixels (NaN, infinite, or ``invalid``) are black.

    Args:
        path: output file.
        img: (H, W) scalar image.
        vmin: value shown at the low end; default: 1st percentile of the valid pixels.
        vmax: value shown at the high end; default: 99th percentile of the valid pixels.
        cmap: matplotlib colour map name.
        invalid: optional (H, W) bool mask of pixels to show black.

    Raises:
        NidarError: bad shapes, unknown colour map, or a write failure.
    """
    import matplotlib

    img = np.asarray(img, dtype=np.float64)
    if img.ndim != 2:
        raise NidarError(f"write_colormap_png needs an (H,W) image, got {img.shape}")
    valid = np.isfinite(img)
    if invalid is not None:
        invalid = np.asarray(invalid, dtype=bool)
        if invalid.shape != img.shape:
            raise NidarError(f"invalid mask shape {invalid.shape} != image shape {img.shape}")
        valid &= ~invalid
    try:
        colormap = matplotlib.colormaps[cmap]
    except KeyError:
        raise NidarError(f"unknown colour map {cmap!r}") from None
    rgb = np.zeros((*img.shape, 3), dtype=np.uint8)
    if valid.any():
        lo = float(np.percentile(img[valid], 1)) if vmin is None else float(vmin)
        hi = float(np.percentile(img[valid], 99)) if vmax is None else float(vmax)
        t = np.clip((img[valid] - lo) / (hi - lo if hi > lo else 1.0), 0.0, 1.0)
        rgb[valid] = np.round(colormap(t)[:, :3] * 255).astype(np.uint8)
    write_png(path, rgb)


def write_srgb_png(path: str | os.PathLike, rgb_linear: np.ndarray) -> None:
    """Encode a linear RGB image with the sRGB OETF and write it as an 8-bit PNG.

    Args:
        path: output file.
        rgb_linear: (H, W, 3) linear RGB; values are clipped to [0, 1], NaN becomes 0.

    Raises:
        NidarError: bad shape, or a write failure.
    """
    rgb = np.asarray(rgb_linear)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise NidarError(f"write_srgb_png needs an (H,W,3) image, got {rgb.shape}")
    encoded = np.nan_to_num(linear_to_srgb(rgb.astype(np.float64)), nan=0.0)
    write_png(path, np.round(encoded * 255).astype(np.uint8))
