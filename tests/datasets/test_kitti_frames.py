"""KITTI frames as training frames: visible returns, rings, splits, caching, the real data."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from nidar_mi.datasets.kitti_frames import (
    DEFAULT_HELD_OUT,
    build_kitti_frames,
    kitti_training_data,
    kitti_training_frame,
)
from nidar_mi.datasets.kitti_objects import load_kitti_frame as load_kitti
from nidar_mi.errors import NidarError
from nidar_mi.geometry import project
from nidar_mi.io.images import write_png
from nidar_mi.io.kitti import write_kitti_bin
from nidar_mi.training_frames import FRAME_SOURCES, list_frames, load_frame
from tests.helpers.synthetic_kitti import CALIB as _SYNTHETIC_KITTI
from tests.helpers.synthetic_kitti import kitti_order_scan

sys.path.insert(0, str(Path(__file__).parent))
from test_kitti_rings import _shared  # noqa: E402


@pytest.fixture()
def drive(tmp_path):
    """A KITTI folder 'drive' with three frames of one synthetic scan (front half)."""
    root = tmp_path / "drive"
    for sub in ("velodyne", "image_2", "calib"):
        (root / sub).mkdir(parents=True)
    xyz, ring, _ = kitti_order_scan(cols=360, front_only=True)
    rng = np.random.default_rng(0)
    for k in range(3):
        inten = rng.uniform(0, 1, len(xyz)).astype(np.float32)
        write_kitti_bin(root / "velodyne" / f"{k:06d}.bin", xyz, inten)
        write_png(root / "image_2" / f"{k:06d}.png", np.full((375, 1242, 3), 40 * k, np.uint8))
        (root / "calib" / f"{k:06d}.txt").write_text(_SYNTHETIC_KITTI)
    return root, ring


def test_training_frame_holds_the_visible_returns(drive):
    root, ring = drive
    fr = load_kitti(root, "000001")
    frame, info = kitti_training_frame(fr)
    assert set(frame) == set(FRAME_SOURCES["kitti"])
    n = len(frame["points_xyz"])
    assert info == {"points": len(fr.xyz), "visible": n, "rings": 64, "ring_method": "scan order"}
    uv, z, front = project(frame["points_xyz"].astype(np.float64), fr.camera)
    assert n > 1000 and front.all() and (uv > -0.5).all()
    assert (uv[:, 0] < 1241.5).all() and (uv[:, 1] < 374.5).all()
    # each visible return keeps its own reflectance and ring (matched back by position)
    idx = {tuple(p): i for i, p in enumerate(fr.xyz.tolist())}
    src = np.array([idx[tuple(p)] for p in frame["points_xyz"].tolist()])
    np.testing.assert_array_equal(frame["points_intensity"], fr.intensity[src])
    np.testing.assert_array_equal(frame["points_ring"], ring[src])
    # the sparse maps: one return per masked pixel, its range and intensity
    m = frame["mask"]
    assert 0 < m.sum() <= n and not frame["intensity"][~m].any()
    assert set(np.round(frame["intensity"][m], 6)) <= set(np.round(frame["points_intensity"], 6))
    dist = np.linalg.norm(frame["points_xyz"].astype(np.float64), axis=1)
    gap = np.abs(frame["range"][m][:, None] - dist[None, :]).min(1)
    assert gap.max() < 1e-4


def test_build_splits_caches_and_refreshes(drive, tmp_path):
    root, _ = drive
    out = tmp_path / "data"
    held = {"test": ("drive__000002",), "val": ("drive__000000", "other__000001")}
    meta = build_kitti_frames([root], out, held_out=held, progress=False)
    assert meta["frames"] == {
        "train": ["drive__000001"],
        "val": ["drive__000000"],
        "test": ["drive__000002"],
    }
    assert json.loads((out / "meta.json").read_text())["source"] == "kitti"
    f = load_frame(list_frames(out, "test")[0])
    assert set(f) == set(FRAME_SOURCES["kitti"])
    target = out / "train" / "drive__000001.npz"
    stamp = os.path.getmtime(target)
    build_kitti_frames([root], out, held_out=held, progress=False)
    assert os.path.getmtime(target) == stamp  # cached
    future = stamp + 10
    os.utime(root / "image_2" / "000001.png", (future, future))
    build_kitti_frames([root], out, held_out=held, progress=False)
    assert os.path.getmtime(target) > stamp  # its source changed: rewritten
    # another held-out list moves frames; nothing stale is left behind
    build_kitti_frames([root], out, held_out={}, progress=False)
    assert [p.name for p in list_frames(out, "train")] == [f"drive__{k:06d}.npz" for k in range(3)]
    assert list_frames(out, "test") == [] and list_frames(out, "val") == []


def test_build_errors(tmp_path, drive):
    with pytest.raises(NidarError, match="no KITTI frame"):
        build_kitti_frames([tmp_path / "nothing"], tmp_path / "o", progress=False)
    root, _ = drive
    with pytest.raises(NidarError, match="distinct names"):
        build_kitti_frames([root, root], tmp_path / "o", progress=False)


def test_the_shared_kitti_frames(tmp_path, monkeypatch):
    dirs = [_shared("kitti"), _shared("kitti_raw_0926")]
    monkeypatch.setenv("NIDAR_MI_CACHE", str(tmp_path / "cache"))
    with pytest.warns(RuntimeWarning, match=r"kitti_raw_0926__000077 \(39 rings\)"):
        out = kitti_training_data(dirs, progress=False)
    assert out.parent.parent == tmp_path / "cache"
    meta = json.loads((out / "meta.json").read_text())
    assert {k: len(v) for k, v in meta["frames"].items()} == {"train": 70, "val": 8, "test": 6}
    assert sorted(meta["frames"]["test"]) == sorted(DEFAULT_HELD_OUT["test"])
    assert all(i["ring_method"] == "scan order" for i in meta["frame_info"].values())
    f = load_frame(out / "test" / "kitti__000003.npz")
    assert f["rgb"].shape[:2] == f["mask"].shape and 15000 < len(f["points_xyz"]) < 25000
    assert 0 <= f["points_intensity"].min() and f["points_intensity"].max() <= 1
    assert f["points_ring"].min() == 0 and 40 < f["points_ring"].max() < 64
