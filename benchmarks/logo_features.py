"""Leave one group out over the shared KITTI groups: what each group of a return's inputs adds to
the ranking of its intensity on drives the fit never saw.

``python benchmarks/logo_features.py [--data DIR] [--rows ROW,...] [--seeds N] [--ks 3,10]
[--cache DIR] [--weights DIR]``

The 123 real KITTI frames under ``--data`` (default: the data root, ``../shared/data``) fall in
the 8 groups of ``calibrate_frames.py`` (``kitti``, ``kitti_raw_0926``, ``obj``, ``o04``,
``r0005``, ``r0009``, ``r0048``, ``r0064``). For every group, a model is fitted on the frames of
the other seven and scored on every frame of the group: Spearman's ρ of the prediction against
the stored reflectance over the frame's camera-visible returns, raw and within 2 m range bins
(:func:`nidar_mi.eval.scan_metrics.binned_spearman`), the mean over the group's frames. A row
gives the mean ± the standard deviation over the 8 groups (each group counts once), and for
rows of several seeds the mean over the seeds of those.

Rows of **inputs** (:data:`ROWS`) fit the ``context`` form's regression
(:mod:`nidar_mi.profiles.context`, its fixed settings: 400 trees of 63 leaves, learning rate
0.05, :data:`~nidar_mi.profiles.context.POINTS_PER_FRAME` returns drawn per frame, seeded) on
named inputs (:mod:`nidar_mi.profiles.inputs`): ``return`` (range, elevation, incidence),
``study_*`` (the inputs of the independent study: height ``z``, ``|n_z|``, the 20-neighbour
linearity / planarity / scatter, the neighbour spacing raw and over the range; then every
image input; then the laser index; then the same on the per-frame rank of the intensity),
``geometry`` (every image-free input: the three scales, the height above the ground, the
ring), ``image`` (and every image input), ``context`` (and NIDAR's four maps: the shipped
``kitti-hdl64e`` recipe), ``context_rank`` (the same on the rank).
Rows of **baselines**: ``nidar`` (NIDAR's R through the former ``kitti-hdl64e`` recipe, a
``gbm`` of R, range, elevation and incidence, :func:`nidar_mi.datasets.profile_fitting.
fit_values_profile`), ``luminance`` (the pixel's luminance through the same recipe), ``grey``
(R of a uniform grey image through it: the recipe without the image), ``carla`` (CARLA's
``exp(-0.004 d)``, no fit). ``--ks``: the ``context`` row fitted on K frames drawn at random
from the other groups, per seed.

Per row: its command line (``--rows ROW``) and wall time. The image gain is ``image`` minus
``geometry`` and ``context`` minus ``geometry``, group by group (positive in how many of 8).
The inputs of every frame are computed once and kept under ``--cache`` (default: the user's
cache folder; KITTI is non-commercial data: nothing derived from it belongs in the project,
only the numbers printed here).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

from calibrate_frames import group_of  # noqa: E402

from nidar_mi.eval.metrics import spearman  # noqa: E402
from nidar_mi.eval.scan_metrics import binned_spearman  # noqa: E402
from nidar_mi.geometry.local_features import GEOMETRY_FEATURES  # noqa: E402
from nidar_mi.profiles.image_context import IMAGE_FEATURES, RELATIVE_FEATURES  # noqa: E402
from nidar_mi.profiles.inputs import DEFAULT_INPUTS, NIDAR_MAPS, RETURN_FEATURES  # noqa: E402

#: Version of the cached inputs (bump when an input's definition changes).
CACHE_VERSION = 3
#: The independent study's geometry inputs.
STUDY_GEOMETRY = (
    "z",
    "nz",
    "linearity_k20",
    "planarity_k20",
    "scatter_k20",
    "spacing",
    "spacing_rel",
)
#: The geometry inputs without the 50-neighbour shapes (what one 20-neighbour query gives).
FAST_GEOMETRY = tuple(f for f in GEOMETRY_FEATURES if not f.endswith("_k50"))
#: The image inputs that do not scale with the exposure.
INVARIANT_IMAGE = ("lum_log", "chroma_r", "chroma_g", "hue", "sat", "contrast")
#: Row -> (label, inputs, target[, kind]) of the rows of inputs (kind: ``gbm`` unless given).
ROWS: dict[str, tuple[str, tuple[str, ...], str]] = {
    "return": ("range, elevation, incidence", RETURN_FEATURES, "intensity"),
    "study_geometry": (
        "+ z, |n_z|, 20-neighbour shape, spacing (the study's geometry)",
        (*RETURN_FEATURES, *STUDY_GEOMETRY),
        "intensity",
    ),
    "study_image": (
        "+ every image input (the study's image row)",
        (*RETURN_FEATURES, *STUDY_GEOMETRY, *IMAGE_FEATURES),
        "intensity",
    ),
    "study_ring": (
        "+ the laser index",
        (*RETURN_FEATURES, *STUDY_GEOMETRY, *IMAGE_FEATURES, "ring"),
        "intensity",
    ),
    "study_rank": (
        "same, trained on the per-frame rank",
        (*RETURN_FEATURES, *STUDY_GEOMETRY, *IMAGE_FEATURES, "ring"),
        "rank",
    ),
    "geometry": (
        "geometry only: return, ring, multi-scale shape, height above the ground",
        (*RETURN_FEATURES, "ring", *GEOMETRY_FEATURES),
        "intensity",
    ),
    "image": (
        "+ every image input",
        (*RETURN_FEATURES, "ring", *GEOMETRY_FEATURES, *IMAGE_FEATURES),
        "intensity",
    ),
    "context": (
        "+ NIDAR's R, S, pseudo-NIR, Î (the context profile's default inputs)",
        DEFAULT_INPUTS,
        "intensity",
    ),
    "geometry_blend": (
        "geometry only, the intensity's and the rank's regressions averaged",
        (*RETURN_FEATURES, "ring", *GEOMETRY_FEATURES),
        "blend",
    ),
    "context_blend": (
        "same, the intensity's and the rank's regressions averaged",
        DEFAULT_INPUTS,
        "blend",
    ),
    "context_rank": (
        "same, trained on the per-frame rank",
        (*RETURN_FEATURES, "ring", *GEOMETRY_FEATURES, *IMAGE_FEATURES, *NIDAR_MAPS),
        "rank",
    ),
    "context_rel": (
        "every input, the image's exposure divided out",
        (
            *RETURN_FEATURES,
            "ring",
            *GEOMETRY_FEATURES,
            *INVARIANT_IMAGE,
            *RELATIVE_FEATURES,
            *NIDAR_MAPS,
        ),
        "intensity",
    ),
    "context_fast": (
        "every input but the 50-neighbour shapes (one 20-neighbour query)",
        (*RETURN_FEATURES, "ring", *FAST_GEOMETRY, *IMAGE_FEATURES, *NIDAR_MAPS),
        "intensity",
    ),
    "context_fast_mlp": (
        "the same, the small head in place of the trees",
        (*RETURN_FEATURES, "ring", *FAST_GEOMETRY, *IMAGE_FEATURES, *NIDAR_MAPS),
        "intensity",
        "mlp",
    ),
    "geometry_mlp": (
        "geometry only, the small head in place of the trees",
        (*RETURN_FEATURES, "ring", *GEOMETRY_FEATURES),
        "intensity",
        "mlp",
    ),
    "context_mlp": (
        "every input, the small head in place of the trees",
        (*RETURN_FEATURES, "ring", *GEOMETRY_FEATURES, *IMAGE_FEATURES, *NIDAR_MAPS),
        "intensity",
        "mlp",
    ),
    "context_rank_mlp": (
        "every input, the small head on the per-frame rank",
        (*RETURN_FEATURES, "ring", *GEOMETRY_FEATURES, *IMAGE_FEATURES, *NIDAR_MAPS),
        "rank",
        "mlp",
    ),
}
#: The baseline rows and their labels.
BASELINES = {
    "nidar": "NIDAR R, gbm + incidence (the former kitti-hdl64e recipe)",
    "luminance": "luminance, gbm + incidence (the same recipe)",
    "grey": "R of a grey image, gbm + incidence (the recipe without the image)",
    "carla": "CARLA exp(-0.004 d), no fit",
}
#: The extra values cached per frame for the baselines.
EXTRA = ("intensity", "grey_R", "luminance", "frame")


def frame_inputs(model, scan, grey: dict) -> dict[str, np.ndarray]:
    """Every input of :mod:`nidar_mi.profiles.inputs` at a scan's returns, with the
    intensity, R of a grey image (``grey_R``; ``grey`` caches it by image size) and the
    luminance: name -> (N,) float32 (NaN where missing)."""
    from nidar_mi.eval.image_cues import GREY_LEVEL
    from nidar_mi.geometry import locate_in_cameras, sample_cameras
    from nidar_mi.profiles.inputs import camera_inputs, return_inputs

    sightings = locate_in_cameras(scan.xyz, scan.cameras, occlusion=False)
    images = scan.images
    maps = [model.predict_image(im) for im in images]
    _, _, cam_index = sample_cameras(
        scan.xyz, scan.cameras, [m["R"] for m in maps], sightings=sightings
    )
    out = return_inputs(scan.xyz, scan.ring) | camera_inputs(sightings, images, cam_index, maps)
    greys = []
    for im in images:
        if im.shape not in grey:
            grey[im.shape] = model.predict_image(np.full_like(im, GREY_LEVEL))["R"]
        greys.append({"R": grey[im.shape]})
    out["grey_R"] = camera_inputs(sightings, images, cam_index, greys)["R"]
    lum = np.asarray([0.2126, 0.7152, 0.0722])
    out["luminance"] = np.stack([out["r_lin"], out["g_lin"], out["b_lin"]], 1) @ lum
    out["intensity"] = scan.intensity
    return {k: np.asarray(v, np.float32) for k, v in out.items()}


def load_inputs(scans, model, cache: Path, progress: bool = True) -> dict[str, dict]:
    """frame name -> its :func:`frame_inputs`, computed once and kept in ``cache``."""
    from nidar_mi.progress import progress_bar

    cache.mkdir(parents=True, exist_ok=True)
    grey: dict = {}
    out = {}
    for scan in progress_bar(scans, show=progress, desc="inputs", unit="frame"):
        path = cache / f"{scan.name}.v{CACHE_VERSION}.npz"
        if path.is_file():
            with np.load(path) as z:
                out[scan.name] = {k: z[k] for k in z.files}
            continue
        feats = frame_inputs(model, scan, grey)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **feats)
        os.replace(tmp, path)
        out[scan.name] = feats
    return out


def frame_rank(y: np.ndarray) -> np.ndarray:
    """(N,) average ranks of ``y`` scaled to [0, 1] (ties share their mean rank)."""
    from scipy.stats import rankdata

    return (rankdata(y) - 1.0) / max(len(y) - 1, 1)


def design(frame: dict, names: Sequence[str]) -> np.ndarray:
    """(N, F) float64 inputs of a frame, columns ``names``."""
    return np.column_stack([frame[k] for k in names]).astype(np.float64)


def frame_scores(pred: np.ndarray, frame: dict) -> tuple[float, float]:
    """Spearman and 2 m range-binned Spearman of a prediction over a frame's returns."""
    y = frame["intensity"].astype(np.float64)
    return spearman(pred, y), binned_spearman(pred, y, frame["range_m"].astype(np.float64))


