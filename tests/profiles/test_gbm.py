"""The ``gbm`` sensor-profile form: accuracy on a known response, the monotone constraint,
round trips, determinism, and corrupt files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.profiles import GbmMap, fit, load_profile
from tests.helpers.profiles import fitted_profile


def _truth(v, d, e):
    """A sensor response: linear in the value, falling with range, a bump over elevation."""
    return 0.1 + 0.5 * v * np.exp(-d / 40.0) + 0.1 * np.sin(e / 5.0)


def _geometry(n, rng):
    return rng.uniform(2, 60, n), rng.uniform(-24, 2, n)


def _sample(n=100_000, seed=0, noise=0.05, f=_truth):
    rng = np.random.default_rng(seed)
    v = rng.uniform(0, 1, n)
    d, e = _geometry(n, rng)
    return v, d, e, f(v, d, e) + rng.normal(0, noise, n)


def _grid(f):
    v, d, e = np.meshgrid(
        np.linspace(0.05, 0.95, 10), np.linspace(5, 55, 11), np.linspace(-22, 0, 12), indexing="ij"
    )
    v, d, e = v.ravel(), d.ravel(), e.ravel()
    return v, d, e, f(v, d, e)


def test_recovers_a_known_response():
    """Fitted on 100 000 noisy returns (noise σ 0.05) the map is within 0.01 of the response on
    average and within 0.04 everywhere on a grid inside the training domain."""
    v, d, e, y = _sample()
    m = fit("gbm", v, d, y, elevation_deg=e)
    gv, gd, ge, truth = _grid(_truth)
    err = np.abs(m(gv, gd, elevation_deg=ge) - truth)
    assert err.mean() < 0.01 and err.max() < 0.04, (err.mean(), err.max())
    assert m.n_trees == 200 and m.uses_value and m.monotone


def test_geometry_only_ignores_the_value():
    def f(v, d, e):
        return 0.6 * np.exp(-d / 30.0) + 0.005 * (e + 24)

    v, d, e, y = _sample(f=f)
    m = fit("gbm", v, d, y, elevation_deg=e, use_value=False)
    assert m.features == ("range_m", "elevation_deg") and not m.uses_value
    gv, gd, ge, truth = _grid(f)
    out = m(gv, gd, elevation_deg=ge)
    np.testing.assert_array_equal(out, m(np.zeros_like(gv), gd, elevation_deg=ge))
    assert np.abs(out - truth).mean() < 0.01


def _dip(v, d, e):
    """A response that falls with the value over (0.6, 0.8): the constraint must overrule it."""
    return 0.2 + 0.6 * v - 0.9 * np.clip(v - 0.6, 0, 0.2) + 0.0 * d + 0.0 * e


def test_monotone_in_the_value_when_constrained():
    v, d, e, y = _sample(60_000, noise=0.02, f=_dip)
    vs = np.linspace(0, 1, 101)
    gd, ge = np.meshgrid(np.linspace(3, 58, 8), np.linspace(-23, 1, 8))
    rows = [(np.full(101, a), np.full(101, b)) for a, b in zip(gd.ravel(), ge.ravel())]
    constrained = fit("gbm", v, d, y, elevation_deg=e, trees=60)
    free = fit("gbm", v, d, y, elevation_deg=e, trees=60, monotone=False)
    for dd, ee in rows:
        assert np.all(np.diff(constrained(vs, dd, elevation_deg=ee)) >= 0)
    # without the constraint the same data give a map that falls (by ~0.06 from v = 0.6 to
    # 0.8): the check above can fail
    for dd, ee in rows:
        y_free = free(vs, dd, elevation_deg=ee)
        assert y_free[80] < y_free[60] - 0.03


def test_output_is_clipped_to_the_sensor_range():
    v, d, e, _ = _sample(20_000)
    y = 1.6 * v - 0.3  # a response that runs past [0, 1] at both ends
    m = fit("gbm", v, d, y, elevation_deg=e, trees=50)
    out = m(np.linspace(0, 1, 500), np.full(500, 20.0), elevation_deg=np.full(500, -5.0))
    assert out.min() == 0 and out.max() == 1 and np.all((out >= 0) & (out <= 1))
    assert np.sum(out == 0) > 50 and np.sum(out == 1) > 50


def _profile(**options):
    v, d, e, y = _sample(30_000)
    return fitted_profile(
        v,
        d,
        y,
        form="gbm",
        name="g-1",
        sensor="x",
        input="nidar:R",
        elevation_deg=e,
        **({"trees": 40} | options),
    )


def test_json_round_trip_gives_identical_predictions(tmp_path):
    p = _profile()
    p.save(tmp_path / "p.json")
    q = load_profile(tmp_path / "p.json")
    assert q.form == "gbm" and q.mapping.model == p.mapping.model
    v, d, e, _ = _sample(5000, seed=1)
    out = p(v, d, elevation_deg=e)
    assert out.dtype == np.float32
    np.testing.assert_array_equal(q(v, d, elevation_deg=e), out)
    size = (tmp_path / "p.json").stat().st_size
    assert size < 1_000_000
    # the shipped size bound: 200 trees of 31 leaves stay under 1 MB
    assert len(json.dumps(_profile(trees=200).to_dict())) < 1_000_000


def test_same_seed_same_model_text():
    v, d, e, y = _sample(20_000)
    a = fit("gbm", v, d, y, elevation_deg=e, trees=30, max_samples=10_000, seed=3)
    b = fit("gbm", v, d, y, elevation_deg=e, trees=30, max_samples=10_000, seed=3)
    c = fit("gbm", v, d, y, elevation_deg=e, trees=30, max_samples=10_000, seed=4)
    assert a.model == b.model and a.model != c.model


def test_needs_elevations_and_finite_inputs():
    p = _profile()
    with pytest.raises(NidarError, match="elevations are needed"):
        p([0.5], [10.0])
    with pytest.raises(NidarError, match="finite"):
        p([0.5], [10.0], elevation_deg=[np.nan])


def _corruptions(text: str, n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    body = text.index("Tree=0")
    for _ in range(n):
        i = int(rng.integers(body, len(text) - 1))
        kind = rng.integers(3)
        if kind == 0:
            yield text[:i] + text[i + 1 :]
        elif kind == 1:
            yield text[:i] + chr(int(rng.integers(32, 127))) + text[i + 1 :]
        else:
            yield text[:i] + "9" + text[i:]


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda m: m | {"model": "tree\nversion=v4\n"}, "not a LightGBM text model"),
        (lambda m: m | {"model": 3}, "LightGBM's text model"),
        (lambda m: m | {"features": ["range_m", "v"]}, "features must be"),
        (lambda m: m | {"features": ["range_m", "elevation_deg"]}, "not a regression on"),
        (lambda m: m | {"pickle": "x"}, "unknown key"),
        (lambda m: {k: v for k, v in m.items() if k != "model"}, "missing key"),
        (
            lambda m: m | {"model": m["model"].replace("num_leaves=", "num_leaves=x", 1)},
            "tree_sizes",
        ),
        (
            lambda m: m | {"model": m["model"].replace("objective=regression", "objective=binary")},
            "not a regression",
        ),
    ],
)
def test_corrupt_files_are_one_line_errors(tmp_path, edit, message):
    data = _profile().to_dict()
    data["mapping"] = edit(data["mapping"])
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(NidarError, match=message) as info:
        load_profile(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_random_corruptions_never_crash_the_parser():
    """LightGBM's own parser aborts the process on some malformed texts; every corrupted text
    is either refused in one line or still a valid model."""
    m = fit("gbm", *_sample(5000)[:2], _sample(5000)[3], elevation_deg=_sample(5000)[2], trees=10)
    data = m.to_dict()
    refused = 0
    for bad in _corruptions(data["model"], 300):
        try:
            GbmMap.from_dict(data | {"model": bad})
        except NidarError as e:
            assert "\n" not in str(e)
            refused += 1
    assert refused > 250


def test_a_corrupt_profile_file_is_a_one_line_cli_error(tmp_path, capsys):
    """What ``assign --profile FILE`` and ``render --profile FILE`` do with the file, through the
    commands' runner: one ``error:`` line naming the file, exit status 2, no traceback."""
    from nidar_mi.cli._common import run
    from nidar_mi.datasets.sensor_profiles import resolve_profile

    data = _profile().to_dict()
    data["mapping"]["model"] = data["mapping"]["model"].replace("Tree=1", "Tree=2", 1)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    code = run(lambda: resolve_profile(str(bad), model=None))
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert lines[0].startswith("error:") and str(bad) in lines[0] and "gbm: tree 1" in lines[0]


