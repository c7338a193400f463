"""Training crops of real RGB/NIR photo pairs (and, optionally, rendered pairs) for the STN.

Each item is one square crop drawn with its own generator, seeded by ``(seed, epoch, index)``:

* a pair (a rendered frame with probability ``render_fraction``, else a photo pair, uniformly);
* a zoom ``z ~ U(zoom_min, 1)``: a window of ``crop / z`` pixels (at most the image) at a
  uniform position, resized bilinearly to ``crop x crop`` in both images alike;
* a horizontal flip with probability 1/2;
* on the colour image only, in training: exposure ``x 2^U(-1, 1)`` and white balance
  ``x exp U(-0.2, 0.2)`` per channel in linear light (clipped to [0, 1] as a camera would),
  re-encoded to 8-bit sRGB and, with probability 1/2, JPEG-compressed at quality
  ``U{30 .. 95}``.

The colour crop becomes the network input by :func:`~nidar_mi.nidar.preprocess.prepare_rgb`
(linear, exposure-normalised per crop: cs-stereo's normalisation, which removes the exposure of
photos and renders alike); the NIR crop stays linear at its own scale (the loss,
:func:`~nidar_mi.nidar.losses.photo_stn_loss`, is invariant to a gain and offset of the target).
Validation items (``train=False``) are drawn the same way with the epoch fixed at 0 and no
photometric augmentation, so every validation pass sees the same crops.
"""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np
import torch
from torch.utils.data import Dataset

from ..errors import NidarError
from ..io.images import linear_to_srgb, srgb_to_linear
from .preprocess import prepare_rgb

__all__ = ["PhotoCropDataset", "augment_colour", "render_pair"]

#: Exposure change of the colour augmentation: ``2^U(-EXPOSURE_STOPS, EXPOSURE_STOPS)``.
EXPOSURE_STOPS = 1.0
#: White-balance change per channel: ``exp U(-WHITE_BALANCE, WHITE_BALANCE)``.
WHITE_BALANCE = 0.2
#: JPEG qualities drawn from (inclusive), with probability :data:`JPEG_PROBABILITY`.
JPEG_QUALITY = (30, 95)
JPEG_PROBABILITY = 0.5


def augment_colour(rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Photometric augmentation of an ``(H, W, 3)`` uint8 sRGB crop (module docstring)."""
    from PIL import Image

    lin = srgb_to_linear(rgb.astype(np.float32) / np.float32(255.0))
    gain = np.float32(2.0) ** np.float32(rng.uniform(-EXPOSURE_STOPS, EXPOSURE_STOPS))
    balance = np.exp(rng.uniform(-WHITE_BALANCE, WHITE_BALANCE, 3)).astype(np.float32)
    lin = np.clip(lin * gain * balance, 0.0, 1.0)
    out = np.clip(np.rint(linear_to_srgb(lin) * 255.0), 0, 255).astype(np.uint8)
    if rng.random() < JPEG_PROBABILITY:
        buf = io.BytesIO()
        quality = int(rng.integers(JPEG_QUALITY[0], JPEG_QUALITY[1] + 1))
        Image.fromarray(out).save(buf, format="JPEG", quality=quality)
        buf.seek(0)
        with Image.open(buf) as im:
            out = np.asarray(im.convert("RGB"), dtype=np.uint8)
    return out


def render_pair(frame) -> tuple[np.ndarray, np.ndarray]:
    """``(rgb uint8 (H, W, 3), nir float32 (H, W) linear)`` of a rendered training frame."""
    from ..training_frames import load_frame

    arrays = load_frame(frame, ("rgb", "nir"))
    rgb = np.asarray(arrays["rgb"])
    if rgb.dtype != np.uint8:
        rgb = np.clip(np.rint(linear_to_srgb(np.clip(rgb, 0, 1)) * 255.0), 0, 255).astype(np.uint8)
    return rgb, np.asarray(arrays["nir"], dtype=np.float32)


def _crop(image: np.ndarray, box: tuple[int, int, int], size: int, flip: bool) -> np.ndarray:
    """Window ``(y, x, side)`` of an image, resized bilinearly to ``size x size``."""
    from PIL import Image

    y, x, side = box
    if image.dtype == np.uint8:
        im = Image.fromarray(image)
    else:
        im = Image.fromarray(np.ascontiguousarray(image, dtype=np.float32), mode="F")
    out = np.asarray(im.resize((size, size), Image.BILINEAR, box=(x, y, x + side, y + side)))
    return out[:, ::-1] if flip else out


class PhotoCropDataset(Dataset):
    """Crops of RGB/NIR pairs (module docstring).

    Args:
        photos: ``(rgb uint8 (H, W, 3), nir uint8 (H, W))`` pairs (sRGB-encoded NIR).
        crop_size: side of the crops (px).
        length: items per epoch.
        seed: seed of the draws.
        train: photometric augmentation and per-epoch draws if True.
        zoom_min: smallest zoom (module docstring), in (0, 1].
        renders: ``(rgb uint8, nir float linear)`` rendered pairs, or none.
        render_fraction: probability that a crop comes from ``renders``.

    Items: ``{"rgb": (3, c, c), "nir": (1, c, c)}`` float32; ``rgb`` exposure-normalised linear,
    ``nir`` linear.
    """

    def __init__(
        self,
        photos: Sequence[tuple[np.ndarray, np.ndarray]],
        crop_size: int,
        length: int,
        seed: int = 0,
        train: bool = True,
        zoom_min: float = 0.5,
        renders: Sequence[tuple[np.ndarray, np.ndarray]] = (),
        render_fraction: float = 0.0,
    ) -> None:
        if not photos:
            raise NidarError("no RGB/NIR photo pairs to train on")
        if render_fraction > 0 and not renders:
            raise NidarError("render_fraction > 0 but the dataset has no rendered RGB/NIR pairs")
        self.photos, self.renders = list(photos), list(renders)
        self.crop_size, self.length = int(crop_size), int(length)
        self.seed, self.train, self.zoom_min = int(seed), bool(train), float(zoom_min)
        self.render_fraction = float(render_fraction)
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """Select the draws of epoch ``epoch``."""
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        rng = np.random.default_rng([self.seed, self.epoch if self.train else 0, index])
        from_render = self.renders and rng.random() < self.render_fraction
        pool = self.renders if from_render else self.photos
        rgb, nir = pool[int(rng.integers(len(pool)))]
        h, w = nir.shape
        zoom = rng.uniform(self.zoom_min, 1.0)
        side = min(int(round(self.crop_size / zoom)), h, w)
        box = (int(rng.integers(0, h - side + 1)), int(rng.integers(0, w - side + 1)), side)
        flip = bool(rng.random() < 0.5)
        rgb_c = np.ascontiguousarray(_crop(rgb, box, self.crop_size, flip))
        nir_c = _crop(nir, box, self.crop_size, flip)
        if self.train:
            rgb_c = augment_colour(rgb_c, rng)
        if nir_c.dtype == np.uint8:
            nir_c = srgb_to_linear(nir_c.astype(np.float32) / np.float32(255.0))
        return {
            "rgb": torch.from_numpy(prepare_rgb(rgb_c)),
            "nir": torch.from_numpy(np.ascontiguousarray(nir_c, dtype=np.float32)[None]),
        }
