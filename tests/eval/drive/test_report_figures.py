"""The drive study's figures: a colour bar where colour encodes a value, legends off the data."""

from __future__ import annotations

from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from nidar_mi.eval.drive.report import _descriptors_figure, _map_figure  # noqa: E402


def test_descriptors_have_a_colour_bar():
    grids = np.random.default_rng(0).uniform(size=(3, 20, 60)).astype(np.float32)
    desc = {s: (grids, None, None) for s in ("physics", "carla", "none")}
    fig = _descriptors_figure(desc, 1)
    bars = [a for a in fig.axes if a.get_label() == "<colorbar>"]
    assert len(fig.axes) == 4 and len(bars) == 1
    assert "99th percentile" in bars[0].get_ylabel()
    plt.close(fig)


def test_map_legend_lies_beside_the_map():
    """The legend does not overlap the map's axes (it covered cars when inside them)."""
    poses = np.tile(np.eye(4), (20, 1, 1))
    poses[:, 0, 3] = np.linspace(0.0, 50.0, 20)
    fig = _map_figure(SimpleNamespace(shapes=[]), poses, np.array([3, 4]))
    fig.canvas.draw()
    ax = fig.axes[0]
    legend = ax.get_legend().get_window_extent()
    assert legend.x0 >= ax.get_window_extent().x1
    plt.close(fig)