#: Threads of each fit (the models do not depend on them; one thread wastes nothing waiting on a
#: busy machine's other cores).
THREADS = 1


def fit_rows(train: Sequence[dict], names, target: str, seed: int, kind: str = "gbm", points=None):
    """The ``context`` form's model (:mod:`nidar_mi.profiles.context`: its trees, or the
    small head of :mod:`nidar_mi.profiles.head`) fitted on ``train`` frames: a predictor of a
    frame's (N, F) design matrix."""
    from nidar_mi.profiles.context import ContextFitOptions, train_context_booster, training_rows
    from nidar_mi.profiles.head import fit_head, head_predict

    o = ContextFitOptions(seed=seed, target=target, kind=kind, threads=THREADS)
    if target == "blend":
        return _fit_blend(
            train, names, o if points is None else replace(o, points_per_frame=points)
        )
    if points is not None:
        o = ContextFitOptions(
            seed=seed, target=target, kind=kind, threads=THREADS, points_per_frame=points
        )
    x, y, w = training_rows(
        [design(f, names) for f in train],
        [f["intensity"] for f in train],
        o,
        [group_of(f["frame"]) for f in train],
    )
    if kind == "mlp":
        head = fit_head(x, y, seed=seed, threads=THREADS, weight=w)
        return lambda x: head_predict(head, x)
    booster = train_context_booster(x, y, tuple(names), o, w)
    return lambda x: booster.predict(x, num_threads=o.threads)


