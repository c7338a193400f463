"""Training-data reader and datasets, on synthetic frames written in the documented format."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.nidar.data import IntrinsicTargets, IRNetDataset, STNDataset
from nidar_mi.nidar.preprocess import prepare_nir, prepare_rgb
from nidar_mi.training_frames import FRAME_KEYS, FRAME_SOURCES, list_frames, load_frame, load_meta
from tests.helpers.synthetic_frames import write_synthetic_dataset


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    return write_synthetic_dataset(tmp_path_factory.mktemp("data"), height=48, width=64)


def test_synthetic_frames_follow_the_format(data_dir):
    meta = load_meta(data_dir)
    assert meta["intensity_scale"] == 255.0 and meta["wavelength_nm"] == 905
    frames = list_frames(data_dir, "train")
    assert [f.name for f in frames] == [f"frame_{i:04d}.npz" for i in range(4)]
    assert len(list_frames(data_dir, "val")) == 2 and len(list_frames(data_dir, "test")) == 1
    f = load_frame(frames[0])
    n = int(f["mask"].sum())
    shapes = {
        "rgb": (48, 64, 3),
        "A_true": (48, 64, 3),
        "K": (3, 3),
        "T_cam_lidar": (4, 4),
        "points_xyz": (n, 3),
    }
    shapes |= {"points_intensity": (n,), "points_ring": (n,)}
    assert set(f) == set(FRAME_KEYS) == set(FRAME_SOURCES[meta["source"]])
    for key, (dtype, _, _) in FRAME_KEYS.items():
        assert f[key].dtype == dtype
        assert f[key].shape == shapes.get(key, (48, 64))
    assert np.all(f["intensity"][~f["mask"]] == 0)
    # Synthetic intensity is scale * NIR radiance on the scan pattern.
    np.testing.assert_allclose(f["intensity"][f["mask"]], 255.0 * f["nir"][f["mask"]], rtol=1e-6)
    np.testing.assert_allclose(np.pi * f["nir"], f["R_true"] * f["S_true"], rtol=1e-5)
    # the returns project back onto their pixels, with their intensity
    from nidar_mi.geometry import CameraModel, project

    cam = CameraModel(K=f["K"], width=64, height=48, T_cam_lidar=f["T_cam_lidar"])
    uv = project(f["points_xyz"].astype(np.float64), cam)[0]
    rows, cols = np.rint(uv[:, 1]).astype(int), np.rint(uv[:, 0]).astype(int)
    assert np.abs(uv - np.rint(uv)).max() < 1e-3 and f["mask"][rows, cols].all()
    np.testing.assert_array_equal(f["points_intensity"], f["intensity"][rows, cols])


def test_reader_errors(tmp_path, data_dir):
    with pytest.raises(NidarError, match="not found"):
        load_meta(tmp_path)
    (tmp_path / "meta.json").write_text(json.dumps({"intensity_scale": -1}))
    with pytest.raises(NidarError, match="intensity_scale"):
        load_meta(tmp_path)
    with pytest.raises(NidarError, match="unknown split"):
        list_frames(data_dir, "dev")
    good = load_frame(list_frames(data_dir, "train")[0])
    np.savez(tmp_path / "missing.npz", **{k: v for k, v in good.items() if k != "mask"})
    with pytest.raises(NidarError, match="missing key"):
        load_frame(tmp_path / "missing.npz")
    np.savez(tmp_path / "dtype.npz", **{**good, "nir": good["nir"].astype(np.float64)})
    with pytest.raises(NidarError, match="nir has dtype float64"):
        load_frame(tmp_path / "dtype.npz")
    np.savez(tmp_path / "shape.npz", **{**good, "mask": good["mask"][:-1]})
    with pytest.raises(NidarError, match="mask has shape"):
        load_frame(tmp_path / "shape.npz")


def test_object_arrays_are_refused_not_unpickled(tmp_path, data_dir):
    good = load_frame(list_frames(data_dir, "train")[0])
    obj = np.empty(1, dtype=object)
    obj[0] = {"payload": 1}
    np.savez(tmp_path / "pickled.npz", **{**good, "K": obj})
    with pytest.raises(NidarError, match="cannot read frame"):
        load_frame(tmp_path / "pickled.npz")


def test_stn_dataset_centre_crop_values(data_dir):
    frames = list_frames(data_dir, "val")
    ds = STNDataset(frames, crop_size=32, train=False)
    item = ds[1]
    assert item["rgb"].shape == (3, 32, 32) and item["nir"].shape == (1, 32, 32)
    f = load_frame(frames[1])
    # Normalised over the whole frame, then the centre crop (rows 8..40, cols 16..48).
    np.testing.assert_array_equal(item["rgb"].numpy(), prepare_rgb(f["rgb"])[:, 8:40, 16:48])
    np.testing.assert_array_equal(item["nir"].numpy(), prepare_nir(f["nir"])[:, 8:40, 16:48])


def test_random_crops_are_seeded_by_seed_epoch_and_index(data_dir):
    frames = list_frames(data_dir, "train")
    a, b = STNDataset(frames, 32, seed=5), STNDataset(frames, 32, seed=5)
    np.testing.assert_array_equal(a[2]["nir"].numpy(), b[2]["nir"].numpy())
    seen = set()
    for epoch in range(6):
        a.set_epoch(epoch)
        seen.add(a[2]["nir"].numpy().tobytes())
    assert len(seen) > 1


def test_irnet_dataset_keeps_input_and_supervision_aligned(tmp_path, data_dir):
    frames = list_frames(data_dir, "train")
    # A "pseudo-NIR" cache holding the raw NIR radiance: wherever the mask is set, the
    # target (intensity / scale) must equal the input pixel after the same crop and flip.
    for f in frames:
        np.save(tmp_path / f"{f.stem}.npy", load_frame(f, ("nir",))["nir"][None])
    ds = IRNetDataset(frames, 255.0, 32, seed=1, train=True, input_dir=tmp_path)
    for epoch in range(3):
        ds.set_epoch(epoch)
        for i in range(len(ds)):
            item = ds[i]
            m = item["mask"].numpy() > 0
            assert m.any()
            np.testing.assert_allclose(
                item["intensity"].numpy()[m], item["x"].numpy()[m], rtol=1e-6
            )
            assert np.all(item["intensity"].numpy()[~m] == 0)
    rgb = IRNetDataset(frames, 255.0, 32, train=False)[0]
    assert rgb["x"].shape == (3, 32, 32) and set(np.unique(rgb["mask"].numpy())) <= {0.0, 1.0}
    # with the true reflectance and shading: R_true * S_true = π * NIR under the same crop/flip
    ds = IRNetDataset(frames, 255.0, 32, seed=2, input_dir=tmp_path, intrinsic=IntrinsicTargets())
    for epoch in range(3):
        ds.set_epoch(epoch)
        item = ds[1]
        np.testing.assert_allclose(
            (item["R_true"] * item["S_true"]).numpy(), np.pi * item["x"].numpy(), rtol=1e-5
        )


def test_reflectance_targets_read_the_surface_or_its_colour(data_dir):
    """``r_target``: the monostatic ``R_true``, the surface's ``R_surface``, or the earthlib
    colour map of the albedo ``A_true``, all under the same crop and flip."""
    from nidar_mi.materials.visible_albedo import colour_reflectance_map

    frames = list_frames(data_dir, "train")
    arrays = load_frame(frames[0], ("A_true", "R_surface"))
    items = {}
    for target in ("monostatic", "surface", "colour"):
        ds = IRNetDataset(
            frames, 255.0, (48, 64), train=False, intrinsic=IntrinsicTargets(r_target=target)
        )
        items[target] = ds[0]["R_true"].numpy()[0]
    np.testing.assert_allclose(items["surface"], arrays["R_surface"], rtol=1e-6)
    np.testing.assert_allclose(items["monostatic"], arrays["R_surface"], rtol=1e-6)  # no gloss
    expected = np.maximum(colour_reflectance_map(905.0)(arrays["A_true"]), 1e-3)
    np.testing.assert_allclose(items["colour"], expected, rtol=1e-6)


def test_crop_larger_than_frame_is_a_user_error(data_dir):
    ds = STNDataset(list_frames(data_dir, "val"), crop_size=64, train=False)
    with pytest.raises(NidarError, match="exceeds the frame size"):
        ds[0]


def test_intensity_is_scaled_and_clipped(data_dir):
    """intensity / scale, clipped to [0, 1]: a retroreflector's huge return saturates at 1."""
    frames = list_frames(data_dir, "train")[:1]
    full = {k: np.asarray(v) for k, v in IRNetDataset(frames, 255.0, 32, train=False)[0].items()}
    small = {k: np.asarray(v) for k, v in IRNetDataset(frames, 25.5, 32, train=False)[0].items()}
    m = full["mask"] > 0  # (small: everything 10x brighter)
    np.testing.assert_allclose(
        small["intensity"][m], np.minimum(10 * full["intensity"][m], 1.0), rtol=1e-5
    )
    assert small["intensity"].max() == 1.0 and full["intensity"].max() <= 1.0
