"""RGB/NIR photo pairs: listing, loading, the held-out split by image."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from nidar_mi.datasets.rgbnir import list_pairs, load_pair, split_pairs
from nidar_mi.errors import NidarError
from nidar_mi.io.images import write_png

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture()
def photos(tmp_path):
    rng = np.random.default_rng(0)
    for cat, n in (("field", 5), ("urban", 11), ("water", 3)):
        (tmp_path / cat).mkdir()
        for i in range(n):
            write_png(
                tmp_path / cat / f"{i:04d}_rgb.png", rng.integers(0, 256, (6, 8, 3), np.uint8)
            )
            write_png(tmp_path / cat / f"{i:04d}_nir.png", rng.integers(0, 256, (6, 8), np.uint8))
    (tmp_path / "urban" / "0099_rgb.png").write_bytes(b"")  # no NIR: not a pair
    (tmp_path / "readme.txt").write_text("x")
    return tmp_path


def test_list_and_load(photos):
    pairs = list_pairs(photos)
    assert len(pairs) == 19 and pairs[0].name == "field/0000" and pairs[-1].name == "water/0002"
    rgb, nir = load_pair(pairs[0])
    assert rgb.shape == (6, 8, 3) and nir.shape == (6, 8) and rgb.dtype == nir.dtype == np.uint8
    write_png(photos / "water" / "0001_nir.png", np.zeros((5, 8), np.uint8))
    with pytest.raises(NidarError, match="differ in size"):
        load_pair(next(p for p in list_pairs(photos) if p.name == "water/0001"))
    with pytest.raises(NidarError, match="no RGB/NIR"):
        list_pairs(photos / "absent")


def test_split_by_image_every_category_everywhere(photos):
    pairs = list_pairs(photos)
    s = split_pairs(pairs)
    names = [p.name for p in pairs]
    assert sorted(s["train"] + s["val"] + s["test"]) == sorted(names)  # each exactly once
    for split in s.values():
        assert {n.split("/")[0] for n in split} == {"field", "urban", "water"}
    # per category: round(0.2 n) test (>= 1), round(0.2 rest) val (>= 1)
    counts = {
        c: [sum(n.startswith(c) for n in s[k]) for k in ("train", "val", "test")]
        for c in ("field", "urban", "water")
    }
    assert counts == {"field": [3, 1, 1], "urban": [7, 2, 2], "water": [1, 1, 1]}
    assert s == split_pairs(list(reversed(pairs)))  # the order of the input does not matter
    assert s != split_pairs(pairs, seed=1)
    with pytest.raises(NidarError, match="fractions"):
        split_pairs(pairs, test=1.0)


def test_the_shared_photos():
    root = Path(os.environ.get("NIDAR_MI_DATA", REPO.parent / "shared" / "data")) / "rgbnir"
    if not root.is_dir():
        pytest.skip(f"RGB/NIR photos not found at {root} (set NIDAR_MI_DATA)")
    pairs = list_pairs(root)
    s = split_pairs(pairs)
    assert len(pairs) == 160 and {k: len(v) for k, v in s.items()} == {
        "train": 106,
        "val": 22,
        "test": 32,
    }
    assert len({n.split("/")[0] for n in s["test"]}) == 9
    rgb, nir = load_pair(pairs[0])
    assert rgb.shape[:2] == nir.shape
