"""The compiled walk of a LightGBM regression's trees: LightGBM's own predictions, bit for bit,
on the values its rules treat specially (missing, zero, on a threshold), in any thread split."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.profiles import forest
from nidar_mi.profiles.context import ContextFitOptions as Options
from nidar_mi.profiles.context import ContextMap, _params
from nidar_mi.profiles.gbm import load_booster

pytest.importorskip("numba")
FEATS = ("range_m", "cos_incidence", "planarity_k20", "R")


def _booster(missing=True, seed=0):
    """LightGBM trees of 4 inputs, one of them half missing (NaN) in training; ``missing``:
    splits of missing type NaN (a missing value goes the learnt way), else None (read as 0)."""
    lgb = pytest.importorskip("lightgbm")
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 1, (3000, 4))
    x[:, 0] *= 60
    x[rng.uniform(size=3000) < 0.5, 2] = np.nan
    x[:, 1] *= rng.choice([-1.0, 0.0, 1.0], 3000)  # zeros: LightGBM splits at ±its zero
    y = np.exp(-x[:, 0] / 30) + np.nan_to_num(x[:, 2], nan=0.7) * x[:, 3] + np.sign(x[:, 1])
    o = Options(features=FEATS, trees=60, leaves=31, min_leaf=20, seed=seed)
    params = _params(o) | {"use_missing": missing}
    return lgb.train(params, lgb.Dataset(x, label=y, feature_name=list(FEATS)), num_boost_round=60)


def _hard_inputs(booster, n=4000, seed=1) -> np.ndarray:
    """Inputs that hit LightGBM's special cases: missing values, zeros of either sign, values
    below its zero threshold, and each split's exact threshold."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-5, 65, (n, 4))
    thresholds = _thresholds(booster)
    pick = rng.integers(0, len(thresholds), n)
    rows = rng.uniform(size=n) < 0.5
    for i in np.flatnonzero(rows):
        f, t = thresholds[pick[i]]
        x[i, f] = t
    x[rng.uniform(size=x.shape) < 0.1] = np.nan
    x[rng.uniform(size=x.shape) < 0.03] = 0.0
    x[rng.uniform(size=x.shape) < 0.03] = -0.0
    for v in (1e-40, -3e-36, forest.ZERO, -forest.ZERO, 1.5 * forest.ZERO, -1.5 * forest.ZERO):
        x[rng.uniform(size=x.shape) < 0.03] = v
    return x


def _thresholds(booster) -> list[tuple[int, float]]:
    """``(feature, threshold)`` of every split of a booster."""
    out = []
    for tree in booster.dump_model()["tree_info"]:
        stack = [tree["tree_structure"]]
        while stack:
            node = stack.pop()
            if "threshold" in node:
                out.append((node["split_feature"], node["threshold"]))
                stack += [node["left_child"], node["right_child"]]
    return out


@pytest.mark.parametrize("missing", [True, False])
def test_the_forest_equals_lightgbm_bit_for_bit(missing):
    """On 4000 rows with NaN, ±0, values at and about LightGBM's zero threshold and exact
    split thresholds, the compiled
    walk gives LightGBM's predictions exactly, with NaN-typed splits (a missing value goes the
    learnt way) and with None-typed ones (read as 0), and the same in one thread or three."""
    text = _booster(missing).model_to_string()
    kinds = {
        v for ln in text.split("\n") if ln.startswith("decision_type=") for v in ln[14:].split()
    }
    assert kinds & {"8", "10"} if missing else kinds <= {"0", "2"}  # NaN-typed splits or none
    b = load_booster(text, FEATS, missing=True)
    assert -forest.ZERO in [t for _, t in _thresholds(b)]  # LightGBM's split below zero
    f = forest.compile_forest(text, len(FEATS))
    assert f is not None and len(f.root) == b.num_trees()
    x = _hard_inputs(b)
    want = b.predict(x, num_threads=1)
    np.testing.assert_array_equal(f(x), want)
    np.testing.assert_array_equal(f(x, threads=3), want)
    np.testing.assert_array_equal(f(x[:5]), want[:5])
    assert f(x[:0]).shape == (0,)


def test_a_context_map_predicts_with_or_without_the_compiled_walk(monkeypatch):
    """A ``context`` map's trees give the same intensities through the compiled walk as through
    LightGBM (without numba: ``compile_forest`` gives None)."""
    b = _booster()
    m = ContextMap(features=FEATS, target="intensity", model=b.model_to_string())
    x = _hard_inputs(b, 500)
    ctx = dict(zip(FEATS, x.T, strict=True))
    fast = m(x[:, 3], x[:, 0], context=ctx)
    monkeypatch.setattr(forest, "_compiled", lambda: None)
    assert forest.compile_forest(b.model_to_string(), 4) is None
    slow = ContextMap(features=FEATS, target="intensity", model=b.model_to_string())
    np.testing.assert_array_equal(slow(x[:, 3], x[:, 0], context=ctx), fast)
    np.testing.assert_array_equal(fast, np.clip(b.predict(x), 0.0, 1.0))


def test_a_model_not_a_plain_sum_goes_to_lightgbm():
    """A transformed output (``regression sqrt``) is not compiled."""
    text = _booster().model_to_string().replace("objective=regression", "objective=regression sqrt")
    assert forest.compile_forest(text, len(FEATS)) is None


def test_a_tree_of_one_leaf():
    """A model whose only tree is one leaf (no split met the fewest returns per leaf) predicts
    that leaf's value, as LightGBM does."""
    lgb = pytest.importorskip("lightgbm")
    rng = np.random.default_rng(0)
    x = rng.uniform(size=(500, 4))
    params = {"objective": "regression", "num_leaves": 4, "min_data_in_leaf": 400, "verbose": -1}
    data = lgb.Dataset(x, label=x[:, 0] > 0.5, feature_name=list(FEATS))
    b = lgb.train(params, data, num_boost_round=3)
    text = b.model_to_string()
    assert "num_leaves=1\n" in text
    b = load_booster(text, FEATS, missing=True)
    f = forest.compile_forest(text, len(FEATS))
    np.testing.assert_array_equal(f(x), b.predict(x))
    assert np.ptp(f(x)) == 0.0
