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


SEQUENCE_SCENE = """<?xml version="1.0"?>
<scene version="3.0.0">
    <sensor type="lidar" id="roof">
        <string name="elevation_angles" value="-5, -10, -15, -20"/>
        <integer name="horizontal_resolution" value="90"/>
        <transform name="to_world"><translate z="1.5"/></transform>
    </sensor>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="0.3"/></bsdf>
    <bsdf type="diffuse" id="white"><spectrum name="reflectance" value="0.8"/></bsdf>
    <shape type="rectangle" id="road" label="road">
        <transform name="to_world"><scale value="200"/></transform><ref id="grey"/></shape>
    <shape type="cube" id="box" label="car" instance="car_1">
        <transform name="to_world"><translate x="8" y="3" z="1"/></transform><ref id="white"/></shape>
</scene>
"""


@pytest.fixture(scope="session")
def synthetic_sequence(variant, tmp_path_factory):
    """Three scans of a small labelled scene from poses 1 m apart along x, yawing 5 deg per
    frame, at 10 Hz: ``(points dicts, (3, 4, 4) T_world_lidar, (3,) times in s)``."""
    from scipy.spatial.transform import Rotation

    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    path = tmp_path_factory.mktemp("seq") / "scene.xml"
    path.write_text(SEQUENCE_SCENE)
    loaded = load_scene(str(path))
    poses, clouds = [], []
    for k in range(3):
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("z", 5.0 * k, degrees=True).as_matrix()
        T[:3, 3] = [1.0 * k, 0.0, 1.5]
        result = scan(loaded.scene, loaded.lidars[0], to_world=T, labels=loaded.labels)
        pts = result.points()
        pts["t"] = (pts["column"] / 90.0 * 0.1).astype(np.float32)  # a 10 Hz sweep
        clouds.append(pts)
        poses.append(T)
    return clouds, np.array(poses), np.array([0.0, 0.1, 0.2])
