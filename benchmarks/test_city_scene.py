"""Checks of the benchmark scene: mesh counts and winding, rays, ranges against the terrain.

Run: ``.venv/bin/pytest benchmarks/`` (outside ``testpaths``: not part of the default suite).
"""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import city_scene as city  # noqa: E402

VARIANT = "llvm_ad_spectral"


def _normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_city_mesh_counts_and_winding():
    meshes = city.city_mesh(grid=11)
    tv, tf = meshes["terrain"]
    bv, bf = meshes["buildings"]
    assert tv.shape == (121, 3) and tf.shape == (2 * 10 * 10, 3)
    # 10 x 10 blocks of 20 m over 200 m; 5 faces (no bottom) of 2 triangles, 4 own vertices each
    assert bf.shape == (100 * 10, 3) and bv.shape == (100 * 20, 3)
    assert tf.min() == 0 and tf.max() == len(tv) - 1
    assert bf.min() == 0 and bf.max() == len(bv) - 1
    assert np.all(_normals(tv, tf)[:, 2] > 0.99)  # gentle terrain, facing up
    # building faces face outwards: from the box's axis (top faces: up)
    n = _normals(bv, bf)
    centroid = bv[bf].mean(axis=1)
    box = np.repeat(np.arange(100), 10)
    axis_xy = bv.reshape(100, 20, 3)[:, :, :2].mean(axis=1)[box]
    top = np.tile(np.r_[np.ones(2, bool), np.zeros(8, bool)], 100)
    assert np.all(n[top, 2] > 0.999)
    outward = np.einsum("ij,ij->i", n[~top, :2], centroid[~top, :2] - axis_xy[~top])
    assert np.all(outward > 0) and np.all(np.abs(n[~top, 2]) < 1e-6)
    # the default grid gives at least 100k triangles
    assert 2 * (241 - 1) ** 2 + 1000 >= 100_000


@pytest.fixture(scope="module")
def small_city():
    from nidar_mi.backend import set_variant

    set_variant(VARIANT)
    loaded, meshes = city.load_city(rings=8, cols=256, grid=241, variant=VARIANT)
    return loaded, meshes


def test_world_rays_hand_computed(small_city):
    loaded, _ = small_city
    rays = city.world_rays(loaded.lidars[0])
    assert rays.shape == (8 * 256, 6) and rays.dtype == np.float32
    # ring 0 is +22.5 deg; column 0 at azimuth 0.5 * 360 / 256; the pose turns it by the yaw
    el, az = np.deg2rad(22.5), np.deg2rad(0.5 * 360 / 256 + city.SENSOR_YAW_DEG)
    expected = [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]
    np.testing.assert_allclose(rays[0, 3:], expected, atol=1e-6)
    np.testing.assert_allclose(rays[:, :3], np.tile([0, 0, city.SENSOR_HEIGHT_M], (len(rays), 1)))
    np.testing.assert_allclose(np.linalg.norm(rays[:, 3:], axis=1), 1.0, atol=1e-6)


def test_scan_ranges_match_the_height_field(small_city):
    """Lowest ring (-22.5 deg) on the street: range from bisection on the analytic terrain."""
    from nidar_mi.lidar.scan import scan

    loaded, _ = small_city
    sensor = loaded.lidars[0]
    res = scan(loaded.scene, sensor)
    rays = city.world_rays(sensor).astype(np.float64).reshape(8, 256, 6)[7]
    o, d = rays[:, :3], rays[:, 3:]

    def f(t):
        p = o + t[:, None] * d
        return p[:, 2] - city.terrain_height(p[:, 0], p[:, 1])

    lo, hi = np.full(256, 1.0), np.full(256, 10.0)
    assert np.all(f(lo) > 0) and np.all(f(hi) < 0)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        above = f(mid) > 0
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    t = 0.5 * (lo + hi)
    p = o + t[:, None] * d
    street = np.minimum(np.abs(p[:, 0]), np.abs(p[:, 1])) < 2.5  # clear of the 3 m kerb line
    assert street.sum() > 150
    assert np.all(res.valid[7, street])
    # The mesh interpolates h linearly over triangles of diameter 1.18 m; |h''| <= 0.015 /m bounds
    # the height error by 0.015 * 1.18**2 / 8 = 2.6 mm, and a beam 22.5 deg down on ground
    # tilted up to 3.3 deg meets it at >= 19 deg: <= 2.6 mm / sin(19 deg) = 8 mm along the beam.
    np.testing.assert_allclose(res.range[7, street], t[street], atol=8e-3)
