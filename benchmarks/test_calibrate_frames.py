"""The leave-one-drive-out benchmark on tiny synthetic scans (no shared data needed)."""

from __future__ import annotations

import os
import sys

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import calibrate_frames as bench  # noqa: E402

H, W = 20, 30


class _FakeModel:
    """R = the image's red channel / 255; pseudo-NIR = its green channel / 255."""

    def __init__(self):
        self.calls: list[tuple] = []

    def predict_image(self, rgb):
        self.calls.append((rgb.shape, int(rgb.min()), int(rgb.max())))
        f = rgb.astype(np.float32) / 255.0
        return {"R": f[..., 0], "pseudo_nir": f[..., 1], "S": f[..., 2], "I_hat": f[..., 0]}


def _scan(name: str, rgb: np.ndarray):
    """A camera looking down the LiDAR's z axis (identity extrinsics) and returns on the plane
    z = 5 m: one at each pixel centre of column 3 + row, plus one behind the camera."""
    from nidar_mi.datasets.scans import ScanFrame
    from nidar_mi.geometry import CameraModel

    k = np.array([[20.0, 0, (W - 1) / 2], [0, 20.0, (H - 1) / 2], [0, 0, 1]])
    cam = CameraModel(K=k, width=W, height=H, T_cam_lidar=np.eye(4), name="c")
    v = np.arange(2, H - 2, dtype=np.float64)
    u = v + 3.0
    z = 5.0
    xyz = np.stack([(u - k[0, 2]) / 20.0 * z, (v - k[1, 2]) / 20.0 * z, np.full_like(u, z)], 1)
    xyz = np.vstack([xyz, [[0.0, 0.0, -5.0]]])  # behind the camera: no camera sees it
    n = len(xyz)
    return ScanFrame(
        name=name,
        xyz=xyz,
        intensity=np.linspace(0, 1, n),
        ring=np.full(n, -1, np.int16),
        cameras=[cam],
        _images=lambda: [rgb],
    )


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _image(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (H, W, 3), dtype=np.uint8)


def test_sources_sample_the_maps_at_the_returns_and_grey_is_the_constant_image():
    rgb = _image(0)
    scans = [_scan("kitti__a", rgb), _scan("kitti__b", _image(1))]
    model = _FakeModel()
    values = bench.source_values(model, scans, list(bench.VALUE_SOURCES))
    v = np.arange(2, H - 2)
    u = v + 3
    from nidar_mi.eval.reflectance_cue import GREY_LEVEL, luminance

    a = {s: values[s]["kitti__a"] for s in bench.VALUE_SOURCES}
    # returns at pixel centres read the pixel; the one behind the camera has no value
    np.testing.assert_allclose(a["nidar"][:-1], rgb[v, u, 0] / 255.0, atol=1e-6)
    np.testing.assert_allclose(a["stn"][:-1], rgb[v, u, 1] / 255.0, atol=1e-6)
    np.testing.assert_allclose(a["luminance"][:-1], luminance(rgb)[v, u], atol=1e-6)
    np.testing.assert_allclose(a["geometry"][:-1], GREY_LEVEL / 255.0, atol=1e-6)
    for s in bench.VALUE_SOURCES:
        assert np.isnan(a[s][-1])
    # the grey image is predicted once per image size, and it is uniform at GREY_LEVEL
    greys = [c for c in model.calls if c[1] == c[2]]
    assert greys == [((H, W, 3), GREY_LEVEL, GREY_LEVEL)]
    np.testing.assert_array_equal(values["geometry"]["kitti__b"], a["geometry"])


def test_group_of_names_drives_and_groups():
    assert bench.group_of("kitti_more__r0009_000012") == "r0009"
    assert bench.group_of("kitti_more__obj000006") == "obj"
    assert bench.group_of("kitti_more__o04_000040") == "o04"
    assert bench.group_of("kitti_raw_0926__000070") == "kitti_raw_0926"
    assert bench.group_of("kitti__000003") == "kitti"


def test_no_fit_sees_a_frame_of_its_held_out_group():
    groups = {g: [f"{g}{i}" for i in range(n)] for g, n in (("a", 3), ("b", 5), ("c", 1))}
    for k in (1, 3, 10, None):
        for seed in range(3):
            held = [g for g, _ in bench.splits(groups, k, seed)]
            assert held == ["a", "b", "c"]
            for g, pick in bench.splits(groups, k, seed):
                others = [s for h in groups if h != g for s in groups[h]]
                assert not set(pick) & set(groups[g])
                assert set(pick) <= set(others)
                want = len(others) if k is None else min(k, len(others))
                assert len(pick) == len(set(pick)) == want


def test_every_source_is_fitted_on_the_same_draws_and_the_gain_is_their_difference(monkeypatch):
    groups = {g: [f"{g}{i}" for i in range(4)] for g in "abc"}
    values = {s: {} for s in ("nidar", "geometry", "luminance")}
    fits: dict[tuple, list] = {}

    def fitted(train, vals, seed, source):
        fits.setdefault((seed, source), []).append(tuple(train))
        return source, tuple(train)

    def score(profile, scans, vals):
        if not isinstance(profile, tuple):  # a generic profile (K = 0): no fit frames
            return (0.2, 0.2)
        source, train = profile
        assert not set(train) & set(scans)  # the held-out frames are never fitted on
        return {"nidar": (0.6, 0.4), "geometry": (0.5, 0.25), "luminance": (0.1, 0.1)}[source]

    monkeypatch.setattr(bench, "fitted", fitted)
    monkeypatch.setattr(bench, "score", score)
    lines = list(bench.table(groups, values, [2, None], 2, extra_ks=[None]))
    for seed in range(2):  # one draw per group and seed, shared by the sources
        assert fits[(seed, "nidar")] == fits[(seed, "geometry")]
    assert fits[(0, "luminance")] == fits[(0, "nidar")][-3:]  # K = all only (one seed)
    assert (1, "luminance") not in fits
    generic = [_cells(ln) for ln in lines if "generic" in ln]
    assert [g[0] for g in generic] == ["NIDAR R"] * 2 + [
        "geometry only (R of a grey image)"
    ] * 2  # the closed forms read R maps only
    rows = [ln for ln in lines if "gbm" in ln]
    assert [_cells(r)[0] for r in rows] == [
        "NIDAR R",
        "geometry only (R of a grey image)",
        "**image gain** (NIDAR R − geometry only)",
        "NIDAR R",
        "geometry only (R of a grey image)",
        "luminance",
        "**image gain** (NIDAR R − geometry only)",
    ]
    assert _cells(rows[2])[3:7] == [
        "+0.100 ± 0.000",
        "+0.150 ± 0.000",
        "2",
        "+0.100/+0.150; +0.100/+0.150",
    ]
    assert _cells(rows[-1])[3:6] == ["+0.100", "+0.150", "1"]