def _fit_blend(train: Sequence[dict], names, o):
    """A ``blend`` map fitted through :meth:`ContextMap.fit` (frames and groups labelled): a
    predictor of a frame's (N, F) design matrix."""
    from nidar_mi.profiles.context import ContextMap

    x = np.concatenate([design(f, names) for f in train])
    context = {n: x[:, i] for i, n in enumerate(names)}
    context["frame"] = np.concatenate(
        [np.full(len(f["intensity"]), i) for i, f in enumerate(train)]
    )
    context["group"] = np.concatenate(
        [np.full(len(f["intensity"]), group_of(f["frame"])) for f in train]
    )
    y = np.concatenate([f["intensity"] for f in train])
    m = ContextMap.fit(y, x[:, 0], y, context=context, options=o)
    return lambda d: m(d[:, 0], d[:, 0], context={n: d[:, i] for i, n in enumerate(names)})


def logo(
    groups: dict[str, list[dict]],
    names,
    target: str,
    seed: int,
    k: int | None = None,
    kind: str = "gbm",
    points: int | None = None,
) -> dict[str, tuple[float, float]]:
    """Held-out group -> (Spearman, binned) of the inputs' regression fitted on the other
    groups (``k`` frames of them drawn with ``seed``; None: all)."""
    out = {}
    for g in sorted(groups):
        pool = [f for h in sorted(groups) if h != g for f in groups[h]]
        if k is not None:
            rng = np.random.default_rng(seed)
            pool = [pool[i] for i in rng.permutation(len(pool))[:k]]
        t = time.perf_counter()
        predict = fit_rows(pool, names, target, seed, kind, points)
        per = [frame_scores(predict(design(f, names)), f) for f in groups[g]]
        out[g] = tuple(np.nanmean(per, axis=0))
        print(
            f"  {g}: {out[g][0]:.3f}/{out[g][1]:.3f} ({time.perf_counter() - t:.0f} s)",
            file=sys.stderr,
            flush=True,
        )
    return out