def _lambert(v, d, e, c):
    """A diffuse surface's compensated return: reflectance times the incidence cosine."""
    return 0.8 * v * c + 0.0 * d + 0.0 * e


def _incidence_sample(n=60_000, seed=0, noise=0.02):
    rng = np.random.default_rng(seed)
    v, c = rng.uniform(0, 1, n), rng.uniform(0, 1, n)
    d, e = _geometry(n, rng)
    return v, d, e, c, _lambert(v, d, e, c) + rng.normal(0, noise, n)


def test_incidence_aware_map_recovers_lamberts_law():
    """I = 0.8 ρ cos θ: with the incidence the map is within 0.02 of the law on average; without
    it the same returns leave the cos θ spread unexplained (mean error ≈ 0.8·v·E|c − ½| ≥ 0.08
    in the mean over the grid), and the map is non-decreasing in cos θ (constrained)."""
    v, d, e, c, y = _incidence_sample()
    m = fit("gbm", v, d, y, elevation_deg=e, cos_incidence=c, trees=100)
    assert m.features == ("v", "range_m", "elevation_deg", "cos_incidence") and m.uses_incidence
    flat = fit("gbm", v, d, y, elevation_deg=e, trees=100)
    g = np.random.default_rng(5)
    gv, gc = g.uniform(0.05, 0.95, 5000), g.uniform(0.05, 0.95, 5000)
    gd, ge = _geometry(5000, g)
    truth = _lambert(gv, gd, ge, gc)
    assert np.abs(m(gv, gd, elevation_deg=ge, cos_incidence=gc) - truth).mean() < 0.02
    assert np.abs(flat(gv, gd, elevation_deg=ge) - truth).mean() > 0.08
    cs = np.linspace(0, 1, 101)
    for vv in (0.1, 0.5, 0.9):
        out = m(
            np.full(101, vv), np.full(101, 20.0), elevation_deg=np.full(101, -5.0), cos_incidence=cs
        )
        assert np.all(np.diff(out) >= 0)


