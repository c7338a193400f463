"""``python -m nidar_mi.assign`` with the shipped model: external clouds, KITTI frames, bad input;
and ``render --intensity nidar``."""

import os
import subprocess
import sys

import numpy as np
import pytest
import yaml

from nidar_mi.io.ownership import RECORD
from nidar_mi.nidar.pipeline import shipped_weights_dir

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
KITTI = os.environ.get("NIDAR_KITTI_DIR", os.path.join(REPO, "..", "shared", "data", "kitti"))
pytestmark = pytest.mark.skipif(
    not (shipped_weights_dir() / "irnet.safetensors").is_file(), reason="no shipped weights"
)


def run(module, *args, env=None):
    return subprocess.run(
        [sys.executable, "-m", module, *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=600,
        env=None if env is None else dict(os.environ, **env),
    )


def test_points_image_calib(tmp_path):
    from nidar_mi.io.images import write_png
    from nidar_mi.io.points import read_npz, write_ply

    rng = np.random.default_rng(0)
    # LiDAR frame x forward; the camera looks along +x (OpenCV: x right = -y, y down = -z)
    xyz = np.column_stack(
        [rng.uniform(4, 30, 500), rng.uniform(-8, 8, 500), rng.uniform(-1.5, 2, 500)]
    ).astype(np.float32)
    behind = np.array([[-10.0, 0.0, 0.0]], dtype=np.float32)
    xyz = np.vstack([xyz, behind])
    write_ply(
        tmp_path / "cloud.ply", {"xyz": xyz, "intensity": np.arange(len(xyz), dtype=np.float32)}
    )
    img = (rng.uniform(0, 1, (120, 200, 3)) * 255).astype(np.uint8)
    write_png(tmp_path / "cam.png", img)
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
    calib = {
        "cameras": [
            {
                "name": "front",
                "fx": 120,
                "fy": 120,
                "cx": 99.5,
                "cy": 59.5,
                "width": 200,
                "height": 120,
                "T_cam_lidar": T.tolist(),
            }
        ]
    }
    (tmp_path / "calib.yaml").write_text(yaml.safe_dump(calib))
    out = tmp_path / "out"
    r = run(
        "nidar_mi.assign",
        "--points",
        str(tmp_path / "cloud.ply"),
        "--image",
        str(tmp_path / "cam.png"),
        "--calib",
        str(tmp_path / "calib.yaml"),
        "-o",
        str(out),
    )
    assert r.returncode == 0, r.stderr
    # a cloud of an unknown sensor: the generic profile, named, with a warning on how to calibrate
    assert "profile: generic-compensated (" in r.stdout
    assert "warning: unknown sensor" in r.stderr and "python -m nidar_mi.calibrate" in r.stderr
    p = read_npz(out / "points.npz")
    assert sorted(os.listdir(out)) == [RECORD, "points.las", "points.npz", "points.ply"]
    np.testing.assert_array_equal(p["xyz"], xyz)
    np.testing.assert_array_equal(p["intensity"], np.arange(len(xyz), dtype=np.float32))
    obs = p["nidar_observed"]
    # observed exactly when the point projects inside the image (no other geometry occludes
    # except the cloud's own z-buffer, which can only remove points)
    u = 120 * (-xyz[:, 1]) / xyz[:, 0] + 99.5
    v = 120 * (-xyz[:, 2]) / xyz[:, 0] + 59.5
    inside = (xyz[:, 0] > 0) & (u > -0.5) & (u < 199.5) & (v > -0.5) & (v < 119.5)
    assert not obs[~inside].any() and obs.sum() > 0.5 * inside.sum()
    assert not obs[-1] and p["intensity_nidar"][-1] == 0
    assert np.all((p["intensity_nidar"] >= 0) & (p["intensity_nidar"] <= 1))
    assert np.all(p["intensity_nidar"][~obs] == 0)
    # reflectance_nidar: IRNet's R map sampled bilinearly at the observed points (scipy's
    # interpolation as the reference), 0 elsewhere
    from scipy.ndimage import map_coordinates

    from nidar_mi.nidar.pipeline import NidarModel

    R = NidarModel.load(device="cpu").predict_image(img)["R"].astype(np.float64)
    expected = map_coordinates(R, [v[obs], u[obs]], order=1, mode="nearest")
    refl = p["reflectance_nidar"]
    assert refl.dtype == np.float32 and np.all(refl[~obs] == 0)
    np.testing.assert_allclose(refl[obs], expected, atol=1e-5)


@pytest.mark.skipif(
    not os.path.isdir(KITTI), reason="KITTI frames not available (../shared/data/kitti)"
)
def test_kitti_frame(tmp_path):
    """The default profile with --kitti is kitti-hdl64e, fitted at first use on the other frames
    of the --kitti folder (never on the frame assigned; nothing to set but the flags) and
    cached; a profile file gives the same numbers."""
    from nidar_mi.io.kitti import read_kitti_bin
    from nidar_mi.io.points import read_npz

    env = {"NIDAR_MI_DATA": str(tmp_path / "no_data"), "NIDAR_MI_CACHE": str(tmp_path / "cache")}
    out = tmp_path / "k"
    args = ("--kitti", KITTI, "--frame", "000000", "--formats", "npz")
    r = run("nidar_mi.assign", *args, "-o", str(out), env=env)
    assert r.returncode == 0, r.stderr
    assert "fitting the kitti-hdl64e profile on 5 other frames of" in r.stderr
    assert "(not on 000000)" in r.stderr
    assert "profile: kitti-hdl64e (" in r.stdout and "unknown sensor" not in r.stderr
    p = read_npz(out / "points.npz")
    xyz, refl = read_kitti_bin(os.path.join(KITTI, "velodyne", "000000.bin"))
    np.testing.assert_array_equal(p["xyz"], xyz)
    np.testing.assert_array_equal(p["intensity"], refl)  # the real reflectance kept beside
    frac = p["nidar_observed"].mean()
    assert 0.05 < frac < 0.5  # the camera sees the front sector of the 360 deg scan
    assert np.all(p["xyz"][p["nidar_observed"], 0] > 0)  # only points in front of the car
    assert np.all((p["intensity_nidar"] >= 0) & (p["intensity_nidar"] <= 1))
    (cached,) = (tmp_path / "cache" / "profiles").glob("kitti-hdl64e-*.json")
    r = run("nidar_mi.assign", *args, "-o", str(tmp_path / "k2"), "--profile", str(cached), env=env)
    assert r.returncode == 0 and "fitting" not in r.stderr, r.stderr
    q = read_npz(tmp_path / "k2" / "points.npz")
    np.testing.assert_array_equal(q["intensity_nidar"], p["intensity_nidar"])
    r = run("nidar_mi.assign", *args, "-o", str(tmp_path / "k3"), "--profile", "sim-905", env=env)
    assert r.returncode == 0, r.stderr
    s = read_npz(tmp_path / "k3" / "points.npz")
    np.testing.assert_array_equal(s["nidar_observed"], p["nidar_observed"])
    assert not np.array_equal(s["intensity_nidar"], p["intensity_nidar"])


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--kitti", "/nonexistent", "--frame", "000000"], "missing velodyne"),
        (["--points", "x.ply"], "give --points, --calib and --image"),
        (["--kitti", "/nonexistent"], "--frame"),
        (["--kitti", "/nonexistent", "--frame", "1", "--formats", "xyz"], "--formats"),
    ],
)
def test_bad_input(tmp_path, args, needle):
    r = run("nidar_mi.assign", *args, "-o", str(tmp_path / "o"))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in r.stderr
    assert not (tmp_path / "o").exists()