def nested(groups, candidates: Sequence[str], seed: int, inner_points: int) -> tuple[dict, dict]:
    """Leave one group out with the inputs chosen inside each fold: for every held-out group,
    each candidate row (:data:`ROWS`) is scored by leave one group out over the other seven
    groups alone (fits on ``inner_points`` returns per frame), and the best by the mean of
    Spearman and range-binned Spearman over those inner groups is fitted on all seven
    (:data:`~nidar_mi.profiles.context.POINTS_PER_FRAME` per frame) and scored on the held-out
    group. Returns ``(held-out group -> scores, held-out group -> chosen row)``."""
    out, chosen = {}, {}
    for g in sorted(groups):
        train = {h: v for h, v in groups.items() if h != g}
        inner = {}
        for c in candidates:
            _, names, target, *kind = ROWS[c]
            per = logo(train, names, target, seed, kind=(kind or ["gbm"])[0], points=inner_points)
            inner[c] = float(np.mean([np.mean(v) for v in per.values()]))
        best = max(candidates, key=lambda c: inner[c])
        chosen[g] = best
        print(f"  {g}: inner {inner} -> {best}", file=sys.stderr, flush=True)
        _, names, target, *kind = ROWS[best]
        pool = [f for h in sorted(train) for f in train[h]]
        predict = fit_rows(pool, names, target, seed, (kind or ["gbm"])[0])
        per = [frame_scores(predict(design(f, names)), f) for f in groups[g]]
        out[g] = tuple(np.nanmean(per, axis=0))
    return out, chosen


