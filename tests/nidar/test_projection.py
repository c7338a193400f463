"""Tests for nidar_mi.nidar.projection (pinhole models, sampling, occlusion, fusion)."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.nidar.projection import (
    R_OPENCV_FROM_WAYMO,
    CameraModel,
    assign,
    bilinear_sample,
    in_image,
    project,
    unproject,
    visible_mask,
)

K = np.array([[500.0, 0.0, 319.5], [0.0, 480.0, 239.5], [0.0, 0.0, 1.0]])
W, H = 640, 480


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


def _identity_cam(width=W, height=H, k=K) -> CameraModel:
    return CameraModel(k, width, height, np.eye(4), "opencv")


# --- projection -------------------------------------------------------------------------


@pytest.mark.parametrize("convention", ["opencv", "waymo"])
def test_project_unproject_round_trip(convention):
    rng = np.random.default_rng(0)
    T = _random_rigid(rng)
    cam = CameraModel(K, W, H, T, convention)
    uv = rng.uniform([-100, -50], [W + 100, H + 50], size=(500, 2))
    depth = rng.uniform(0.5, 80.0, 500)
    pts = unproject(uv, depth, cam)
    uv2, depth2, in_front = project(pts, cam)
    assert in_front.all()
    np.testing.assert_allclose(uv2, uv, rtol=0, atol=1e-8)
    np.testing.assert_allclose(depth2, depth, rtol=1e-12)
    np.testing.assert_allclose(unproject(uv2, depth2, cam), pts, rtol=0, atol=1e-10)


def test_project_waymo_matches_paper_equation():
    rng = np.random.default_rng(1)
    T = _random_rigid(rng)
    cam = CameraModel(K, W, H, T, "waymo")
    pts = rng.normal(size=(200, 3)) * 10
    pc = pts @ T[:3, :3].T + T[:3, 3]
    X, Y, Z = pc.T
    front = X > 1e-6
    u = K[0, 0] * (-Y / X) + K[0, 2]
    v = K[1, 1] * (-Z / X) + K[1, 2]
    uv, depth, in_front = project(pts, cam)
    np.testing.assert_array_equal(in_front, front)
    np.testing.assert_allclose(depth, X, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(uv[front], np.stack([u, v], 1)[front], rtol=1e-10)
    assert np.isnan(uv[~front]).all()


def test_project_opencv_matches_pinhole_equation():
    rng = np.random.default_rng(2)
    k = K.copy()
    k[0, 1] = 3.0  # skew is honoured
    T = _random_rigid(rng)
    cam = CameraModel(k, W, H, T, "opencv")
    pts = rng.normal(size=(200, 3)) * 10
    X, Y, Z = (pts @ T[:3, :3].T + T[:3, 3]).T
    front = Z > 1e-6
    u = k[0, 0] * X / Z + k[0, 1] * Y / Z + k[0, 2]
    v = k[1, 1] * Y / Z + k[1, 2]
    uv, depth, in_front = project(pts, cam)
    np.testing.assert_array_equal(in_front, front)
    np.testing.assert_allclose(depth, Z, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(uv[front], np.stack([u, v], 1)[front], rtol=1e-10)


def test_conventions_agree_for_the_same_physical_camera():
    rng = np.random.default_rng(3)
    # A camera 1.5 m up, yawed 30 degrees left, in a LiDAR frame x fwd / y left / z up.
    R_lidar_cam_waymo = _rot("z", 30.0)  # waymo camera axes coincide with LiDAR axes, yawed
    T_lidar_cam = _rigid(R_lidar_cam_waymo, [0.2, 0.1, 1.5])
    waymo = CameraModel(K, W, H, np.linalg.inv(T_lidar_cam), "waymo")
    # The same camera written by hand in OpenCV axes (right, down, forward).
    R_lidar_cam_cv = R_lidar_cam_waymo @ R_OPENCV_FROM_WAYMO.T
    opencv = CameraModel(K, W, H, np.linalg.inv(_rigid(R_lidar_cam_cv, [0.2, 0.1, 1.5])))
    np.testing.assert_allclose(waymo.to_opencv().T_cam_lidar, opencv.T_cam_lidar, atol=1e-12)
    pts = rng.uniform([-5, -40, -3], [60, 40, 8], size=(1000, 3))
    uv_w, d_w, f_w = project(pts, waymo)
    uv_c, d_c, f_c = project(pts, opencv)
    np.testing.assert_array_equal(f_w, f_c)
    np.testing.assert_allclose(d_w, d_c, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(uv_w[f_w], uv_c[f_c], rtol=1e-10, atol=1e-9)
    # A point straight ahead of the camera, 1 m to its left and up, lands up-left of centre.
    p = (T_lidar_cam @ [10.0, 1.0, 1.0, 1.0])[:3]
    ((u, v),) = project(p[None], waymo)[0]
    assert u == pytest.approx(319.5 - 50.0) and v == pytest.approx(239.5 - 48.0)


def test_pixel_convention_centre_and_bounds():
    cam = _identity_cam(width=8, height=6, k=[[4.0, 0, 3.5], [0, 4.0, 2.5], [0, 0, 1]])
    ((u, v),) = project(np.array([[0.0, 0.0, 5.0]]), cam)[0]
    assert (u, v) == (3.5, 2.5)  # the optical axis hits the image centre ((W-1)/2, (H-1)/2)
    uv = np.array([[-0.5, 0.0], [-0.5001, 0.0], [7.4999, 5.4999], [7.5, 0.0], [0.0, 5.5]])
    assert in_image(uv, cam).tolist() == [True, False, True, False, False]
    # unprojecting pixel (c, r)'s centre and sampling there returns img[r, c] exactly
    img = np.arange(48, dtype=float).reshape(6, 8)
    cr = np.array([[0, 0], [7, 5], [3, 2], [6, 1]], dtype=float)
    pts = unproject(cr, np.full(4, 3.0), cam)
    uv, _, _ = project(pts, cam)
    np.testing.assert_allclose(bilinear_sample(img, uv), img[[0, 5, 2, 1], [0, 7, 3, 6]])


def test_behind_camera_is_not_in_front():
    uv, depth, in_front = project(np.array([[0.0, 0.0, -2.0], [0.0, 0.0, 0.0]]), _identity_cam())
    assert not in_front.any() and np.isnan(uv).all()
    assert depth.tolist() == [-2.0, 0.0]
    assert not in_image(uv, _identity_cam()).any()


# --- sampling ---------------------------------------------------------------------------


def test_bilinear_sample_exact_on_linear_ramp():
    rows, cols = np.mgrid[0:7, 0:9]
    img = 2.0 * cols - 3.0 * rows + 1.0
    rng = np.random.default_rng(4)
    uv = rng.uniform([0, 0], [8, 6], size=(300, 2))
    np.testing.assert_allclose(
        bilinear_sample(img, uv), 2.0 * uv[:, 0] - 3.0 * uv[:, 1] + 1.0, rtol=0, atol=1e-12
    )
    # integer coordinates hit pixel centres
    assert bilinear_sample(img, np.array([[8.0, 6.0], [2.0, 3.0]])).tolist() == [
        img[6, 8],
        img[3, 2],
    ]


def test_bilinear_sample_edges_and_outside():
    img = np.array([[1.0, 2.0], [3.0, 4.0]])
    uv = np.array([[-0.5, -0.5], [-0.2, 0.0], [1.4, 1.0], [1.5, 0.0], [0.0, -0.6], [np.nan, 0]])
    out = bilinear_sample(img, uv)
    np.testing.assert_array_equal(out[:3], [1.0, 1.0, 4.0])  # outer half pixel: edge value
    assert np.isnan(out[3:]).all()
    assert bilinear_sample(img, uv[3:], fill=-1.0).tolist() == [-1.0, -1.0, -1.0]
    single = bilinear_sample(np.array([[5.0]]), np.array([[0.3, -0.2]]))
    assert single.tolist() == [5.0]
    with pytest.raises(NidarError, match=r"\(H, W\)"):
        bilinear_sample(np.zeros((2, 2, 3)), uv)


# --- occlusion --------------------------------------------------------------------------


def _wall_scene():
    """Identity camera; a wall of points at z = 10 m over x, y in [-2, 2] m (5 cm grid)."""
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


def _render_wall_depth(cam: CameraModel, kind: str) -> np.ndarray:
    rows, cols = np.mgrid[0 : cam.height, 0 : cam.width]
    xn = (cols - cam.K[0, 2]) / cam.K[0, 0]
    yn = (rows - cam.K[1, 2]) / cam.K[1, 1]
    hit = (np.abs(10.0 * xn) <= 2.0) & (np.abs(10.0 * yn) <= 2.0)
    z = np.where(hit, 10.0, np.inf)
    return z if kind == "z" else z * np.sqrt(xn**2 + yn**2 + 1.0)


def test_point_behind_wall_hidden_by_cloud_zbuffer():
    pts, n_wall = _wall_scene()
    cam = _identity_cam()
    uv, depth, _ = project(pts, cam)
    vis = visible_mask(uv, depth, cam)
    assert vis[:n_wall].all()
    assert vis[n_wall:].tolist() == [False, True, True, True]


@pytest.mark.parametrize("kind", ["z", "range"])
def test_point_behind_wall_hidden_by_depth_image(kind):
    pts, n_wall = _wall_scene()
    cam = _identity_cam()
    uv, depth, _ = project(pts, cam)
    vis = visible_mask(uv, depth, cam, depth_image=_render_wall_depth(cam, kind), depth_kind=kind)
    assert vis[:n_wall].all()
    assert vis[n_wall:].tolist() == [False, True, True, True]
    # a zero-depth ("no hit") image hides nothing; a tight tolerance hides the 3 % point
    none = visible_mask(uv, depth, cam, depth_image=np.zeros((H, W)))
    assert none.all()
    tight = visible_mask(
        uv, depth, cam, depth_image=_render_wall_depth(cam, "z"), rel_tol=0.0, abs_tol=0.0
    )
    assert not tight[-1]


def test_visible_mask_rejects_bad_arguments():
    cam = _identity_cam()
    uv, depth = np.zeros((2, 2)), np.ones(2)
    with pytest.raises(NidarError, match="depth image"):
        visible_mask(uv, depth, cam, depth_image=np.ones((3, 3)))
    with pytest.raises(NidarError, match="depth_kind"):
        visible_mask(uv, depth, cam, depth_image=np.ones((H, W)), depth_kind="disparity")
    with pytest.raises(NidarError, match="zbuffer_cell"):
        visible_mask(uv, depth, cam, zbuffer_cell=0)


def test_assign_occlusion_changes_the_hidden_point():
    pts, n_wall = _wall_scene()
    cam = _identity_cam()
    img = np.full((H, W), 0.25)
    vals, obs, idx = assign(pts, [cam], [img])
    assert obs[:n_wall].all() and obs[n_wall:].tolist() == [False, True, True, True]
    assert vals[n_wall] == 0.0 and idx[n_wall] == -1
    assert vals.dtype == np.float32 and idx.dtype == np.int64
    vals2, obs2, idx2 = assign(pts, [cam], [img], occlusion=False)
    assert obs2.all() and vals2[n_wall] == np.float32(0.25) and idx2[n_wall] == 0


# --- fusion -----------------------------------------------------------------------------


def _two_cameras():
    """Camera 0 at the origin looking +z; camera 1 yawed 20 deg to the right, 1 m behind."""
    cam0 = _identity_cam()
    R_lidar_cam1 = _rot("y", 20.0)  # rotates +z (forward) towards +x (right)
    T1 = np.linalg.inv(_rigid(R_lidar_cam1, R_lidar_cam1 @ [0.0, 0.0, -1.0]))
    return cam0, CameraModel(K, W, H, T1, "opencv")


def test_fusion_rules_pick_as_documented():
    cam0, cam1 = _two_cameras()
    ang = np.deg2rad([15.0, -20.0, 80.0])  # 15 deg right, 20 deg left of cam0 axis; outside
    pts = np.stack([10 * np.sin(ang), np.zeros(3), 10 * np.cos(ang)], 1)
    images = [np.full((H, W), 0.25), np.full((H, W), 0.75)]
    # nearest_center: the 15 deg point is 5 deg off cam1's axis, 15 deg off cam0's
    vals, obs, idx = assign(pts, [cam0, cam1], images, occlusion=False)
    assert obs.tolist() == [True, True, False]
    assert idx.tolist() == [1, 0, -1]
    np.testing.assert_array_equal(vals, np.float32([0.75, 0.25, 0.0]))
    # min_depth: cam1 stands 1 m behind, so cam0 is always nearer
    vals, _, idx = assign(pts, [cam0, cam1], images, occlusion=False, fusion="min_depth")
    assert idx.tolist() == [0, 0, -1]
    np.testing.assert_array_equal(vals, np.float32([0.25, 0.25, 0.0]))
    # mean over the cameras that see the point (the -20 deg point is outside cam1's view)
    uv1, _, f1 = project(pts, cam1)
    assert not (in_image(uv1, cam1) & f1)[1]
    vals, _, idx = assign(pts, [cam0, cam1], images, occlusion=False, fusion="mean")
    np.testing.assert_array_equal(vals, np.float32([0.5, 0.25, 0.0]))
    assert idx.tolist() == [1, 0, -1]


def test_fusion_ties_go_to_the_lowest_index_and_nan_pixels_do_not_count():
    cam = _identity_cam()
    pts = np.array([[0.0, 0.0, 5.0], [1.0, 0.0, 5.0]])
    img0 = np.full((H, W), 0.1)
    img0[:, W // 2 + 20 :] = np.nan  # camera 0 has no value at the second point
    vals, obs, idx = assign(pts, [cam, cam], [img0, np.full((H, W), 0.9)], occlusion=False)
    assert obs.all() and idx.tolist() == [0, 1]
    np.testing.assert_array_equal(vals, np.float32([0.1, 0.9]))


def test_assign_rejects_mismatched_inputs():
    cam = _identity_cam()
    pts = np.zeros((1, 3))
    with pytest.raises(NidarError, match="images"):
        assign(pts, [cam], [])
    with pytest.raises(NidarError, match="image 0"):
        assign(pts, [cam], [np.zeros((2, 2))])
    with pytest.raises(NidarError, match="fusion"):
        assign(pts, [cam], [np.zeros((H, W))], fusion="max")
    with pytest.raises(NidarError, match=r"\(N, 3\)"):
        assign(np.zeros((4, 2)), [cam], [np.zeros((H, W))])


def test_camera_model_validation():
    with pytest.raises(NidarError, match="convention"):
        CameraModel(K, W, H, np.eye(4), "ros")
    with pytest.raises(NidarError, match="K must"):
        CameraModel(np.eye(4), W, H, np.eye(4))
    with pytest.raises(NidarError, match="last row"):
        CameraModel(K, W, H, np.ones((4, 4)))
    with pytest.raises(NidarError, match="positive"):
        CameraModel(K, 0, H, np.eye(4))
    cam = CameraModel(K, W, H, _rigid(_rot("x", 10.0), [1, 2, 3]), name="front")
    np.testing.assert_allclose(cam.T_lidar_cam @ cam.T_cam_lidar, np.eye(4), atol=1e-12)
    assert cam.to_opencv() is not cam and cam.to_opencv().name == "front"


# --- what occlusion changes: an analytic street -----------------------------------------

_BOXES = [  # (min corner, max corner, image value); LiDAR frame x fwd, y left, z up
    ((10.0, -1.0, -1.8), (11.0, 1.0, 0.5), 0.9),
    ((15.0, 2.0, -1.8), (16.0, 4.0, 1.0), 0.7),
    ((20.0, -5.0, -1.8), (21.0, -3.0, 2.0), 0.3),
]
_SURFACE_VALUE = np.array([0.2, 0.5] + [b[2] for b in _BOXES])  # ground, wall, boxes


def _cast(origin, dirs):
    """First hit (distance, surface id) of unit rays with ground z=-1.8, wall x=30, boxes."""
    t = np.full(len(dirs), np.inf)
    sid = np.full(len(dirs), -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k, tk in enumerate([(-1.8 - origin[2]) / dirs[:, 2], (30.0 - origin[0]) / dirs[:, 0]]):
            m = (tk > 1e-6) & (tk < t)
            t[m], sid[m] = tk[m], k
        for k, (lo, hi, _) in enumerate(_BOXES):
            t1, t2 = (np.array(lo) - origin) / dirs, (np.array(hi) - origin) / dirs
            tn = np.nanmax(np.minimum(t1, t2), axis=1)
            tf = np.nanmin(np.maximum(t1, t2), axis=1)
            m = (tn <= tf) & (tn > 1e-6) & (tn < t)
            t[m], sid[m] = tn[m], 2 + k
    return t, sid


def test_occlusion_on_an_analytic_street():
    el, az = np.meshgrid(
        np.deg2rad(np.linspace(-24.8, 2.0, 64)), np.deg2rad(np.arange(-60, 60, 0.1))
    )
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
    t, sid = _cast(np.zeros(3), dirs.reshape(-1, 3))
    keep = t < 80.0
    pts, truth = dirs.reshape(-1, 3)[keep] * t[keep, None], _SURFACE_VALUE[sid[keep]]
    # camera 1.2 m from the LiDAR, waymo axes = LiDAR axes
    width, height, offset = 800, 300, np.array([0.5, 1.0, -0.3])
    k = np.array([[400.0, 0, width / 2 - 0.5], [0, 400.0, height / 2 - 0.5], [0, 0, 1]])
    cam = CameraModel(k, width, height, _rigid(np.eye(3), -offset), "waymo")
    rows, cols = np.mgrid[0:height, 0:width]
    uv = np.stack([cols.ravel(), rows.ravel()], 1).astype(float)
    rays = unproject(uv, np.ones(len(uv)), cam) - offset
    t_pix, sid_pix = _cast(offset, rays / np.linalg.norm(rays, axis=1, keepdims=True))
    img = _SURFACE_VALUE[sid_pix].reshape(height, width)
    zimg = (t_pix * rays[:, 0] / np.linalg.norm(rays, axis=1)).reshape(height, width)

    def wrong_fraction(**kw):
        vals, obs, _ = assign(pts, [cam], [img], **kw)
        return np.mean(np.abs(vals[obs] - truth[obs]) > 1e-6), obs.sum()

    none, n_none = wrong_fraction(occlusion=False)
    with_depth, n_depth = wrong_fraction(depth_images=[zimg])
    with_zbuf, n_zbuf = wrong_fraction()
    # measured 3.2 % / 0.8 % / 0.8 % (module docstring); the rest is silhouette blending
    assert none > 0.025
    assert with_depth < 0.01 and with_zbuf < 0.01
    assert n_depth > 0.97 * n_none and n_zbuf > 0.97 * n_none