def test_unknown_profile_is_a_user_error():
    from nidar_mi.cloud_intensity import assign_intensity
    from nidar_mi.errors import NidarError

    with pytest.raises(NidarError, match="unknown profile 'nope'.*sim-905, kitti-hdl64e"):
        assign_intensity(np.zeros((1, 3)), [], [], profile="nope")


def test_render_with_nidar_intensity(tmp_path):
    from nidar_mi.io.points import read_npz, read_ply

    out = tmp_path / "street"
    r = run(
        "nidar_mi.render",
        "scenes/street.xml",
        "-o",
        str(out),
        "--intensity",
        "nidar",
        "-q",
        "-D",
        "width=96",
        "-D",
        "height=64",
        "-D",
        "cols=256",
        "--spp",
        "2",
        "--formats",
        "npz,ply",
        "--profile",
        "sim-905",
    )
    assert r.returncode == 0, r.stderr
    import json

    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["nidar_profile"].startswith("sim-905@")
    assert manifest["request"]["profile"] == manifest["nidar_profile"]
    p = read_npz(out / "lidar_top/points.npz")
    assert p["intensity_nidar"].dtype == np.float32 and p["nidar_observed"].dtype == bool
    obs = p["nidar_observed"]
    assert 0 < obs.sum() < len(obs)  # the forward camera sees part of the 360 deg scan
    assert np.all(p["intensity_nidar"][~obs] == 0)
    assert np.all((p["intensity_nidar"] >= 0) & (p["intensity_nidar"] <= 1))
    refl = p["reflectance_nidar"]
    assert refl.dtype == np.float32 and np.all(refl[~obs] == 0) and np.all(np.isfinite(refl))
    assert refl[obs].std() > 0  # a per-surface value, not a constant
    # the physical intensity is still there, unchanged in meaning
    assert np.all(p["intensity"] >= 0) and p["intensity"].max() > 0
    ply = read_ply(out / "lidar_top/points.ply")
    np.testing.assert_array_equal(ply["intensity_nidar"], p["intensity_nidar"])
    np.testing.assert_array_equal(ply["nidar_observed"], obs)


