"""The torch path of the camera sampling (nidar_mi.geometry.device_fusion) equals the NumPy
reference (nidar_mi.geometry.fusion.sample_cameras) on the CPU device."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.geometry import CameraModel, sample_cameras
from nidar_mi.geometry.device_fusion import sample_cameras_on

K = np.array([[500.0, 0.0, 319.5], [0.0, 480.0, 239.5], [0.0, 0.0, 1.0]])
W, H = 640, 480


def _cameras(random_rigid, rot, rigid):
    """A camera at the origin, one yawed 20 deg 1 m behind, one at a random pose (Waymo axes)."""
    r1 = rot("y", 20.0)
    cam1 = CameraModel(K, W, H, np.linalg.inv(rigid(r1, r1 @ [0.0, 0.0, -1.0])), "opencv")
    cam2 = CameraModel(K, W // 2, H // 2, random_rigid(np.random.default_rng(3)), "waymo")
    return [CameraModel(K, W, H, np.eye(4), "opencv"), cam1, cam2]


def _cloud(n=30_000, seed=0):
    """Points in front of and around the cameras, a wall and boxes that hide some of them,
    plus points behind the cameras and far away."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-12, 12, (n, 2))
    z = rng.uniform(-5, 40, n)
    z[: n // 3] = np.where(np.abs(xy[: n // 3, 0]) < 3, 8.0, 25.0)  # near wall and far wall
    return np.column_stack([xy, z])


def _images(cams, seed=1):
    rng = np.random.default_rng(seed)
    out = [rng.uniform(0, 1, (c.height, c.width)) for c in cams]
    out[0][10:20, 30:60] = np.nan  # a hole: points sampling it are unobserved
    return out


def _assert_same(a, b):
    np.testing.assert_array_equal(a[1], b[1])
    np.testing.assert_array_equal(a[2], b[2])
    np.testing.assert_allclose(a[0], b[0], rtol=0, atol=1e-6)  # float32 values
    assert a[0].dtype == b[0].dtype and a[2].dtype == b[2].dtype


@pytest.mark.parametrize("fusion", ["nearest_center", "mean", "min_depth"])
@pytest.mark.parametrize("occlusion", [True, False])
def test_the_torch_path_equals_the_reference(fusion, occlusion, random_rigid, rot, rigid):
    cams = _cameras(random_rigid, rot, rigid)
    pts, imgs = _cloud(), _images(cams)
    ref = sample_cameras(pts, cams, imgs, occlusion=occlusion, fusion=fusion)
    got = sample_cameras_on("cpu", pts, cams, imgs, occlusion=occlusion, fusion=fusion)
    _assert_same(got, ref)
    assert 0 < ref[1].sum() < len(pts)


@pytest.mark.parametrize("kind", ["z", "range"])
def test_depth_images_and_options_give_the_reference_result(kind, random_rigid, rot, rigid):
    cams = _cameras(random_rigid, rot, rigid)
    pts, imgs = _cloud(seed=2), _images(cams)
    rng = np.random.default_rng(4)
    depths = [rng.uniform(5, 30, (c.height, c.width)) for c in cams]
    depths[1][:, :100] = np.nan  # no surface there
    depths[2] = None  # that camera falls back to the z-buffer
    opts = {"depth_kind": kind, "rel_tol": 0.1, "abs_tol": 0.05, "zbuffer_cell": 3}
    ref = sample_cameras(pts, cams, imgs, depth_images=depths, **opts)
    got = sample_cameras_on("cpu", pts, cams, imgs, depth_images=depths, **opts)
    _assert_same(got, ref)


def test_the_benchmark_scan_and_tensor_images():
    """The HDL-64E-like benchmark cloud through a KITTI-like camera, the image a float32
    tensor as NIDAR's maps are."""
    import torch

    from benchmarks.bench_nidar import hdl64e_cloud, kitti_like_camera

    pts, cam = hdl64e_cloud(512), kitti_like_camera(1242, 375)
    img = np.random.default_rng(5).uniform(0, 1, (375, 1242)).astype(np.float32)
    ref = sample_cameras(pts, [cam], [img])
    _assert_same(sample_cameras_on("cpu", pts, [cam], [torch.from_numpy(img)]), ref)


def test_bad_input_is_the_reference_error(wall_scene):
    pts, _ = wall_scene
    cam = CameraModel(K, W, H, np.eye(4), "opencv")
    img = np.zeros((H, W))
    for call, message in [
        (lambda: sample_cameras_on("cpu", pts, [], []), "no cameras"),
        (lambda: sample_cameras_on("cpu", pts, [cam], [img], fusion="max"), "fusion must be"),
        (lambda: sample_cameras_on("cpu", pts, [cam], [img, img]), "1 cameras but 2 images"),
        (lambda: sample_cameras_on("cpu", pts, [cam], [img[1:]]), "image 0 is"),
        (lambda: sample_cameras_on("cpu", pts[:, :2], [cam], [img]), r"shape \(N, 3\)"),
        (lambda: sample_cameras_on("cpu", pts, [cam], [img], zbuffer_cell=0), "zbuffer_cell"),
        (lambda: sample_cameras_on("cpu", pts, [cam], [img], rel_tol=-1), "non-negative"),
    ]:
        with pytest.raises(NidarError, match=message):
            call()
