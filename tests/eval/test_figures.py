"""Evaluation figures: PNG files of the expected layout, written atomically."""

from __future__ import annotations

import numpy as np

from nidar_mi.eval.figures import maps_figure, scatter_figure
from nidar_mi.io.images import read_png


def test_maps_and_scatter_pngs(tmp_path):
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    uv = rng.uniform(0, 47, (100, 2))
    gt = rng.uniform(0, 1, 100)
    preds = {"a": gt * 0.5, "b": np.clip(gt + 0.1, 0, 1)}
    maps_figure(rgb, uv, gt, preds, tmp_path / "m.png", labels={"a": "A"}, title="t")
    scatter_figure(gt, preds, tmp_path / "s.png", title="t")
    for name in ("m.png", "s.png"):
        img = read_png(tmp_path / name)
        assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100
    # three panel columns (GT + 2 methods) make the map figure wider than tall
    m = read_png(tmp_path / "m.png")
    assert m.shape[1] > m.shape[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.png", "s.png"]