def test_incidence_profile_round_trip_and_checks(tmp_path):
    v, d, e, c, y = _incidence_sample(20_000)
    p = fitted_profile(
        v, d, y, form="gbm", name="inc", sensor="x", input="nidar:R",
        elevation_deg=e, cos_incidence=c, trees=30,
    )  # fmt: skip
    assert p.uses_incidence and not _profile().uses_incidence
    p.save(tmp_path / "p.json")
    q = load_profile(tmp_path / "p.json")
    assert q.uses_incidence
    np.testing.assert_array_equal(q(v[:500], d[:500], elevation_deg=e[:500], cos_incidence=c[:500]),
                                  p(v[:500], d[:500], elevation_deg=e[:500], cos_incidence=c[:500]))  # fmt: skip
    with pytest.raises(NidarError, match="reads the returns' incidence"):
        p(v[:5], d[:5], elevation_deg=e[:5])
    with pytest.raises(NidarError, match=r"in \[0, 1\]"):
        p(v[:2], d[:2], elevation_deg=e[:2], cos_incidence=[0.5, 1.5])
    with pytest.raises(NidarError, match="differ in length"):
        p(v[:2], d[:2], elevation_deg=e[:2], cos_incidence=[0.5])
    with pytest.raises(NidarError, match="only a gbm or physical profile reads the incidence"):
        fitted_profile(v, d, y, form="range_ring", name="r", sensor="x", input="nidar:R",
                    elevation_deg=e, cos_incidence=c)  # fmt: skip
    # a map without the incidence ignores one given
    np.testing.assert_array_equal(
        _profile()(v[:50], d[:50], elevation_deg=e[:50], cos_incidence=c[:50]),
        _profile()(v[:50], d[:50], elevation_deg=e[:50]),
    )


def test_value_and_incidence_map_recovers_lamberts_law_without_the_geometry(tmp_path):
    """``use_geometry=False``: features (v, cos θ) only. On I = 0.8 ρ cos θ it is within 0.02
    of the law on average, its output does not move with range or elevation (none given at
    all), it round-trips through a profile file, and it cannot be asked without the value or
    the incidence."""
    v, d, e, c, y = _incidence_sample()
    m = fit("gbm", v, d, y, elevation_deg=e, cos_incidence=c, use_geometry=False, trees=100)
    assert m.features == ("v", "cos_incidence") and not m.uses_geometry and m.uses_incidence
    g = np.random.default_rng(6)
    gv, gc = g.uniform(0.05, 0.95, 5000), g.uniform(0.05, 0.95, 5000)
    gd, ge = _geometry(5000, g)
    out = m(gv, gd, cos_incidence=gc)
    assert np.abs(out - _lambert(gv, gd, ge, gc)).mean() < 0.02
    np.testing.assert_array_equal(out, m(gv, gd[::-1], elevation_deg=ge, cos_incidence=gc))
    p = fitted_profile(
        v, d, y, form="gbm", name="vc", sensor="x", input="nidar:R",
        elevation_deg=None, cos_incidence=c, trees=30, use_geometry=False,
    )  # fmt: skip
    p.save(tmp_path / "vc.json")
    q = load_profile(tmp_path / "vc.json")
    np.testing.assert_array_equal(q(gv, gd, cos_incidence=gc), p(gv, gd, cos_incidence=gc))
    with pytest.raises(NidarError, match="reads the value and the incidence"):
        fit("gbm", v, d, y, elevation_deg=e, use_geometry=False)
    with pytest.raises(NidarError, match="reads the value and the incidence"):
        fit("gbm", v, d, y, elevation_deg=e, cos_incidence=c, use_value=False, use_geometry=False)
    with pytest.raises(NidarError, match="differ in length"):
        m(gv[:3], gd[:3], cos_incidence=gc[:2])