def baseline_logo(groups, scans_by_name, row: str, seed: int) -> dict[str, tuple]:
    """Held-out group -> (Spearman, binned) of a baseline row (:data:`BASELINES`)."""
    from calibrate_frames import fitted

    out = {}
    for g in sorted(groups):
        test = groups[g]
        if row == "carla":
            per = [frame_scores(np.exp(-0.004 * f["range_m"].astype(np.float64)), f) for f in test]
            out[g] = tuple(np.nanmean(per, axis=0))
            continue
        key = {"nidar": "R", "luminance": "luminance", "grey": "grey_R"}[row]
        pool = [f for h in sorted(groups) if h != g for f in groups[h]]
        values = {f["frame"]: f[key].astype(np.float64) for f in [*pool, *test]}
        predict = fitted([scans_by_name[f["frame"]] for f in pool], values, seed, row)
        per = []
        for f in test:
            s = scans_by_name[f["frame"]]
            ok = np.isfinite(values[f["frame"]])
            pred = np.full(len(ok), np.nan)
            pred[ok] = predict(s, values[f["frame"]], ok)
            sub = {k: f[k][ok] for k in ("intensity", "range_m")}
            per.append(frame_scores(pred[ok], sub))
        out[g] = tuple(np.nanmean(per, axis=0))
    return out


def summary(per_seed: list[dict[str, tuple]]) -> str:
    """``raw mean ± sd / binned mean ± sd`` over the groups (each seed's group scores averaged
    over the seeds first)."""
    groups = sorted(per_seed[0])
    a = np.array([[s[g] for g in groups] for s in per_seed]).mean(axis=0)  # (G, 2)
    m, sd = a.mean(axis=0), a.std(axis=0)
    return f"{m[0]:.3f} ± {sd[0]:.3f} | {m[1]:.3f} ± {sd[1]:.3f}"


def gain(plus: list[dict], minus: list[dict]) -> str:
    """The per-group gain ``plus − minus`` (means over the seeds): mean ± sd, and in how many
    groups it is positive, raw / binned."""
    groups = sorted(plus[0])
    a = np.array([[s[g] for g in groups] for s in plus]).mean(axis=0)
    b = np.array([[s[g] for g in groups] for s in minus]).mean(axis=0)
    d = a - b
    m, sd, pos = d.mean(axis=0), d.std(axis=0), (d > 0).sum(axis=0)
    return (
        f"{m[0]:+.3f} ± {sd[0]:.3f} ({pos[0]}/{len(groups)} > 0) | "
        f"{m[1]:+.3f} ± {sd[1]:.3f} ({pos[1]}/{len(groups)} > 0)"
    )


def per_group(per_seed: list[dict]) -> str:
    groups = sorted(per_seed[0])
    a = np.array([[s[g] for g in groups] for s in per_seed]).mean(axis=0)
    return "; ".join(f"{g} {r:.3f}/{b:.3f}" for g, (r, b) in zip(groups, a))


def _record(path: str | None, row: str, runs: list[dict], wall: float, seeds) -> None:
    """Add a row's per-group scores of each seed, and its wall time, to the JSON file at
    ``path`` (rows of other runs and other seeds kept)."""
    if path is None:
        return
    import json

    data = json.loads(Path(path).read_text()) if Path(path).is_file() else {}
    entry = data.setdefault(row, {"runs": {}, "wall_s": {}})
    for seed, r in zip(seeds, runs, strict=True):
        entry["runs"][str(seed)] = {g: list(v) for g, v in r.items()}
        entry["wall_s"][str(seed)] = wall / len(runs)
    Path(path).write_text(json.dumps(data, indent=1))


