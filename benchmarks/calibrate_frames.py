"""How the score of a calibrated sensor profile grows with the frames it is fitted on, and what
the camera image adds on drives the fit never saw.

``python benchmarks/calibrate_frames.py [--data DIR] [--ks 1,3,10,all] [--seeds 3]
[--sources nidar,geometry,luminance,linnir,stn,lin9,colour_gbm,image_gbm] [--extra-ks KS]
[--weights DIR]``

Leave-one-drive-out over the real KITTI frames under ``--data`` (default: the data root,
``../shared/data``): the groups are ``kitti_raw_0926`` (one drive), each drive of
``kitti_more`` (``rDDDD_*``: drive DDDD), its object frames (``obj*``), its odometry frames
(``o04_*``), and ``kitti`` (scattered frames). For every held-out group and every K, a profile
of the ``kitti-hdl64e`` recipe (``gbm`` of the per-return value with the incidence,
:func:`nidar_mi.datasets.profile_fitting.fit_values_profile`) is fitted on K frames drawn at
random (seeded) from the other groups, and scored on every frame of the held-out group, which no
fit ever saw: Spearman's ρ against the stored reflectance and the range-binned Spearman
(:func:`nidar_mi.eval.scan_metrics.binned_spearman`), the mean over the group's frames. K = 0
rows are the generic profiles (closed forms, no fit). A row gives the mean over the groups (each
group counts once) and the spread over the seeds (standard deviation of that mean).

The per-return value comes from one of these sources (:data:`VALUE_SOURCES`), each sampled at
the returns the same way (:func:`sample_scan_maps`); every source of a row sees the same groups,
the same K frames of each seed and the same recipe:

* ``nidar``: NIDAR's R map of the camera image;
* ``geometry``: R of a uniform grey image of the same size (8-bit level
  :data:`~nidar_mi.eval.image_cues.GREY_LEVEL`): the profile keeps the range, incidence
  and ring, but no image information;
* ``luminance``: Rec. 709 luminance of the image's linear RGB
  (:func:`nidar_mi.eval.image_cues.luminance`);
* ``linnir``: baseline (i), the 4-parameter linear RGB -> NIR map
  (:class:`~nidar_mi.eval.baselines.LinearNIR`) fitted once on the non-test RGB/NIR photo pairs
  of ``<data>/rgbnir`` (:func:`nidar_mi.eval.real.fit_linear_nir`), applied to the image;
* ``stn``: the STN's pseudo-NIR.

Two more rows are predictors of their own, fitted on the same K frames of each seed and scored
on the same held-out returns, with no profile; their value is the (N, 3) colour at the return
(8-bit sRGB / 255, :func:`nidar_mi.eval.loo.colour_at_returns`):

* ``lin9``: baseline (h), least squares of the stored reflectance on ``r, g, b, r/Σ, g/Σ, b/Σ,
  log d, d/50, 1`` (:func:`nidar_mi.eval.loo.linear_colour_distance_method`);
* ``colour_gbm``: a diagnostic, the recipe's ``gbm`` with the full colour in place of one value:
  the features are the linear R, G, B at the return, its range, elevation (the recipe's stand-in
  for the ring) and incidence cosine, with the recipe's LightGBM settings (the defaults of
  :class:`~nidar_mi.profiles.gbm.GbmFitOptions`; non-decreasing in the incidence, free in the
  colour). What any map of the pixel's colour could add to the geometry, bounded by this
  regression's reach;
* ``image_gbm``: a diagnostic, the same regression on every image feature at hand
  (:data:`IMAGE_GBM_FEATURES`, :func:`image_features`): the linear colour at the return, its
  mean over the :data:`CONTEXT_WINDOWS` pixel windows around it, the spread of the luminance
  over the smaller one, and NIDAR's R, S and pseudo-NIR, beside range, elevation and incidence.
  What the pixel, its neighbourhood and the networks' maps together could add to the geometry,
  bounded by this regression's reach. Not in the default ``--sources`` (it runs the networks a
  second time on every image): ask for it by name.

The image gain of a K is NIDAR R minus geometry only, per seed (paired draws); the colour gain
is the colour gbm minus geometry only, the image-feature gain the image gbm minus geometry only.
The draws depend on the held-out group, K and the seed only (:func:`splits`), never on the
sources requested, so rows of separate runs pair.

Prints a Markdown table; nothing is written. KITTI is non-commercial data: only numbers are
reported.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np

from nidar_mi.datasets.paths import data_root
from nidar_mi.datasets.profile_fitting import fit_values_profile
from nidar_mi.datasets.scans import ScanFrame, load_scans
from nidar_mi.datasets.sensor_profiles import (
    GENERIC_COMPENSATED_PROFILE,
    GENERIC_RAW_PROFILE,
    generic_profile,
)
from nidar_mi.eval.image_cues import GREY_LEVEL, luminance
from nidar_mi.eval.loo import colour_at_returns, linear_colour_distance_method
from nidar_mi.eval.metrics import spearman
from nidar_mi.eval.scan_metrics import binned_spearman
from nidar_mi.nidar.pipeline import NidarModel

#: The KITTI folders of the data root that are read.
FOLDERS = ("kitti_raw_0926", "kitti_more", "kitti")
#: Value source -> its label in the table (module docstring).
VALUE_SOURCES = {
    "nidar": "NIDAR R",
    "geometry": "geometry only (R of a grey image)",
    "luminance": "luminance",
    "linnir": "(i) linear RGB→NIR",
    "stn": "STN pseudo-NIR",
    "lin9": "(h) linear colour + distance",
    "colour_gbm": "colour gbm (diagnostic)",
    "image_gbm": "image gbm (diagnostic)",
}
#: The sources of a run that names none: all but the image gbm (module docstring).
DEFAULT_SOURCES = tuple(s for s in VALUE_SOURCES if s != "image_gbm")
#: The sources that are R maps: fitted at every K (the others at ``--extra-ks`` only).
R_SOURCES = ("nidar", "geometry")
#: The sources whose value is the (N, 3) colour at the return: predictors of their own.
COLOUR_SOURCES = ("lin9", "colour_gbm")
#: The sources whose value is the (N, F) image features at the return (:data:`IMAGE_FEATURES`).
FEATURE_SOURCES = ("image_gbm",)
#: The recipe's label.
RECIPE = "gbm + incidence (kitti-hdl64e recipe)"
#: The profile column of the predictors of their own.
PREDICTORS = {
    "lin9": "least squares, 9 parameters (no profile)",
    "colour_gbm": "gbm of linear RGB, range, elevation, incidence (recipe's settings)",
    "image_gbm": "gbm of colour, context, texture, NIDAR maps, range, elevation, incidence "
    "(recipe's settings)",
}
#: The gain rows: (source, minus source, label).
GAINS = (
    ("nidar", "geometry", "**image gain** (NIDAR R − geometry only)"),
    ("colour_gbm", "geometry", "**colour gain** (colour gbm − geometry only)"),
    ("image_gbm", "geometry", "**image-feature gain** (image gbm − geometry only)"),
)
#: The colour gbm's features, in column order.
COLOUR_GBM_FEATURES = ("r_lin", "g_lin", "b_lin", "range_m", "elevation_deg", "cos_incidence")
#: Side lengths, pixels, of the square windows whose mean colour is the image gbm's context.
CONTEXT_WINDOWS = (15, 61)
#: The image gbm's image features at a return (:func:`image_features`), in column order.
IMAGE_FEATURES = (
    "r_lin",
    "g_lin",
    "b_lin",
    *(f"{c}_mean{w}" for w in CONTEXT_WINDOWS for c in ("r", "g", "b")),
    f"lum_sd{CONTEXT_WINDOWS[0]}",
    "R",
    "S",
    "pseudo_nir",
)
#: The image gbm's features, in column order.
IMAGE_GBM_FEATURES = (*IMAGE_FEATURES, "range_m", "elevation_deg", "cos_incidence")

Values = dict[str, dict[str, np.ndarray]]  # source -> frame name -> (N,), (N, 3) or (N, F)
Predictor = Callable[[ScanFrame, np.ndarray, np.ndarray], np.ndarray]


def group_of(name: str) -> str:
    """The drive or group of a frame named ``<source>__<id>``."""
    source, fid = name.split("__", 1)
    if source != "kitti_more":
        return source
    if fid.startswith("r"):
        return fid[:5]
    return "obj" if fid.startswith("obj") else fid.split("_", 1)[0]


def sample_scan_maps(scan: ScanFrame, maps: Sequence[dict[str, np.ndarray]]) -> Values:
    """Per-camera maps sampled at a scan's returns, as the profile fit samples NIDAR's maps
    (:func:`nidar_mi.datasets.profile_fitting.scan_branches`: no second occlusion test).

    Args:
        scan: the scan (C cameras).
        maps: per camera, name -> (H, W) map at that camera's image size (any unit).

    Returns:
        name -> (N,) float64 values at the returns, NaN where no camera gives one.
    """
    from nidar_mi.geometry import sample_cameras

    out = {}
    for name in maps[0]:
        values, seen, _ = sample_cameras(
            scan.xyz, scan.cameras, [m[name] for m in maps], occlusion=False
        )
        out[name] = np.where(seen, values, np.nan).astype(np.float64)
    return out


def image_maps(
    model: NidarModel, rgb: np.ndarray, sources: Sequence[str], grey: dict, linear_nir=None
) -> dict:
    """Each value source's (H, W) float32 map of one (H, W, 3) uint8 image (module docstring;
    the colour sources have none).

    ``grey`` caches R of the grey image by image shape (the same for every image of a size);
    ``linear_nir``: the fitted :class:`~nidar_mi.eval.baselines.LinearNIR` (for ``linnir``).
    """
    out = {}
    if "nidar" in sources or "stn" in sources:
        pred = model.predict_image(rgb)
        out |= {"nidar": pred["R"], "stn": pred["pseudo_nir"]}
    if "geometry" in sources:
        if rgb.shape not in grey:
            grey[rgb.shape] = model.predict_image(np.full_like(rgb, GREY_LEVEL))["R"]
        out["geometry"] = grey[rgb.shape]
    if "luminance" in sources:
        out["luminance"] = luminance(rgb)
    if "linnir" in sources:
        out["linnir"] = linear_nir(rgb)
    return {s: out[s] for s in sources if s not in COLOUR_SOURCES + FEATURE_SOURCES}


def image_features(model: NidarModel, rgb: np.ndarray) -> dict[str, np.ndarray]:
    """The image gbm's (H, W) float32 feature maps (:data:`IMAGE_FEATURES`) of one (H, W, 3)
    uint8 image: linear RGB; its means over square windows of :data:`CONTEXT_WINDOWS` pixels
    (the image's edge pixels repeated beyond it); the standard deviation of the Rec. 709
    luminance over the first window; NIDAR's R, S and pseudo-NIR."""
    from scipy.ndimage import uniform_filter

    from nidar_mi.io.images import REC709_LUMA, srgb_to_linear

    lin = srgb_to_linear(rgb.astype(np.float32) / np.float32(255.0)).astype(np.float32)
    out = {f"{c}_lin": lin[..., i] for i, c in enumerate("rgb")}
    for w in CONTEXT_WINDOWS:
        for i, c in enumerate("rgb"):
            out[f"{c}_mean{w}"] = uniform_filter(lin[..., i], w, mode="nearest")
    lum = lin.astype(np.float64) @ np.asarray(REC709_LUMA, np.float64)  # no float32 cancellation
    w = CONTEXT_WINDOWS[0]
    var = uniform_filter(lum * lum, w, mode="nearest") - uniform_filter(lum, w, mode="nearest") ** 2
    out[f"lum_sd{w}"] = np.sqrt(np.maximum(var, 0.0))
    pred = model.predict_image(rgb)
    out |= {"R": pred["R"], "S": pred["S"], "pseudo_nir": pred["pseudo_nir"]}
    return {k: np.asarray(out[k], np.float32) for k in IMAGE_FEATURES}


def source_values(
    model: NidarModel, scans: Sequence[ScanFrame], sources: Sequence[str], linear_nir=None
) -> Values:
    """Every source's values at every scan's returns: source -> frame name -> (N,) float64,
    (N, 3) colours for :data:`COLOUR_SOURCES`, or (N, F) features for :data:`FEATURE_SOURCES`
    (NaN where no camera gives one)."""
    grey: dict = {}
    out: Values = {s: {} for s in sources}
    colour = [s for s in sources if s in COLOUR_SOURCES]
    for scan in scans:
        maps = [image_maps(model, im, sources, grey, linear_nir) for im in scan.images]
        if maps[0]:
            for s, v in sample_scan_maps(scan, maps).items():
                out[s][scan.name] = v
        if colour:
            rgb = colour_at_returns(scan)
            for s in colour:
                out[s][scan.name] = rgb
        if "image_gbm" in sources:
            feats = sample_scan_maps(scan, [image_features(model, im) for im in scan.images])
            out["image_gbm"][scan.name] = np.column_stack([feats[k] for k in IMAGE_FEATURES])
    return out


def _seen(v: np.ndarray) -> np.ndarray:
    """(N,) bool: the returns with a finite value (every channel of a colour)."""
    ok = np.isfinite(v)
    return ok if ok.ndim == 1 else ok.all(axis=1)


def profile_predictor(profile) -> Predictor:
    """``predict(scan, values, ok)``: ``profile`` at the ``ok`` returns of ``scan``."""

    def predict(s: ScanFrame, v: np.ndarray, ok: np.ndarray) -> np.ndarray:
        return profile(
            v[ok],
            s.range_m[ok],
            ring=s.ring[ok] if np.all(s.ring >= 0) else None,
            elevation_deg=s.elevation_deg[ok],
            cos_incidence=s.cos_incidence[ok] if profile.uses_incidence else None,
        )

    return predict


def score(predict: Predictor, scans: Sequence[ScanFrame], values: dict[str, np.ndarray]) -> tuple:
    """Mean Spearman and range-binned Spearman of ``predict`` (:data:`Predictor`) over ``scans``
    (``values``: frame name -> values; returns without a finite value are left out)."""
    rho, rho_bin = [], []
    for s in scans:
        ok = _seen(values[s.name])
        pred = predict(s, values[s.name], ok)
        rho.append(spearman(pred, s.intensity[ok]))
        rho_bin.append(binned_spearman(pred, s.intensity[ok], s.range_m[ok]))
    return float(np.nanmean(rho)), float(np.nanmean(rho_bin))


def fitted(
    train: Sequence[ScanFrame], values: dict[str, np.ndarray], seed: int, source: str
) -> Predictor:
    """``source``'s predictor fitted on ``train``: the recipe's profile of its values, or the
    predictor of its own of a colour or feature source (module docstring)."""
    if source == "lin9":
        predict = linear_colour_distance_method(lambda s: values[s.name]).fit(train)
        return lambda s, v, ok: predict(s)[ok]
    if source == "colour_gbm":
        return fit_design_gbm(train, values, seed, colour_design, COLOUR_GBM_FEATURES)
    if source == "image_gbm":
        return fit_design_gbm(train, values, seed, feature_design, IMAGE_GBM_FEATURES)
    profile = fit_values_profile(
        train,
        lambda s: values[s.name],
        name=f"{source}-k{len(train)}-s{seed}",
        sensor="KITTI HDL-64E",
        input=f"bench:{source}",
        incidence=True,
        seed=seed,
    )
    return profile_predictor(profile)


def colour_design(scan: ScanFrame, colour: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(n, 6) float64 features :data:`COLOUR_GBM_FEATURES` of the ``ok`` returns of ``scan``
    (``colour``: (N, 3) 8-bit sRGB / 255, linearised here)."""
    from nidar_mi.io.images import srgb_to_linear

    lin = srgb_to_linear(np.clip(colour[ok], 0.0, 1.0))
    geo = [scan.range_m[ok], scan.elevation_deg[ok], scan.cos_incidence[ok]]
    return np.column_stack([lin, *geo]).astype(np.float64)


def feature_design(scan: ScanFrame, features: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(n, F + 3) float64 features :data:`IMAGE_GBM_FEATURES` of the ``ok`` returns of ``scan``
    (``features``: (N, F) :data:`IMAGE_FEATURES` at the returns)."""
    geo = [scan.range_m[ok], scan.elevation_deg[ok], scan.cos_incidence[ok]]
    return np.column_stack([features[ok], *geo]).astype(np.float64)


def fit_design_gbm(
    train: Sequence[ScanFrame],
    values: dict[str, np.ndarray],
    seed: int,
    design: Callable[[ScanFrame, np.ndarray, np.ndarray], np.ndarray],
    feats: tuple[str, ...],
) -> Predictor:
    """A gbm diagnostic (module docstring) fitted on ``train``: LightGBM on the ``design``
    matrix of each frame's values (columns ``feats``) with the parameters, rounds and
    subsample bound of the recipe's ``gbm`` form (non-decreasing in the incidence)."""
    from nidar_mi.profiles.gbm import GbmFitOptions, train_booster

    o = GbmFitOptions(seed=seed)
    oks = [_seen(values[s.name]) for s in train]
    x = np.concatenate([design(s, values[s.name], m) for s, m in zip(train, oks)])
    y = np.concatenate([s.intensity[m] for s, m in zip(train, oks)]).astype(np.float64)
    if y.size > o.max_samples:
        keep = np.sort(np.random.default_rng(o.seed).choice(y.size, o.max_samples, replace=False))
        x, y = x[keep], y[keep]
    booster = train_booster(x, y, feats, o)

    def predict(s: ScanFrame, v: np.ndarray, ok: np.ndarray) -> np.ndarray:
        out = booster.predict(design(s, v, ok), num_threads=1)
        return np.clip(np.asarray(out, dtype=np.float64), 0.0, 1.0)

    return predict


def draw(pool: Sequence[ScanFrame], k: int | None, seed: int) -> list[ScanFrame]:
    """K frames of ``pool`` drawn at random with ``seed`` (None: the whole pool)."""
    if k is None:
        return list(pool)
    rng = np.random.default_rng(seed)
    return [pool[i] for i in rng.permutation(len(pool))[:k]]


def splits(groups: dict[str, list], k: int | None, seed: int) -> Iterator[tuple[str, list]]:
    """``(held-out group, the K fit frames)`` for every group; the fit frames are drawn from the
    other groups only."""
    names = sorted(groups)
    for g in names:
        pool = [s for h in names if h != g for s in groups[h]]
        yield g, draw(pool, k, seed)


def generic_rows(groups: dict[str, list], values: Values) -> Iterator[tuple]:
    """``(source, profile label, 0, [(spearman, binned)])`` of the generic profiles, for the
    sources that are R maps (the closed forms read a reflectance in [0, 1])."""
    names = sorted(groups)
    for source, vals in values.items():
        if source not in R_SOURCES:
            continue
        for gen in (GENERIC_COMPENSATED_PROFILE, GENERIC_RAW_PROFILE):
            prof = profile_predictor(generic_profile(gen))
            per = [score(prof, groups[g], vals) for g in names]
            yield source, gen, 0, [tuple(np.mean(per, axis=0))]


def fitted_runs(groups: dict[str, list], values: Values, k: int | None, seeds: int) -> dict:
    """source -> [(spearman, binned) per seed], means over the held-out groups, for one K.

    Every source is fitted on the same draws (one draw per held-out group and seed).
    """
    runs: dict[str, list] = {s: [] for s in values}
    for seed in range(1 if k is None else seeds):
        per: dict[str, list] = {s: [] for s in values}
        for g, pick in splits(groups, k, seed):
            for source, vals in values.items():
                per[source].append(score(fitted(pick, vals, seed, source), groups[g], vals))
        for source in values:
            runs[source].append(tuple(np.mean(per[source], axis=0)))
    return runs


def _cell(runs, column: int, signed: bool = False) -> str:
    """``mean ± sd`` over the seeds (the mean alone for one run)."""
    a = np.asarray(runs)[:, column]
    fmt = "+.3f" if signed else ".3f"
    return f"{a.mean():{fmt}}" + (f" ± {a.std():.3f}" if a.size > 1 else "")


def _per_seed(runs, signed: bool = False) -> str:
    """The seeds' (raw, binned) pairs, e.g. ``0.510/0.320; ...`` (``+0.010/+0.020`` signed)."""
    fmt = "+.3f" if signed else ".3f"
    return "; ".join(f"{r:{fmt}}/{b:{fmt}}" for r, b in runs)


def table(groups: dict[str, list], values: Values, ks, seeds: int, extra_ks=None) -> Iterator[str]:
    """The Markdown table's rows, as they finish (the gain rows after each K's source rows).

    ``extra_ks``: the K (None: the whole pool) at which the sources other than
    :data:`R_SOURCES` are fitted (default: every K).
    """
    yield "| values | profile | K frames | Spearman | range-binned Spearman | seeds | per seed |"
    yield "| --- | --- | --- | --- | --- | --- | --- |"
    for source, label, k, runs in generic_rows(groups, values):
        yield f"| {VALUE_SOURCES[source]} | {label} | {k} | {_cell(runs, 0)} | {_cell(runs, 1)} | 1 | |"
    for k in ks:
        extra = extra_ks is None or k in extra_ks
        vals = {s: v for s, v in values.items() if extra or s in R_SOURCES}
        runs = fitted_runs(groups, vals, k, seeds)
        kk = "all" if k is None else k
        for source, r in runs.items():
            row = f"{_cell(r, 0)} | {_cell(r, 1)} | {len(r)} | {_per_seed(r)}"
            yield f"| {VALUE_SOURCES[source]} | {PREDICTORS.get(source, RECIPE)} | {kk} | {row} |"
        for plus, minus, label in GAINS:
            if plus in runs and minus in runs:
                gain = [(a[0] - b[0], a[1] - b[1]) for a, b in zip(runs[plus], runs[minus])]
                row = f"{_cell(gain, 0, True)} | {_cell(gain, 1, True)} | {len(gain)} | {_per_seed(gain, True)}"
                yield f"| {label} | {PREDICTORS.get(plus, RECIPE)} | {kk} | {row} |"


def _parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--data", default=None, help="folder holding the KITTI folders")
    ap.add_argument("--ks", default="1,3,10,all", help="frame counts (all: the whole pool)")
    ap.add_argument("--seeds", type=int, default=3, help="random draws of the K frames")
    ap.add_argument(
        "--sources",
        default=",".join(DEFAULT_SOURCES),
        help=f"value sources (module docstring; default {','.join(DEFAULT_SOURCES)})",
    )
    ap.add_argument(
        "--extra-ks",
        default=None,
        help="K at which the sources other than nidar and geometry are fitted "
        "(default: every K of --ks)",
    )
    ap.add_argument("--weights", default=None, help="NIDAR weights (default: the shipped)")
    args = ap.parse_args(argv)
    args.sources = [s.strip() for s in args.sources.split(",") if s.strip()]
    bad = [s for s in args.sources if s not in VALUE_SOURCES]
    if bad or not args.sources:
        ap.error(f"--sources: one or more of {', '.join(VALUE_SOURCES)} (got {bad or 'none'})")
    args.ks = _ks(args.ks)
    args.extra_ks = None if args.extra_ks is None else _ks(args.extra_ks)
    return args


def _ks(text: str) -> list[int | None]:
    """``"1,3,all"`` -> ``[1, 3, None]``."""
    return [None if k.strip() == "all" else int(k) for k in text.split(",")]


def kitti_scans(data: str | None, weights: str | None) -> tuple[list[ScanFrame], NidarModel]:
    """The scans of the :data:`FOLDERS` under ``data`` (default: the data root) and the NIDAR
    model of ``weights`` (default: the shipped one) on the CPU; no scans, with a line on
    stderr, when there are no such folders (the model is then not loaded: None)."""
    root = Path(data) if data else data_root()
    dirs = [root / s for s in FOLDERS if (root / s / "velodyne").is_dir()]
    if not dirs:
        print(f"no KITTI folders under {root}", file=sys.stderr)
        return [], None
    return load_scans(dirs, progress=False), NidarModel.load(weights, device="cpu")


def main(argv=None) -> int:
    args = _parse(argv)
    t0 = time.perf_counter()
    scans, model = kitti_scans(args.data, args.weights)
    if not scans:
        return 2
    linear_nir = None
    if "linnir" in args.sources:
        from nidar_mi.eval.real import fit_linear_nir

        root = Path(args.data) if args.data else data_root()
        linear_nir, _ = fit_linear_nir(root / "rgbnir")
    values = source_values(model, scans, args.sources, linear_nir)
    groups: dict[str, list] = {}
    for s in scans:
        groups.setdefault(group_of(s.name), []).append(s)
    sizes = ", ".join(f"{g} {len(v)}" for g, v in sorted(groups.items()))
    print(f"{len(scans)} frames in {len(groups)} held-out groups ({sizes})")
    print(f"values ready after {time.perf_counter() - t0:.0f} s\n", flush=True)
    for line in table(groups, values, args.ks, args.seeds, args.extra_ks):
        print(line, flush=True)
    print(f"\nwall time {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
