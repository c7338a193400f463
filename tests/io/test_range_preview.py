"""Range-image previews: the colour range and what its caption says about clipping."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.io.range_preview import ColourRange, colour_range, write_range_preview


def test_default_clip_is_stated_with_the_data_range():
    """A range bar clipped at the 99th percentile (29 m) for data to 69.9 m says so."""
    rng = np.random.default_rng(0)
    v = np.concatenate([rng.uniform(3.0, 29.0, 10_000), [0.5, 69.9]])
    c = colour_range(v)
    assert c.lo == pytest.approx(np.percentile(v, 1)) and c.hi == pytest.approx(
        np.percentile(v, 99)
    )
    assert c.extend == "both"
    assert "1st-99th percentile" in c.note and "data 0.5-69.9" in c.note
    assert f"{c.hi:.3g}" in c.note


def test_no_note_when_nothing_is_clipped():
    v = np.linspace(0.0, 10.0, 101)
    assert colour_range(v, 0.0, 10.0) == ColourRange(0.0, 10.0, "neither", "")
    c = colour_range(v, vmax=5.0)  # a given end: clipped, but no percentile
    assert c.extend == "both" and "percentile" in c.note and "1st" in c.note
    assert colour_range(np.array([np.nan])).note == ""


def test_preview_is_written(tmp_path):
    img = np.linspace(1.0, 70.0, 8 * 32).reshape(8, 32)
    path = tmp_path / "range.png"
    write_range_preview(
        path, img, np.ones_like(img, bool), np.linspace(180, -180, 32), label="range (m)"
    )
    assert path.stat().st_size > 0
