"""Pixel-aligned RGB / near-infrared photo pairs (the EPFL RGB-NIR scene dataset layout).

Layout: ``ROOT/<category>/NNNN_rgb.<ext>`` (8-bit sRGB; ``.jpg``, ``.jpeg``, ``.png`` or
``.tif``) and ``ROOT/<category>/NNNN_nir.<ext>`` (8-bit grey, same size, pixel-aligned). A pair is
named ``<category>/NNNN``. The shared copy lives in ``../shared/data/rgbnir`` (research use with
citation; never copied into the project).

:func:`split_pairs` holds out whole images, every category represented: per category (sorted by
name), the pair names (sorted) are permuted by one generator seeded once (``seed``) and drawn in
category order; the first ``round(test · n)`` (at least one) are ``test``, of the rest the next
``round(val · rest)`` (at least one) are ``val``, the remainder ``train``. With the defaults (0.2,
0.2, seed 0) the 160 shared pairs split 106 / 22 / 32.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import NidarError
from .paths import data_root

__all__ = ["PhotoPair", "default_rgbnir_dir", "list_pairs", "load_pair", "split_pairs"]

_RGB_EXT = (".jpg", ".jpeg", ".png", ".tif", ".tiff")


@dataclass(frozen=True)
class PhotoPair:
    """One RGB/NIR pair.

    Attributes:
        name: ``<category>/NNNN``.
        category: the folder it is in.
        rgb: path of the colour image.
        nir: path of the NIR image.
    """

    name: str
    category: str
    rgb: Path
    nir: Path


def default_rgbnir_dir() -> Path:
    """``<data root>/rgbnir`` (:func:`nidar_mi.datasets.paths.data_root`)."""
    return data_root() / "rgbnir"


def _find(folder: Path, stem: str) -> Path | None:
    for ext in _RGB_EXT:
        p = folder / f"{stem}{ext}"
        if p.is_file():
            return p
    return None


def list_pairs(root: str | os.PathLike | None = None) -> list[PhotoPair]:
    """Every complete pair under ``root`` (default :func:`default_rgbnir_dir`), sorted by name.

    Raises:
        NidarError: ``root`` is missing or holds no pair.
    """
    root = Path(root) if root is not None else default_rgbnir_dir()
    if not root.is_dir():
        raise NidarError(f"{root}: no RGB/NIR photo folder (expected <category>/NNNN_rgb.jpg)")
    pairs = []
    for cat in sorted(p for p in root.iterdir() if p.is_dir()):
        stems = sorted({p.name[: -len("_nir") - len(p.suffix)] for p in cat.glob("*_nir.*")})
        for stem in stems:
            rgb, nir = _find(cat, f"{stem}_rgb"), _find(cat, f"{stem}_nir")
            if rgb is not None and nir is not None:
                pairs.append(PhotoPair(f"{cat.name}/{stem}", cat.name, rgb, nir))
    if not pairs:
        raise NidarError(f"{root}: no RGB/NIR pair (<category>/NNNN_rgb.jpg + NNNN_nir.png)")
    return pairs


def load_pair(pair: PhotoPair) -> tuple[np.ndarray, np.ndarray]:
    """``(rgb, nir)``: (H, W, 3) and (H, W) uint8, pixel-aligned.

    Raises:
        NidarError: an unreadable file, or images of different sizes.
    """
    from PIL import Image

    from ..io.atomic import reading

    with reading(pair.rgb) as p, Image.open(p) as im:
        rgb = np.asarray(im.convert("RGB"), dtype=np.uint8)
    with reading(pair.nir) as p, Image.open(p) as im:
        nir = np.asarray(im.convert("L"), dtype=np.uint8)
    if rgb.shape[:2] != nir.shape:
        raise NidarError(
            f"{pair.name}: RGB {rgb.shape[1]}x{rgb.shape[0]} and NIR {nir.shape[1]}x{nir.shape[0]} "
            "differ in size"
        )
    return rgb, nir


def split_pairs(
    pairs: list[PhotoPair], *, test: float = 0.2, val: float = 0.2, seed: int = 0
) -> dict[str, list[str]]:
    """Held-out split by image, every category in every split (module docstring).

    Args:
        pairs: from :func:`list_pairs`.
        test: fraction of each category held out for testing.
        val: fraction of each category's remainder for validation (model selection).
        seed: the generator's seed.

    Returns:
        ``{"train", "val", "test"}`` -> sorted pair names.

    Raises:
        NidarError: fractions outside [0, 1), or a category with fewer than 3 pairs.
    """
    if not (0 <= test < 1 and 0 <= val < 1):
        raise NidarError(f"split fractions must lie in [0, 1) (got test={test}, val={val})")
    by_cat: dict[str, list[str]] = {}
    for p in pairs:
        by_cat.setdefault(p.category, []).append(p.name.split("/", 1)[1])
    rng = np.random.default_rng(seed)
    out: dict[str, list[str]] = {"train": [], "val": [], "test": []}
    for cat in sorted(by_cat):
        ids = sorted(by_cat[cat])
        if len(ids) < 3:
            raise NidarError(f"category {cat} has {len(ids)} pair(s); at least 3 are needed")
        ids = list(rng.permutation(ids))
        nt = max(1, round(test * len(ids))) if test > 0 else 0
        held, rest = ids[:nt], ids[nt:]
        nv = max(1, round(val * len(rest))) if val > 0 else 0
        out["test"] += [f"{cat}/{i}" for i in sorted(held)]
        out["val"] += [f"{cat}/{i}" for i in sorted(rest[:nv])]
        out["train"] += [f"{cat}/{i}" for i in sorted(rest[nv:])]
    return {k: sorted(v) for k, v in out.items()}


def stn_training_pairs(
    root: str | os.PathLike | None = None, *, progress: bool = False
) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[tuple[np.ndarray, np.ndarray]]]:
    """The photo pairs the STN is trained on, loaded: ``(fit, val)``.

    The pairs of ``root`` are split by image with :func:`split_pairs` (seed 0, every category in
    every split): ``fit`` holds the ``train`` and ``val`` pairs, ``val`` the ``val`` pairs alone
    (logged during training); the ``test`` pairs are never read (the photo evaluation scores
    them, :mod:`nidar_mi.eval.photos`). Each pair is ``(rgb (H, W, 3) uint8, nir (H, W) uint8)``.
    """
    from ..progress import progress_bar

    pairs = {p.name: p for p in list_pairs(root)}
    split = split_pairs(list(pairs.values()))
    names = split["train"] + split["val"]
    fit = [load_pair(pairs[n]) for n in progress_bar(names, show=progress, desc="photos")]
    val = [load_pair(pairs[n]) for n in split["val"]]
    return fit, val