def test_render_manifest_names_the_default_profile_applied(tmp_path):
    """Without --profile the weights' own sim-905 maps R: the manifest names it (the request,
    the cache key, leaves it to the weights' hash); with --nidar-branch I_hat none is applied."""
    import json

    from nidar_mi.nidar.pipeline import NidarModel
    from nidar_mi.render_session import profile_key

    small = ["-q", "-D", "width=48", "-D", "height=32", "-D", "cols=128", "--spp", "1"]
    small += ["--formats", "npz"]
    default = profile_key(NidarModel.load(device="cpu").default_profile())
    assert default.startswith("sim-905@")
    for branch, expected in (("R", default), ("I_hat", None)):
        out = tmp_path / branch
        r = run("nidar_mi.render", "scenes/street.xml", "-o", str(out), "--intensity", "nidar",
                "--nidar-branch", branch, *small)  # fmt: skip
        assert r.returncode == 0, r.stderr
        manifest = json.loads((out / "manifest.json").read_text())
        assert manifest["nidar_profile"] == expected
        assert manifest["request"]["profile"] is None


def test_i_hat_branch_is_the_head_sampled_at_the_points():
    """branch="I_hat": Î bilinearly sampled at each observed point, clipped to [0, 1]."""
    from nidar_mi.geometry import CameraModel, bilinear_sample, project
    from nidar_mi.nidar.pipeline import NidarModel

    rng = np.random.default_rng(3)
    img = (rng.uniform(0, 1, (64, 96, 3)) * 255).astype(np.uint8)
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
    cam = CameraModel(np.array([[60.0, 0, 47.5], [0, 60.0, 31.5], [0, 0, 1]]), 96, 64, T)
    xyz = np.column_stack([rng.uniform(5, 20, 50), rng.uniform(-2, 2, 50), rng.uniform(-1, 1, 50)])
    model = NidarModel.load(device="cpu")
    maps = model.predict_image(img)
    res = model.point_intensity(xyz, [cam], [img], maps=[maps], branch="I_hat", occlusion=False)
    uv, _, _ = project(xyz, cam)
    expected = np.clip(bilinear_sample(maps["I_hat"], uv), 0, 1)
    assert res.observed.sum() > 40
    np.testing.assert_allclose(
        res.intensity[res.observed], expected[res.observed], rtol=1e-5, atol=1e-6
    )
    with pytest.raises(Exception, match="branch"):
        model.point_intensity(xyz, [cam], [img], maps=[maps], branch="S")
