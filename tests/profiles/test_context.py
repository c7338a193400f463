"""The ``context`` profile form: fits on named inputs, survives its file, refuses what it cannot
read (the image it needs, a tampered file)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.profiles import SensorProfile, fit, load_profile
from nidar_mi.profiles.context import (
    QUANTILES,
    ContextFitOptions,
    ContextMap,
    train_context_booster,
    training_rows,
    weighted_quantiles,
)
from nidar_mi.profiles.inputs import GROUPS


def _data(n=6000, frames=3, seed=0):
    """Inputs of three groups and an intensity that depends on range, planarity and the
    pixel's luminance-like value: (context, intensity, frame)."""
    rng = np.random.default_rng(seed)
    ctx = {
        "range_m": rng.uniform(2, 60, n),
        "elevation_deg": rng.uniform(-24, 2, n),
        "cos_incidence": rng.uniform(0, 1, n),
        "planarity_k20": rng.uniform(0, 1, n),
        "r_lin": rng.uniform(0, 1, n),
        "R": rng.uniform(0, 1, n),
    }
    y = 0.5 * np.exp(-ctx["range_m"] / 30) + 0.3 * ctx["planarity_k20"] * ctx["r_lin"]
    y = np.clip(y + rng.normal(0, 0.01, n), 0, 1)
    return ctx, y, np.repeat(np.arange(frames), n // frames)


def _profile(kind="gbm", **options) -> SensorProfile:
    ctx, y, frame = _data()
    m = fit(
        "context", ctx["R"], ctx["range_m"], y, context=ctx | {"frame": frame}, kind=kind, **options
    )
    return SensorProfile(name="ctx", sensor="test", form="context", input="nidar:R", mapping=m)


@pytest.mark.parametrize("kind", ["gbm", "mlp"])
def test_fit_predict_and_the_file_round_trip(tmp_path, kind):
    """Fitted on three frames, the map follows the intensity on fresh returns; written and read
    back it predicts the same values, and the file names what it reads."""
    p = _profile(kind, trees=60)
    ctx, y, _ = _data(3000, seed=1)
    pred = p(ctx["R"], ctx["range_m"], context=ctx)
    assert pred.dtype == np.float32 and 0 <= pred.min() and pred.max() <= 1
    assert np.corrcoef(pred, y)[0, 1] > 0.95
    path = tmp_path / "ctx.json"
    p.save(path)
    data = json.loads(path.read_text())
    assert data["form"] == "context" and data["mapping"]["kind"] == kind
    assert data["mapping"]["groups"] == ["return", "geometry", "image", "nidar"]
    assert data["mapping"]["needs_image"] is True
    q = load_profile(path)
    np.testing.assert_array_equal(q(ctx["R"], ctx["range_m"], context=ctx), pred)
    assert q.reads_context and q.needs_image and q.mapping.features == p.mapping.features


def test_a_profile_that_reads_the_image_refuses_without_it():
    p = _profile(trees=20)
    ctx, _, _ = _data(100)
    without = {k: v for k, v in ctx.items() if k not in ("r_lin", "R")}
    with pytest.raises(NidarError, match="reads the camera image .image, nidar inputs"):
        p(ctx["R"], ctx["range_m"], context=without)
    with pytest.raises(NidarError, match="inputs missing: planarity_k20"):
        p(ctx["R"], ctx["range_m"], context={k: v for k, v in ctx.items() if k != "planarity_k20"})
    with pytest.raises(NidarError, match="reads the camera image"):
        p(ctx["R"], ctx["range_m"])
    # one that reads no image input needs none
    ctx2, y, frame = _data()
    geo = {k: ctx2[k] for k in ("range_m", "elevation_deg", "cos_incidence", "planarity_k20")}
    m = fit("context", ctx2["R"], ctx2["range_m"], y, context=geo | {"frame": frame}, trees=20)
    assert m.groups == ("return", "geometry") and not m.needs_image
    assert m(ctx2["R"], ctx2["range_m"], context=geo).shape == y.shape


def test_missing_inputs_take_their_branch_and_ranks_map_to_the_intensity_scale():
    """NaN inputs (no ring) are read as missing, not refused; a rank map's output follows the
    training intensities' quantiles (the same ranking on the sensor's scale)."""
    ctx, y, frame = _data()
    ctx = ctx | {"ring": np.where(np.arange(y.size) % 2 == 0, np.nan, 3.0)}
    m = fit(
        "context",
        ctx["R"],
        ctx["range_m"],
        y,
        context=ctx | {"frame": frame},
        target="rank",
        trees=30,
    )
    assert (
        len(m.quantiles) == QUANTILES and m.quantiles[0] == y.min() and m.quantiles[-1] == y.max()
    )
    out = m(ctx["R"], ctx["range_m"], context=ctx)
    assert np.all(np.isfinite(out)) and y.min() <= out.min() and out.max() <= y.max()
    assert "ring" in m.features and "ring" in m.groups


def test_weighted_quantiles_are_numpys_hazen_quantiles_for_equal_weights():
    """Equal weights give NumPy's ``hazen`` estimate; the weights' scale does not matter; weights
    move the quantiles as repeating the values would."""
    y = np.random.default_rng(3).gamma(2.0, 0.1, 517)
    levels = np.linspace(0, 1, QUANTILES)
    np.testing.assert_allclose(
        weighted_quantiles(y, np.ones_like(y), QUANTILES),
        np.quantile(y, levels, method="hazen"),
        rtol=0,
        atol=1e-12,
    )
    w = np.random.default_rng(4).uniform(0.1, 2.0, y.size)
    np.testing.assert_allclose(
        weighted_quantiles(y, w, QUANTILES),
        weighted_quantiles(y, 7.5 * w, QUANTILES),
        rtol=0,
        atol=1e-12,
    )
    # the upper half weighing three times the lower: the median is the unweighted 2/3 quantile
    heavy = np.where(y > np.median(y), 3.0, 1.0)
    q = weighted_quantiles(y, heavy, 3)
    assert abs(q[1] - np.quantile(y, 2 / 3)) < 0.01 * np.ptp(y)


def test_a_blend_map_is_the_mean_of_its_two_regressions(tmp_path):
    """A ``blend`` map returns (F_I + Q(F_u)) / 2 of two regressions fitted on the same rows (the
    intensity's and the per-frame rank's, Q the weighted quantiles of the intensities), survives
    its file, and is refused with the small head."""
    ctx, y, frame = _data()
    groups = np.where(frame == 0, "a", "b")
    m = fit(
        "context",
        ctx["R"],
        ctx["range_m"],
        y,
        context=ctx | {"frame": frame, "group": groups},
        target="blend",
        trees=30,
        points_per_frame=1500,
    )
    o = ContextFitOptions(trees=30, points_per_frame=1500)
    feats = m.features
    x = np.column_stack([ctx[f] for f in feats])
    parts = [np.flatnonzero(frame == f) for f in range(3)]
    labels = ["a", "b", "b"]
    xt, yt, wt = training_rows([x[p] for p in parts], [y[p] for p in parts], o, labels)
    ranks = [(np.argsort(np.argsort(y[p])) / (p.size - 1)) for p in parts]
    _, ut, _ = training_rows([x[p] for p in parts], ranks, o, labels)
    level = train_context_booster(xt, yt, feats, o, wt).predict(x)
    rank = np.clip(train_context_booster(xt, ut, feats, o, wt).predict(x), 0, 1)
    grid = np.linspace(0, 1, QUANTILES)
    expected = 0.5 * (level + np.interp(rank, grid, weighted_quantiles(yt, wt, QUANTILES)))
    got = m(ctx["R"], ctx["range_m"], context=ctx)
    np.testing.assert_allclose(got, np.clip(expected, 0, 1), rtol=0, atol=1e-12)
    assert np.corrcoef(got, y)[0, 1] > 0.95
    back = ContextMap.from_dict(json.loads(json.dumps(m.to_dict())))
    np.testing.assert_array_equal(back(ctx["R"], ctx["range_m"], context=ctx), got)
    with pytest.raises(NidarError, match="'blend' needs kind 'gbm'"):
        ContextFitOptions(target="blend", kind="mlp")
    data = m.to_dict()
    data.pop("rank_model")
    with pytest.raises(NidarError, match="'rank_model' belongs to"):
        ContextMap.from_dict(data)


def test_a_tampered_or_malformed_file_is_refused(tmp_path):
    p = _profile(trees=10)
    good = p.to_dict()

    def load(change):
        data = json.loads(json.dumps(good))
        change(data["mapping"])
        path = tmp_path / "bad.json"
        path.write_text(json.dumps(data))
        return load_profile(path)

    with pytest.raises(NidarError, match="'groups' do not match"):
        load(lambda m: m.update(groups=["return"]))
    with pytest.raises(NidarError, match="'needs_image' does not match"):
        load(lambda m: m.update(needs_image=False))
    with pytest.raises(NidarError, match="unknown profile input"):
        load(lambda m: m.update(features=[*m["features"][:-1], "colour"]))
    with pytest.raises(NidarError, match="not a regression on"):
        load(lambda m: m.update(features=m["features"][::-1]))
    with pytest.raises(NidarError, match="unknown key"):
        load(lambda m: m.update(pickle="x"))
    h = _profile("mlp").to_dict()
    data = json.loads(json.dumps(h))
    data["mapping"]["head"]["layers"][1]["weight"] = [[1.0, 2.0]]
    path = tmp_path / "head.json"
    path.write_text(json.dumps(data))
    with pytest.raises(NidarError, match="do not chain"):
        load_profile(path)


def test_fit_refuses_what_it_cannot_read():
    ctx, y, frame = _data(200)
    with pytest.raises(NidarError, match="named inputs"):
        fit("context", ctx["R"], ctx["range_m"], y)
    with pytest.raises(NidarError, match="only a context profile reads named inputs"):
        fit("gbm", ctx["R"], ctx["range_m"], y, elevation_deg=ctx["elevation_deg"], context=ctx)
    with pytest.raises(NidarError, match="kind must be one of"):
        fit("context", ctx["R"], ctx["range_m"], y, context=ctx, kind="forest")
    with pytest.raises(NidarError, match="unknown profile input"):
        fit("context", ctx["R"], ctx["range_m"], y, context=ctx, features=("range_m", "x"))
    assert set(GROUPS) == {"return", "ring", "geometry", "image", "image_rel", "nidar"}
    assert ContextMap.reads_context


def test_the_exposure_divided_inputs_only_when_named():
    """By default a context map reads the inputs of DEFAULT_GROUPS the data give (the recipe
    measured leave one group out), not the image's exposure-divided copies; named, it reads
    them."""
    from nidar_mi.profiles.inputs import DEFAULT_GROUPS, DEFAULT_INPUTS

    ctx, y, frame = _data(1500)
    ctx = ctx | {"g_rel": ctx["r_lin"] * 2.0, "ring": np.zeros(len(y))}
    m = fit("context", ctx["R"], ctx["range_m"], y, context=ctx | {"frame": frame}, trees=5)
    order = ("range_m", "elevation_deg", "cos_incidence", "ring", "planarity_k20", "r_lin", "R")
    assert m.features == order
    assert set(m.features) <= set(DEFAULT_INPUTS) and "image_rel" not in DEFAULT_GROUPS
    named = (*m.features, "g_rel")
    m = fit(
        "context",
        ctx["R"],
        ctx["range_m"],
        y,
        context=ctx | {"frame": frame},
        trees=5,
        features=named,
    )
    assert m.features == named and "image_rel" in m.groups and m.needs_image


def test_frame_weights_give_each_group_an_equal_share():
    """Groups of 3 and 1 frames: each group half the weight, shared by its frames."""
    from nidar_mi.profiles.context import frame_weights

    np.testing.assert_allclose(frame_weights(["a", "a", "a", "b"], 4), [1 / 6, 1 / 6, 1 / 6, 0.5])
    np.testing.assert_allclose(frame_weights(None, 4), [0.25] * 4)
    assert frame_weights([0, 1, 1, 2, 2, 2], 6).sum() == pytest.approx(1.0)


@pytest.mark.parametrize("kind", ["gbm", "mlp"])
def test_a_long_recording_does_not_outweigh_a_short_one(kind):
    """Two recordings that disagree, read through one input: nine frames where I = 0.2 and one
    where I = 0.8. Least squares on the intensity predicts the weighted mean: 0.5 when each
    recording weighs the same (``balance="group"``), 0.9·0.2 + 0.1·0.8 = 0.26 when each frame
    does."""
    rng = np.random.default_rng(0)
    frames, per = 10, 400
    n = frames * per
    frame = np.repeat(np.arange(frames), per)
    group = np.where(frame < 9, 7, 3)
    ctx = {"range_m": rng.uniform(2, 60, n)}
    y = np.where(group == 7, 0.2, 0.8)
    expected = {"group": 0.5, "frame": 0.26}
    for balance, want in expected.items():
        m = fit(
            "context",
            ctx["range_m"],
            ctx["range_m"],
            y,
            context=ctx | {"frame": frame, "group": group},
            kind=kind,
            balance=balance,
            target="intensity",
            trees=50,
        )
        pred = m(ctx["range_m"], ctx["range_m"], context=ctx)
        assert np.median(pred) == pytest.approx(want, abs=0.02), balance
        assert m.params["balance"] == balance and m.params["groups"] == 2


def test_a_frame_in_two_groups_is_refused():
    ctx = {"range_m": np.linspace(2, 50, 400)}
    frame = np.repeat([0, 1], 200)
    group = np.repeat([0, 1, 1, 1], 100)  # frame 0 half in group 0, half in group 1
    with pytest.raises(NidarError, match="one frame carry different group labels"):
        fit(
            "context",
            ctx["range_m"],
            ctx["range_m"],
            np.full(400, 0.5),
            context=ctx | {"frame": frame, "group": group},
        )
