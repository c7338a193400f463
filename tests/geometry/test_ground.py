"""The ground under a scan: heights above known ground planes, with objects standing on them."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.geometry.ground import ground_height


def _scene(z_ground, seed: int = 0):
    """Ground returns on rings of a spinning sensor out to 50 m (``z_ground(x, y)``), and boxes
    standing on it: (points, true height above the ground, is ground)."""
    rng = np.random.default_rng(seed)
    r = np.concatenate([np.full(400, d) for d in np.geomspace(4.0, 50.0, 30)])
    az = rng.uniform(-np.pi, np.pi, r.size)
    x, y = r * np.cos(az), r * np.sin(az)
    ground = np.stack([x, y, z_ground(x, y)], axis=1)
    boxes, heights = [], []
    for cx, cy, h in ((8.0, 3.0, 1.5), (15.0, -6.0, 2.0), (-25.0, 10.0, 1.0), (30.0, 30.0, 3.0)):
        u = rng.uniform(-1, 1, (300, 2))
        hh = rng.uniform(0.3, h, 300)
        bx, by = cx + u[:, 0], cy + u[:, 1]
        boxes.append(np.stack([bx, by, z_ground(bx, by) + hh], axis=1))
        heights.append(hh)
    p = np.vstack([ground, *boxes])
    true = np.concatenate([np.zeros(len(ground)), *heights])
    return p, true, np.arange(len(p)) < len(ground)


def test_level_ground_heights_are_exact():
    """A level road 1.73 m under the sensor (KITTI's mounting height): every point's height is
    its z + 1.73, ground points 0, box points their height above the road."""
    p, true, is_ground = _scene(lambda x, y: np.full_like(x, -1.73))
    h = ground_height(p)
    np.testing.assert_allclose(h, true, atol=1e-9)
    assert np.all(np.abs(h[is_ground]) < 1e-9)


def test_sloped_and_tilted_ground():
    """A road rising 3 % along x, and a sensor tilted 2° about y over it: heights within 5 cm of
    the true distance above the road everywhere (one global plane would miss by up to 1.5 m)."""
    slope = 0.03
    p, true, _ = _scene(lambda x, y: -1.73 + slope * x)
    h = ground_height(p)
    tilt = np.cos(np.arctan(slope))  # height along the plane's normal
    np.testing.assert_allclose(h, true * tilt, atol=0.05)
    a = np.radians(2.0)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    p2, true2, _ = _scene(lambda x, y: np.full_like(x, -1.73), seed=1)
    np.testing.assert_allclose(ground_height(p2 @ rot.T), true2, atol=0.02)


def test_curved_ground_follows_the_zones():
    """A road that bends up beyond 20 m (a hill): a single plane is off by tens of cm there; the
    per-zone planes keep the ground within 0.15 m."""

    def hill(x, y):
        r = np.hypot(x, y)
        return -1.73 + 0.0006 * np.maximum(r - 20.0, 0.0) ** 2

    p, true, is_ground = _scene(hill, seed=2)
    h = ground_height(p)
    assert np.max(np.abs(h[is_ground])) < 0.15
    assert np.median(np.abs(h - true)) < 0.05


def test_degenerate_and_bad_input():
    assert np.isnan(ground_height(np.zeros((2, 3)))).all()
    assert ground_height(np.zeros((0, 3))).shape == (0,)
    line = np.stack([np.linspace(1, 10, 50), np.zeros(50), np.full(50, -1.7)], axis=1)
    assert np.isnan(ground_height(line)).all()  # one line: no plane
    with pytest.raises(NidarError, match="finite"):
        ground_height(np.array([[np.inf, 0.0, 0.0]] * 4))
    with pytest.raises(NidarError, match=r"\(N, 3\)"):
        ground_height(np.zeros((4, 2)))