def test_prediction_does_not_depend_on_the_threads(monkeypatch):
    from nidar_mi.profiles import gbm

    p = _profile()
    v, d, e, _ = _sample(20_000, seed=2)
    monkeypatch.setattr(gbm, "predict_threads", lambda: 1)
    one = p(v, d, elevation_deg=e)
    monkeypatch.setattr(gbm, "predict_threads", lambda: 4)
    np.testing.assert_array_equal(p(v, d, elevation_deg=e), one)


def test_too_few_returns_and_bad_constraint_headers_are_errors():
    v, d, e, y = _sample(150)
    with pytest.raises(NidarError, match="150 returns are too few"):
        fit("gbm", v, d, y, elevation_deg=e)  # leaves of >= 100 returns: a constant at best
    v, d, e, y = _sample(3000)
    m = fit("gbm", v, d, y, elevation_deg=e, trees=5)
    assert m.params["trees"] == 5
    bad = m.model.replace("monotone_constraints=1 0 0", "monotone_constraints=1 0 0 1 1")
    assert bad != m.model
    with pytest.raises(NidarError, match="monotone_constraints"):
        GbmMap(m.features, m.monotone, bad)


def _table_probe(m, n=20_000, seed=5):
    """(rows, F) design points: random ones, every split threshold exactly and one ulp either
    side of it, and values LightGBM reads as 0."""
    from nidar_mi.profiles import gbm

    th = gbm._split_thresholds(m.model, len(m.features))
    rng = np.random.default_rng(seed)
    cols = []
    for t in th:
        edge = np.concatenate([t, np.nextafter(t, -np.inf), np.nextafter(t, np.inf)])
        lo, hi = (t.min() - 1, t.max() + 1) if len(t) else (0.0, 1.0)
        col = np.concatenate([rng.uniform(lo, hi, n), edge, [0.0, -0.0, 1e-36, -1e-36]])
        cols.append(col)
    size = max(len(c) for c in cols)
    return np.stack([np.resize(rng.permutation(c), size) for c in cols], axis=1)


@pytest.mark.parametrize("which", ["shipped", "value_incidence", "geometry"])
def test_the_lookup_table_equals_lightgbm(which):
    """The cell table gives LightGBM's own predictions bit for bit, at random points and at and
    beside every split threshold (the shipped value-and-incidence profile and fitted maps)."""
    from nidar_mi.nidar.pipeline import NidarModel
    from nidar_mi.profiles import gbm

    if which == "shipped":
        m = NidarModel.load(device="cpu", optimize=False).default_profile().mapping
    else:
        v, d, e, y = _sample(20_000)
        c = np.random.default_rng(6).uniform(0, 1, len(v))
        if which == "value_incidence":
            m = fit("gbm", v, d, y * c, cos_incidence=c, use_geometry=False, trees=60)
        else:
            m = fit("gbm", v, d, y, elevation_deg=e, use_value=False, trees=60)
    x = _table_probe(m)
    table = gbm._CellTable.build(m._booster, m.model, len(m.features))
    assert table, "the map fits a table"
    np.testing.assert_array_equal(table(x), m._booster.predict(x, num_threads=1))


def test_a_map_beyond_the_table_size_goes_to_lightgbm(monkeypatch):
    from nidar_mi.profiles import gbm

    v, d, e, y = _sample(20_000)
    tabled = fit("gbm", v, d, y, elevation_deg=e, use_value=False, trees=30)
    gv, gd, ge, _ = _grid(_truth)
    expected = tabled(gv, gd, elevation_deg=ge)
    assert tabled._table
    monkeypatch.setattr(gbm, "MAX_TABLE_CELLS", 0)
    direct = gbm.GbmMap.from_dict(tabled.to_dict())
    np.testing.assert_array_equal(direct(gv, gd, elevation_deg=ge), expected)
    assert not direct._table
