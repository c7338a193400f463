"""A context profile on the paths that assign NIDAR intensity: ``point_intensity`` (``assign``)
and ``render --intensity nidar``'s columns, which hand it the camera images it reads."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.nidar.pipeline import NidarModel
from nidar_mi.profiles import SensorProfile, fit
from nidar_mi.profiles.inputs import GROUPS

W, H = 64, 48
K = [[50.0, 0, 31.5], [0, 50.0, 23.5], [0, 0, 1]]
T = [[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1.0]]
#: Points of the scene behind the wall, in the camera's view (the last ones).
HIDDEN = 50


def _scene():
    """A wall 10 m ahead and a floor 1.7 m below, sampled on a 0.1 m grid, then a patch 15 m
    ahead that the wall hides (its last :data:`HIDDEN` points); an image whose left half is dark
    and right half bright."""
    s, h = np.meshgrid(np.arange(-3, 3, 0.1), np.arange(-1.5, 1.5, 0.1))
    wall = np.stack([np.full(s.size, 10.0), s.ravel(), h.ravel()], axis=1)
    x, y = np.meshgrid(np.arange(3, 10, 0.1), np.arange(-3, 3, 0.1))
    floor = np.stack([x.ravel(), y.ravel(), np.full(x.size, -1.7)], axis=1)
    s, h = np.meshgrid(np.arange(-1, 1, 0.2), np.arange(-0.5, 0.5, 0.2))
    hidden = np.stack([np.full(s.size, 15.0), s.ravel(), h.ravel()], axis=1)
    assert len(hidden) == HIDDEN
    img = np.full((H, W, 3), 40, np.uint8)
    img[:, W // 2 :] = 220
    return np.vstack([wall, floor, hidden]), img


def _profile(groups=("return", "ring", "geometry", "image", "nidar")) -> SensorProfile:
    """A few trees on made-up inputs: the intensity is the pixel's linear green."""
    rng = np.random.default_rng(0)
    names = [f for g in groups for f in GROUPS[g]]
    ctx = {f: rng.uniform(0, 1, 2000) for f in names}
    y = ctx["g_lin"] if "g_lin" in ctx else ctx["range_m"]
    m = fit("context", ctx["range_m"], ctx["range_m"], y, context=ctx, trees=20)
    return SensorProfile("ctx", "test", "context", "nidar:R", m)


@pytest.fixture(scope="module")
def model():
    return NidarModel.load(device="cpu")


def test_point_intensity_reads_the_image_at_the_returns(model):
    """Brighter pixels give brighter returns (the profile's whole response); the reflectance
    output stays NIDAR's R; points hidden behind the wall are not assigned."""
    from nidar_mi.geometry import CameraModel

    xyz, img = _scene()
    cam = CameraModel(K=np.array(K), width=W, height=H, T_cam_lidar=np.array(T))
    res = model.point_intensity(xyz, [cam], [img], profile=_profile())
    o = res.observed
    assert o.sum() > 100 and not o[-HIDDEN:].any()
    assert np.all(res.intensity[-HIDDEN:] == 0)
    u = np.array(K)[0, 0] * -xyz[:, 1] / xyz[:, 0] + np.array(K)[0, 2]  # column of each point
    bright, dark = o & (u > W / 2 + 2), o & (u < W / 2 - 2)
    assert res.intensity[bright].min() > res.intensity[dark].max()
    plain = model.point_intensity(xyz, [cam], [img])  # the weights' own profile, R branch
    np.testing.assert_array_equal(res.reflectance, plain.reflectance)
    np.testing.assert_array_equal(res.observed, plain.observed)


def test_render_columns_hand_the_images_to_a_context_profile(model):
    """``nidar_columns`` (``render --intensity nidar``) gives the profile the camera images:
    the same intensities as ``point_intensity`` with the image; a profile of the image refuses
    where no image is given, one of the geometry alone needs none."""
    from nidar_mi.geometry import CameraModel
    from nidar_mi.simulate import nidar_columns

    xyz, img = _scene()
    render = SimpleNamespace(srgb8=lambda: img, depth=None)
    calib = {"K": K, "width": W, "height": H, "T_cam_lidar": {"lidar": T}}
    result = SimpleNamespace(points=lambda: {"xyz": xyz, "ring": np.full(len(xyz), -1)})
    prof = _profile()
    out = nidar_columns(model, {"lidar": result}, {"cam": (render, calib)}, "R", prof)["lidar"]
    cam = CameraModel(K=np.array(K), width=W, height=H, T_cam_lidar=np.array(T), name="cam")
    ref = model.point_intensity(xyz, [cam], [img], profile=prof, ring=np.full(len(xyz), -1))
    np.testing.assert_array_equal(out["intensity_nidar"], ref.intensity)
    maps = [model.predict_image(img)]
    with pytest.raises(NidarError, match="reads the camera image"):
        model.point_intensity(xyz, [cam], [None], maps=maps, profile=prof)
    geo = _profile(("return", "geometry"))
    res = model.point_intensity(xyz, [cam], [None], maps=maps, profile=geo)
    assert res.observed.sum() > 100
