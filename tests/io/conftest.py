"""Shared fixtures of the nidar_mi.io tests."""

import numpy as np
import pytest


def _make_points(n: int, seed: int = 0) -> dict:
    """A points dict with every schema column, two later columns and metadata."""
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(-80.0, 80.0, (n, 3)).astype(np.float32)
    return {
        "xyz": xyz,
        "xyz_world": (xyz + np.float32(1000.0)).astype(np.float32),
        "range": np.linalg.norm(xyz, axis=1).astype(np.float32),
        "intensity": rng.uniform(0.0, 0.3, n).astype(np.float32),
        "reflectance": rng.uniform(0.0, 1.0, n).astype(np.float32),
        "cos_incidence": rng.uniform(0.0, 1.0, n).astype(np.float32),
        "ring": rng.integers(0, 64, n).astype(np.uint16),
        "column": rng.integers(0, 2048, n).astype(np.uint32),
        "material": rng.integers(-1, 3, n).astype(np.int32),
        "material_names": np.array(["asphalt", "concrete", "birch leaf"]),
        "intensity_nidar": rng.uniform(0.0, 0.3, n).astype(np.float32),
        "nidar_observed": rng.uniform(size=n) < 0.5,
        "wavelength_nm": np.float32(905.0),
    }


def _assert_points_equal(got: dict, want: dict) -> None:
    """Same keys, dtypes, shapes and values (NaN equal to NaN)."""
    assert sorted(got) == sorted(want)
    for k, v in want.items():
        v = np.asarray(v)
        assert got[k].dtype == v.dtype, k
        assert got[k].shape == v.shape, k
        np.testing.assert_array_equal(got[k], v, err_msg=k)


# Helpers are handed out as fixtures: test modules never import conftest by name.


@pytest.fixture
def make_points():
    """Factory ``make_points(n, seed=0)`` of points dicts."""
    return _make_points


@pytest.fixture
def points() -> dict:
    """A 257-point points dict."""
    return _make_points(257)


@pytest.fixture
def assert_points_equal():
    """``assert_points_equal(got, want)``: same keys, dtypes, shapes and values."""
    return _assert_points_equal