def _parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--data", default=None, help="folder holding the KITTI folders")
    ap.add_argument(
        "--rows",
        default=",".join([*ROWS, *BASELINES]),
        help=f"rows: {', '.join([*ROWS, *BASELINES])}",
    )
    ap.add_argument("--seeds", type=int, default=1, help="seeds of each row")
    ap.add_argument("--seed-start", type=int, default=0, help="the first seed")
    ap.add_argument("--ks", default="", help="K frames for the context row, e.g. 3,10")
    ap.add_argument("--cache", default=None, help="folder of the per-frame inputs")
    ap.add_argument("--weights", default=None, help="NIDAR weights (default: the shipped)")
    ap.add_argument(
        "--select",
        default="",
        help="rows to choose from inside each fold (nested leave one group out), e.g. "
        "context,context_rel",
    )
    ap.add_argument(
        "--inner-points", type=int, default=1000, help="returns per frame in the inner fits"
    )
    ap.add_argument("--json", default=None, help="also write every row's per-group scores here")
    args = ap.parse_args(argv)
    args.rows = [r.strip() for r in args.rows.split(",") if r.strip()]
    bad = [r for r in args.rows if r not in ROWS and r not in BASELINES]
    if bad:
        ap.error(f"--rows: unknown {bad}")
    args.ks = [int(k) for k in args.ks.split(",") if k.strip()]
    args.select = [r.strip() for r in args.select.split(",") if r.strip()]
    if any(r not in ROWS for r in args.select):
        ap.error(f"--select: rows of {', '.join(ROWS)}")
    return args


def main(argv=None) -> int:
    from calibrate_frames import kitti_scans

    from nidar_mi.datasets.paths import cache_dir

    args = _parse(argv)
    t0 = time.perf_counter()
    scans, model = kitti_scans(args.data, args.weights)
    if not scans:
        return 2
    cache = Path(args.cache) if args.cache else cache_dir("logo_features")
    inputs = load_inputs(scans, model, cache)
    groups: dict[str, list[dict]] = {}
    for s in scans:
        inputs[s.name]["frame"] = s.name
        groups.setdefault(group_of(s.name), []).append(inputs[s.name])
    sizes = ", ".join(f"{g} {len(v)}" for g, v in sorted(groups.items()))
    print(
        f"{len(scans)} frames in {len(groups)} groups ({sizes}); inputs ready after "
        f"{time.perf_counter() - t0:.0f} s\n",
        flush=True,
    )
    by_name = {s.name: s for s in scans}
    seeds = range(args.seed_start, args.seed_start + args.seeds)
    results = {}
    print("| row | inputs | Spearman | range-binned | seeds | wall s | per group (raw/binned) |")
    print("| --- | --- | --- | --- | --- | ---: | --- |")
    for row in args.rows:
        t = time.perf_counter()
        if row in ROWS:
            label, names, target, *kind = ROWS[row]
            runs = [logo(groups, names, target, s, kind=(kind or ["gbm"])[0]) for s in seeds]
        else:
            label = BASELINES[row]
            runs = [baseline_logo(groups, by_name, row, s) for s in seeds]
        results[row] = runs
        wall = time.perf_counter() - t
        _record(args.json, row, runs, wall, seeds)
        print(
            f"| {row} | {label} | {summary(runs)} | {len(runs)} | {wall:.0f} | {per_group(runs)} |",
            flush=True,
        )
    for k in args.ks:
        t = time.perf_counter()
        _, names, target = ROWS["context_blend"][:3]  # the shipped recipe (blend)
        k_seeds = range(args.seed_start, args.seed_start + max(args.seeds, 3))
        runs = [logo(groups, names, target, s, k=k) for s in k_seeds]
        wall = time.perf_counter() - t
        _record(args.json, f"context_k{k}", runs, wall, k_seeds)
        print(
            f"| context K={k} | {k} frames drawn from the other groups | {summary(runs)} | {len(runs)} | {wall:.0f} | {per_group(runs)} |",
            flush=True,
        )
    if args.select:
        t = time.perf_counter()
        picked = [nested(groups, args.select, s, args.inner_points) for s in seeds]
        runs = [r for r, _ in picked]
        wall = time.perf_counter() - t
        name = "nested:" + "|".join(args.select)
        _record(args.json, name, runs, wall, seeds)
        choice = "; ".join(f"{g} {c}" for g, c in sorted(picked[0][1].items()))
        print(
            f"| {name} | chosen per fold: {choice} | {summary(runs)} | {len(runs)} | {wall:.0f} | {per_group(runs)} |",
            flush=True,
        )
    for plus, minus in (
        ("image", "geometry"),
        ("context", "geometry"),
        ("study_image", "study_geometry"),
    ):
        if plus in results and minus in results:
            print(f"| gain {plus} − {minus} | | {gain(results[plus], results[minus])} | | | |")
    print(f"\nwall time {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
