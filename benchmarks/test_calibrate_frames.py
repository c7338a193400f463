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
    from nidar_mi.eval.baselines import LinearNIR
    from nidar_mi.io.images import srgb_to_linear

    blue = LinearNIR(weights=np.array([0.0, 0.0, 1.0, 0.0]))  # the linear blue channel
    values = bench.source_values(model, scans, list(bench.VALUE_SOURCES), linear_nir=blue)
    v = np.arange(2, H - 2)
    u = v + 3
    from nidar_mi.eval.image_cues import GREY_LEVEL, luminance

    a = {s: values[s]["kitti__a"] for s in bench.VALUE_SOURCES}
    n = len(v) + 1
    for s in bench.VALUE_SOURCES:  # one value per return, a colour for the colour sources
        if s in bench.FEATURE_SOURCES:
            assert a[s].shape == (n, len(bench.IMAGE_FEATURES))
        else:
            assert a[s].shape == ((n, 3) if s in bench.COLOUR_SOURCES else (n,))
    # returns at pixel centres read the pixel; the one behind the camera has no value
    np.testing.assert_allclose(a["nidar"][:-1], rgb[v, u, 0] / 255.0, atol=1e-6)
    np.testing.assert_allclose(a["stn"][:-1], rgb[v, u, 1] / 255.0, atol=1e-6)
    np.testing.assert_allclose(a["luminance"][:-1], luminance(rgb)[v, u], atol=1e-6)
    np.testing.assert_allclose(a["geometry"][:-1], GREY_LEVEL / 255.0, atol=1e-6)
    want_nir = srgb_to_linear(rgb[v, u, 2].astype(np.float32) / 255.0)
    np.testing.assert_allclose(a["linnir"][:-1], want_nir, atol=1e-6)
    for s in bench.COLOUR_SOURCES:
        np.testing.assert_allclose(a[s][:-1], rgb[v, u] / 255.0, atol=1e-6)
    feats = dict(zip(bench.IMAGE_FEATURES, a["image_gbm"][:-1].T, strict=True))
    lin = srgb_to_linear(rgb.astype(np.float64) / 255.0)
    np.testing.assert_allclose(feats["g_lin"], lin[v, u, 1], atol=1e-6)
    np.testing.assert_allclose(feats["R"], rgb[v, u, 0] / 255.0, atol=1e-6)
    np.testing.assert_allclose(feats["S"], rgb[v, u, 2] / 255.0, atol=1e-6)
    np.testing.assert_allclose(feats["pseudo_nir"], rgb[v, u, 1] / 255.0, atol=1e-6)
    w = bench.CONTEXT_WINDOWS[0]  # the window's mean, the image's edge repeated beyond it
    pad = np.pad(lin, ((w // 2, w // 2), (w // 2, w // 2), (0, 0)), mode="edge")
    box = np.array([pad[i : i + w, j : j + w].reshape(-1, 3) for i, j in zip(v, u)])
    np.testing.assert_allclose(feats[f"b_mean{w}"], box[:, :, 2].mean(axis=1), atol=1e-5)
    lum = box @ np.array([0.2126, 0.7152, 0.0722])
    np.testing.assert_allclose(feats[f"lum_sd{w}"], lum.std(axis=1), atol=1e-4)
    for s in bench.VALUE_SOURCES:
        assert np.all(np.isnan(a[s][-1]))
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


def _cloud(name: str, seed: int, n: int = 3000):
    """A scan of ``n`` returns at random directions and ranges (no camera), with the (N, 3)
    colour at each (the last 10 returns unseen: NaN) and its incidence cosine set."""
    from nidar_mi.datasets.scans import ScanFrame

    rng = np.random.default_rng(seed)
    d = rng.uniform(3.0, 60.0, n)
    el = np.radians(rng.uniform(-20.0, 2.0, n))
    az = rng.uniform(-0.7, 0.7, n)
    xyz = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1) * d[:, None]
    colour = rng.uniform(0.0, 1.0, (n, 3))
    colour[-10:] = np.nan
    scan = ScanFrame(name, xyz, np.zeros(n), np.full(n, -1, np.int16), cameras=[])
    scan.__dict__["cos_incidence"] = rng.uniform(0.05, 1.0, n)
    return scan, colour


def _clouds_with(law, count: int, seed: int):
    """``count`` synthetic scans (:func:`_cloud`, seeds ``seed``, ``seed + 1``, ...) whose
    intensity ``law(scan, colour)`` sets, and their colours by scan name."""
    scans, values = [], {}
    for i in range(count):
        scan, colour = _cloud(f"kitti__{i}", seed + i)
        law(scan, colour)
        scans.append(scan)
        values[scan.name] = colour
    return scans, values


def test_linear_colour_distance_recovers_a_linear_law_exactly():
    from nidar_mi.eval.baselines import colour_distance_features

    w = np.array([0.2, 0.1, -0.05, 0.1, 0.05, 0.0, 0.03, -0.1, 0.2])

    def law(scan, colour):
        ok = bench._seen(colour)
        scan.intensity[ok] = colour_distance_features(colour[ok], scan.range_m[ok]) @ w
        assert 0.0 < scan.intensity[ok].min() and scan.intensity[ok].max() < 1.0

    scans, values = _clouds_with(law, count=4, seed=0)
    predict = bench.fitted(scans[:3], values, 0, "lin9")
    held = scans[3]
    ok = bench._seen(values[held.name])
    pred = predict(held, values[held.name], ok)
    assert pred.shape == (ok.sum(),) == (len(ok) - 10,)
    np.testing.assert_allclose(pred, held.intensity[ok], atol=1e-9)
    assert bench.score(predict, [held], values) == (1.0, 1.0)


def test_colour_gbm_reads_the_colour_with_the_recipes_settings():
    from nidar_mi.io.images import srgb_to_linear

    def law(scan, colour):  # the red channel ranks the intensity; range and incidence shade it
        lin = srgb_to_linear(np.nan_to_num(colour))
        scan.intensity[:] = 0.6 * lin[:, 0] * scan.cos_incidence + 0.2 * np.exp(-scan.range_m / 40)

    scans, values = _clouds_with(law, count=3, seed=10)
    predict = bench.fitted(scans[:2], values, 0, "colour_gbm")
    held = scans[2]
    ok = bench._seen(values[held.name])
    pred = predict(held, values[held.name], ok)
    assert pred.shape == (ok.sum(),) and np.all((0.0 <= pred) & (pred <= 1.0))
    rho, _ = bench.score(predict, [held], values)
    assert rho > 0.9
    x = bench.colour_design(held, values[held.name], ok)
    assert x.shape == (ok.sum(), len(bench.COLOUR_GBM_FEATURES))
    np.testing.assert_allclose(x[:, 0], srgb_to_linear(values[held.name][ok, 0]))
    np.testing.assert_allclose(
        x[:, 3:], np.c_[held.range_m, held.elevation_deg, held.cos_incidence][ok]
    )
    # the same draws and seed give the same model
    again = bench.fitted(scans[:2], values, 0, "colour_gbm")
    np.testing.assert_array_equal(again(held, values[held.name], ok), pred)


def test_image_gbm_reads_every_feature():
    """A law that only a context feature and NIDAR's S set: the image gbm ranks it on a frame no
    fit saw; the colour gbm, which reads the colour at the return only, cannot."""
    f = len(bench.IMAGE_FEATURES)
    col = {k: i for i, k in enumerate(bench.IMAGE_FEATURES)}

    def law(scan, colour):
        rng = np.random.default_rng(len(scan.name) + int(scan.name[-1]))
        feats = rng.uniform(0.0, 1.0, (len(colour), f))
        feats[-10:] = np.nan
        scan.__dict__["features"] = feats
        x = np.nan_to_num(feats)
        scan.intensity[:] = 0.5 * x[:, col["g_mean61"]] * scan.cos_incidence + 0.3 * x[:, col["S"]]

    scans, _ = _clouds_with(law, count=3, seed=20)
    values = {s.name: s.__dict__["features"] for s in scans}
    predict = bench.fitted(scans[:2], values, 0, "image_gbm")
    held = scans[2]
    ok = bench._seen(values[held.name])
    assert ok.sum() == len(ok) - 10
    pred = predict(held, values[held.name], ok)
    rho, _ = bench.score(predict, [held], values)
    assert rho > 0.9 and np.all((0.0 <= pred) & (pred <= 1.0))
    x = bench.feature_design(held, values[held.name], ok)
    assert x.shape == (ok.sum(), len(bench.IMAGE_GBM_FEATURES))
    np.testing.assert_array_equal(x[:, :f], values[held.name][ok])
    np.testing.assert_array_equal(x[:, -1], held.cos_incidence[ok])
    colours = {n: v[:, :3] for n, v in values.items()}  # the linear colour columns alone
    colour_only = bench.fitted(scans[:2], colours, 0, "colour_gbm")
    assert bench.score(colour_only, [held], colours)[0] < 0.5


def test_the_colour_and_feature_gain_rows_pair_their_gbm_with_geometry_only(monkeypatch):
    groups = {g: [f"{g}{i}" for i in range(4)] for g in "ab"}
    values = {s: {} for s in ("geometry", "lin9", "colour_gbm", "image_gbm")}
    scores = {
        "geometry": (0.5, 0.25),
        "lin9": (0.3, 0.1),
        "colour_gbm": (0.56, 0.33),
        "image_gbm": (0.52, 0.24),
    }
    monkeypatch.setattr(bench, "fitted", lambda train, vals, seed, source: source)
    monkeypatch.setattr(bench, "score", lambda p, scans, vals: scores.get(p, (0.2, 0.2)))
    rows = [_cells(ln) for ln in bench.table(groups, values, [3], 2) if "| 3 |" in ln]
    assert [r[:2] for r in rows] == [
        ["geometry only (R of a grey image)", bench.RECIPE],
        ["(h) linear colour + distance", bench.PREDICTORS["lin9"]],
        ["colour gbm (diagnostic)", bench.PREDICTORS["colour_gbm"]],
        ["image gbm (diagnostic)", bench.PREDICTORS["image_gbm"]],
        ["**colour gain** (colour gbm − geometry only)", bench.PREDICTORS["colour_gbm"]],
        ["**image-feature gain** (image gbm − geometry only)", bench.PREDICTORS["image_gbm"]],
    ]
    assert rows[-2][3:6] == ["+0.060 ± 0.000", "+0.080 ± 0.000", "2"]
    assert rows[-1][3:6] == ["+0.020 ± 0.000", "-0.010 ± 0.000", "2"]
