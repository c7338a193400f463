"""Training-data builder: split by scene, frame contents, resumability."""

import os
import shutil

import numpy as np
import pytest

from nidar_mi.dataset import build_dataset, split_scenes
from nidar_mi.errors import NidarError

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_split_is_by_scene_and_seeded():
    names = [f"s{i:02d}" for i in range(20)]
    a = split_scenes(names, (0.8, 0.1, 0.1), seed=1)
    assert [len(a[s]) for s in ("train", "val", "test")] == [16, 2, 2]
    assert sorted(sum(a.values(), [])) == names  # every scene exactly once
    assert a == split_scenes(list(reversed(names)), (0.8, 0.1, 0.1), seed=1)
    assert a != split_scenes(names, (0.8, 0.1, 0.1), seed=2)
    small = split_scenes(["a", "b", "c"], (0.8, 0.1, 0.1))
    assert all(len(v) == 1 for v in small.values())
    with pytest.raises(NidarError):
        split_scenes(names, (1.0, -0.5, 0.5))


@pytest.mark.slow
def test_frames_from_target_scene(variant, tmp_path):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    shutil.copy(os.path.join(REPO, "scenes", "target.xml"), scenes / "target.xml")
    out = tmp_path / "data"
    params = {"cols": "720"}
    meta = build_dataset(
        str(scenes), str(out), fractions=(1, 0, 0), spp=2, params=params, progress=False
    )
    assert meta["frames"]["train"] == ["target__camera"] and meta["wavelength_nm"] == 905.0
    f = np.load(out / "train" / "target__camera.npz")
    H, W = 160, 320
    assert f["rgb"].shape == (H, W, 3) and f["rgb"].dtype == np.uint8
    for k in ("nir", "intensity", "reflectance", "range", "depth"):
        assert f[k].shape == (H, W) and f[k].dtype == np.float32, k
    m = f["mask"]
    assert m.dtype == bool and 50 < m.sum() < m.size
    assert not f["intensity"][~m].any()
    # every projected return lies on a panel: ρ is one of the panel reflectances (or the ramp)
    rho = f["reflectance"][m]
    flat = (
        np.isclose(rho, 0.95, atol=1e-4)
        | np.isclose(rho, 0.5, atol=1e-4)
        | np.isclose(rho, 0.05, atol=1e-4)
    )
    ramp = np.isclose(rho, 0.2 + 0.6 * 505 / 1200, atol=1e-4)
    assert (flat | ramp).all()
    # compensated intensity of a Lambertian panel never exceeds ρ (cos θ ≤ 1, no extinction)
    assert np.all(f["intensity"][m] <= rho + 1e-6) and np.all(f["intensity"][m] > 0)
    # the LiDAR return and the camera see the same surface: camera z-depth at the pixel is
    # no larger than the LiDAR range (the camera is 0.2 m above the LiDAR) plus a margin
    assert np.all(f["depth"][m] <= f["range"][m] + 0.3)
    # the true reflectance per pixel is the same ρ the LiDAR saw there (Lambertian panels; a few
    # silhouette pixels may see another surface than the return that landed on them)
    same = np.isclose(f["R_true"][m], rho, atol=1e-4)
    assert same.mean() > 0.95
    lit = f["R_true"] >= 1e-3
    np.testing.assert_allclose(
        f["R_true"][lit] * f["S_true"][lit], np.pi * f["nir"][lit], rtol=1e-4
    )
    assert not f["S_true"][~lit].any()
    # the visible returns: at least one per masked pixel, their intensities include the map's
    n = len(f["points_xyz"])
    assert f["points_intensity"].shape == f["points_ring"].shape == (n,) and n >= m.sum()
    assert set(np.round(f["intensity"][m], 6)) <= set(np.round(f["points_intensity"], 6))
    assert f["points_ring"].min() >= 0
    # resumable: a second run renders nothing and keeps the frame
    stamp = os.path.getmtime(out / "train" / "target__camera.npz")
    build_dataset(str(scenes), str(out), fractions=(1, 0, 0), spp=2, params=params, progress=False)
    assert os.path.getmtime(out / "train" / "target__camera.npz") == stamp
