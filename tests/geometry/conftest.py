"""Shared fixtures of the nidar_mi.geometry tests: rigid transforms and a wall of points."""

import numpy as np
import pytest


def _rot(axis: str, deg: float) -> np.ndarray:
    c, s = np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _rigid(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def _random_rigid(rng) -> np.ndarray:
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    return _rigid(R, rng.normal(size=3))


# Helpers are handed out as fixtures: test modules never import conftest by name.


@pytest.fixture()
def rot():
    """``rot(axis, deg)``: (3, 3) rotation by ``deg`` degrees about ``"x"``, ``"y"`` or ``"z"``."""
    return _rot


@pytest.fixture()
def rigid():
    """``rigid(R, t)``: (4, 4) transform with rotation R and translation t (m)."""
    return _rigid


@pytest.fixture()
def random_rigid():
    """``random_rigid(rng)``: (4, 4) rigid transform, uniform rotation, N(0, 1) m translation."""
    return _random_rigid


@pytest.fixture()
def wall_scene():
    """``(points, n_wall)``: a wall of points at z = 10 m over x, y in [-2, 2] m (5 cm grid),
    then four probes, seen from a camera at the origin looking along +z (OpenCV axes):
    behind the wall (hidden), on the wall, beside the wall, and 3 % behind the wall surface
    (within the default tolerance)."""
    g = np.arange(-2.0, 2.0001, 0.05)
    gx, gy = np.meshgrid(g, g)
    wall = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, 10.0)], 1)
    probes = np.array(
        [
            [0.013, 0.021, 20.0],  # behind the wall: hidden
            [0.5, -0.5, 10.0],  # on the wall: visible
            [6.0, 0.0, 20.0],  # beside the wall (outside its footprint): visible
            [0.013, 0.021, 10.3],  # 3 % behind the wall surface: within tolerance
        ]
    )
    return np.concatenate([wall, probes]), wall.shape[0]
