"""Leave-one-frame-out evaluation on a sensor's real scans, for any method.

**Protocol.** Given scans (:class:`~nidar_mi.datasets.scans.ScanFrame`) and the names of the
test frames, fold ``k`` fits every method on all scans except test frame ``k`` and scores it on
frame ``k`` (:func:`nidar_mi.eval.scan_metrics.scan_metrics`). On KITTI the test frames are the
six scattered frames of ``kitti/`` and the training frames of fold ``k`` are the 78 frames of
the raw drive plus the 5 other scattered frames. No metric is computed on a frame a method was
fitted on.

**Methods.** A method is a callable ``fit(train_scans) -> predict``, where ``predict(scan)``
returns an intensity per return of ``scan``: anything fitted on the training frames plugs in
(a network trained per fold, a sensor profile, a regression). :func:`standard_methods` builds
this package's baselines and NIDAR rows; every sensor profile in them is fitted by
:func:`nidar_mi.datasets.profile_fitting.fit_values_profile`, the code path of ``python -m
nidar_mi.calibrate`` and of the ``kitti-hdl64e`` profile.

Per-return values that take time (the networks' maps) are computed once per frame and reused
across folds (:class:`CachedValues`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import NidarError
from .scan_metrics import SCAN_METRICS, scan_metrics

__all__ = [
    "CachedValues",
    "LooMethod",
    "carla_values",
    "colour_at_returns",
    "leave_one_out",
    "linear_colour_distance_method",
    "map_at_returns",
    "profile_method",
    "raw_method",
    "standard_methods",
]

Predictor = Callable[[Any], np.ndarray]


@dataclass(frozen=True)
class LooMethod:
    """A row of the leave-one-out table.

    Attributes:
        label: the row's label.
        fit: ``fit(train_scans) -> predict``; ``predict(scan)`` gives ``(N,)`` intensities.
        note: what the method is, in a few words (for the report).
    """

    label: str
    fit: Callable[[Sequence[Any]], Predictor]
    note: str = ""


@dataclass
class CachedValues:
    """Per-return values computed once per frame (by name).

    Attributes:
        fn: ``fn(scan) -> (N,)`` values.
        cache: frame name -> values.
    """

    fn: Callable[[Any], np.ndarray]
    cache: dict[str, np.ndarray] = field(default_factory=dict)

    def __call__(self, scan) -> np.ndarray:
        if scan.name not in self.cache:
            self.cache[scan.name] = self.fn(scan)
        return self.cache[scan.name]


def map_at_returns(scan, maps: Sequence[np.ndarray]) -> np.ndarray:
    """One (H, W) map per camera sampled at the scan's returns (NaN where none gives a value)."""
    from ..geometry import sample_cameras

    vals, seen, _ = sample_cameras(scan.xyz, scan.cameras, list(maps), occlusion=False)
    return np.where(seen, vals, np.nan).astype(np.float64)


def colour_at_returns(scan) -> np.ndarray:
    """(N, 3) 8-bit sRGB / 255 at the scan's returns (bilinear; NaN where no camera sees)."""
    images = scan.images
    return np.stack(
        [
            map_at_returns(scan, [im[..., c].astype(np.float32) / 255.0 for im in images])
            for c in range(3)
        ],
        axis=1,
    )


def carla_values(scan) -> np.ndarray:
    """CARLA's ``exp(-0.004 d)`` at the scan's returns."""
    from .baselines import carla

    return carla(scan.range_m)


def _fill(values: np.ndarray, fallback: float) -> np.ndarray:
    """Values with the non-finite ones (returns no camera gives a value) set to ``fallback``."""
    return np.where(np.isfinite(values), values, fallback)


def raw_method(label: str, values: Callable[[Any], np.ndarray], note: str = "") -> LooMethod:
    """A method that fits nothing: the values themselves, clipped to [0, 1] (NaN -> 0)."""

    def fit(train):
        return lambda scan: np.clip(_fill(values(scan), 0.0), 0.0, 1.0)

    return LooMethod(label, fit, note)


def profile_method(
    label: str,
    values: Callable[[Any], np.ndarray],
    *,
    form: str,
    input: str,
    note: str = "",
    **options: Any,
) -> LooMethod:
    """Values through a sensor profile of ``form`` fitted on the training frames.

    Returns without a value at test time get the profile's output for the median training value.
    """
    from ..datasets.profile_fitting import fit_values_profile

    def fit(train):
        profile = fit_values_profile(
            train,
            values,
            name="loo",
            sensor="the training frames",
            input=input,
            form=form,
            **options,
        )
        median = float(np.nanmedian(np.concatenate([values(s) for s in train])))

        def predict(scan):
            v = _fill(values(scan), median)
            cos = scan.cos_incidence if profile.uses_incidence else None
            return profile(
                v,
                scan.range_m,
                ring=scan.ring,
                elevation_deg=scan.elevation_deg,
                cos_incidence=cos,
            )

        return predict

    return LooMethod(label, fit, note)


def linear_colour_distance_method(colours: Callable[[Any], np.ndarray]) -> LooMethod:
    """(h): :class:`~nidar_mi.eval.baselines.LinearColourDistance` fitted on the training frames."""
    from .baselines import LinearColourDistance

    def fit(train):
        cols = [colours(s) for s in train]
        ok = [np.isfinite(c).all(1) for c in cols]
        model = LinearColourDistance.fit(
            np.concatenate([c[m] for c, m in zip(cols, ok)]),
            np.concatenate([s.range_m[m] for s, m in zip(train, ok)]),
            np.concatenate([s.intensity[m] for s, m in zip(train, ok)]),
        )
        fallback = np.nanmedian(np.concatenate(cols), axis=0)

        def predict(scan):
            c = colours(scan)
            c = np.where(np.isfinite(c), c, fallback)
            return model.predict(c, scan.range_m)

        return predict

    return LooMethod(
        "(h) linear colour+distance, 9 parameters",
        fit,
        "least squares on r, g, b, r/Σ, g/Σ, b/Σ, log d, d/50, 1",
    )


def standard_methods(
    *,
    model=None,
    linear_nir=None,
    zero_shot_profile=None,
    forms: Sequence[str] = ("distance_quantile", "range_ring", "gbm"),
) -> dict[str, LooMethod]:
    """The baselines and NIDAR rows of the leave-one-out table.

    Args:
        model: a :class:`~nidar_mi.nidar.pipeline.NidarModel` (None: no NIDAR rows).
        linear_nir: a fitted :class:`~nidar_mi.eval.baselines.LinearNIR` for baseline (i)
            (None: no row (i)).
        zero_shot_profile: a profile fitted elsewhere (e.g. ``sim-905``) for a zero-shot NIDAR
            row that fits nothing on the real frames (None: no such row).
        forms: the profile forms each value source is shown with. With ``"gbm"`` there are
            also a geometry-only ``gbm`` row (range and elevation, no value), for luminance
            and the linear map a ``gbm`` row without the monotone constraint, and
            incidence-aware ``gbm`` rows (``*_gbm_inc``: the returns' ``|cos θ|`` from normals
            estimated on each scan) for the geometry, the linear map, NIDAR's pseudo-NIR and R.

    Returns:
        key -> :class:`LooMethod`, in table order.
    """
    colours = CachedValues(colour_at_returns)
    lum = CachedValues(lambda s: map_at_returns(s, [_luminance_map(im) for im in s.images]))
    nir = None
    if linear_nir is not None:
        nir = CachedValues(lambda s: map_at_returns(s, [linear_nir(im) for im in s.images]))
    methods: dict[str, LooMethod] = {
        "lin9": linear_colour_distance_method(colours),
        "carla": raw_method("(d) CARLA exp(-0.004 d)", carla_values, "no fitting"),
    }
    if nir is not None:
        methods["linnir_dq"] = profile_method(
            "(i) linear RGB→NIR + NIDAR calibration",
            nir,
            form="distance_quantile",
            input="linear_nir",
            note="4-parameter map fitted on the RGB/NIR training photos; the paper's distance "
            "encoding + quantile map fitted on the training frames",
        )
    methods |= _geometry_methods(forms)
    sources = _value_sources(lum, nir, model)
    methods |= _source_methods(sources, forms)
    if model is not None:
        raw = next(v for k, _, v, _ in sources if k == "nidar_I_hat")
        methods["nidar_I_hat_raw"] = raw_method("(f) NIDAR Î raw, zero-shot", raw, "no fitting")
        if zero_shot_profile is not None:
            methods["nidar_zero_shot"] = _zero_shot_method(model, zero_shot_profile, sources)
    return methods


def _geometry_methods(forms: Sequence[str]) -> dict[str, LooMethod]:
    """The rows that read no image: range and ring (``range_ring``) and, with ``gbm`` among the
    ``forms``, range and elevation, without and with the incidence."""
    range_only = CachedValues(lambda s: np.zeros(len(s.xyz)))
    methods = {
        "range_only": profile_method(
            "range and ring only (constant value, range_ring profile)",
            range_only,
            form="range_ring",
            input="constant",
            note="what a profile knows without any image",
        )
    }
    if "gbm" in forms:
        methods["geometry_gbm"] = profile_method(
            "range and elevation only (gbm profile without a value)",
            range_only,
            form="gbm",
            input="constant",
            note="what a regression on the return's geometry knows without any image",
            use_value=False,
        )
        methods["geometry_gbm_inc"] = profile_method(
            "range, elevation and incidence only (gbm profile without a value)",
            range_only,
            form="gbm",
            input="constant",
            note="the return's geometry with the incidence from the scan's normals; no image",
            use_value=False,
            incidence=True,
        )
    return methods


def _value_sources(lum, nir, model) -> list[tuple[str, str, CachedValues, str]]:
    """The image values profiles are fitted on: ``(key, label, values, input)`` each, in table
    order (luminance, the linear map when given, NIDAR's maps when a model is given)."""
    sources = [("lum", "(b) luminance", lum, "luminance")]
    if nir is not None:
        sources.append(("linnir", "(i) linear RGB→NIR", nir, "linear_nir"))
    if model is not None:
        maps = CachedValues(lambda s: _nidar_branches(model, s))
        for branch, name in (
            ("pseudo_nir", "(e) NIDAR pseudo-NIR"),
            ("R", "(g) NIDAR R"),
            ("I_hat", "(f) NIDAR Î"),
        ):
            sources.append(
                (f"nidar_{branch}", name, CachedValues(_branch_of(maps, branch)), f"nidar:{branch}")
            )
    return sources


def _source_methods(sources, forms: Sequence[str]) -> dict[str, LooMethod]:
    """One row per value source and profile form, and the source's variants
    (:data:`_VARIANTS`)."""
    methods = {}
    for key, name, vals, inp in sources:
        for form in forms:
            if key == "linnir" and form == "distance_quantile":
                continue  # row (i), with the rows that read no value source
            methods[f"{key}_{form}"] = profile_method(
                f"{name} + {form} profile", vals, form=form, input=inp
            )
            for v_form, keys, suffix, what, options in _VARIANTS:
                if form == v_form and key in keys:
                    methods[f"{key}{suffix}"] = profile_method(
                        f"{name} + {what}", vals, form=form, input=inp, **options
                    )
    return methods


#: Extra rows per value source: (profile form, sources, key suffix, label, fitting options).
_VARIANTS = (
    ("gbm", ("linnir", "nidar_pseudo_nir", "nidar_R"), "_gbm_inc", "gbm profile with incidence",
     {"incidence": True}),
    ("gbm", ("lum", "linnir"), "_gbm_free", "gbm profile, not monotone in the value",
     {"monotone": False}),
    ("range_ring", ("nidar_R", "nidar_I_hat"), "_range",
     "range_ring profile without ring gains", {"ring_gains_on": False}),
)  # fmt: skip


def _luminance_map(rgb: np.ndarray) -> np.ndarray:
    from ..io.images import REC709_LUMA, srgb_to_linear

    return (
        srgb_to_linear(rgb.astype(np.float32) / 255.0) @ np.asarray(REC709_LUMA, np.float32)
    ).astype(np.float32)


def _nidar_branches(model, scan) -> dict[str, np.ndarray]:
    from ..datasets.profile_fitting import scan_branches

    return scan_branches(model, scan, ("pseudo_nir", "R", "I_hat"))


def _branch_of(maps: CachedValues, branch: str):
    def values(scan):
        return maps(scan)[branch]

    return values


def _zero_shot_method(model, profile, sources) -> LooMethod:
    vals = next(v for k, _, v, _ in sources if k == f"nidar_{profile.branch}")

    def fit(train):
        return lambda scan: profile(
            _fill(vals(scan), 0.0),
            scan.range_m,
            ring=scan.ring,
            elevation_deg=scan.elevation_deg,
            cos_incidence=scan.cos_incidence if profile.uses_incidence else None,
        )

    return LooMethod(
        f"(g) NIDAR-Full zero-shot ({profile.name} profile)",
        fit,
        "the shipped model with the simulator's profile; nothing fitted on real frames",
    )


def leave_one_out(
    scans: Sequence[Any],
    test_names: Sequence[str],
    methods: Mapping[str, LooMethod],
    *,
    progress: bool = True,
) -> dict[str, Any]:
    """Run the protocol of the module docstring.

    Args:
        scans: every frame (training and test).
        test_names: the frames that are held out in turn.
        methods: key -> :class:`LooMethod`.
        progress: show a progress bar over folds and methods.

    Returns:
        ``{"folds": [test names], "rows": [one per fold and method: "frame", "method", "label",
        metrics...], "mean": [one per method: the unweighted mean over folds], "train_frames":
        frames per fold}``.

    Raises:
        NidarError: a test name that is not a frame, or fewer than two frames.
    """
    from ..progress import progress_bar

    names = [s.name for s in scans]
    missing = [n for n in test_names if n not in names]
    if missing:
        raise NidarError(f"test frame(s) not among the scans: {', '.join(missing)}")
    if len(scans) < 2 or not test_names:
        raise NidarError("leave-one-out needs at least two frames and one test frame")
    rows = []
    bar = progress_bar(total=len(test_names) * len(methods), show=progress, desc="leave-one-out")
    for test in test_names:
        k = names.index(test)
        train = [s for j, s in enumerate(scans) if j != k]
        for key, m in methods.items():
            bar.set_postfix_str(f"{test}: {key}")
            predict = m.fit(train)
            rows.append(
                {"frame": test, "method": key, "label": m.label}
                | scan_metrics(scans[k], predict(scans[k]))
            )
            bar.update(1)
    bar.close()
    mean = []
    for key, m in methods.items():
        r = [row for row in rows if row["method"] == key]
        entry = {"method": key, "label": m.label, "note": m.note, "folds": len(r)}
        for metric, *_ in SCAN_METRICS:
            vals = [
                row[metric] for row in r if row[metric] is not None and math.isfinite(row[metric])
            ]
            entry[metric] = float(np.mean(vals)) if vals else None
        mean.append(entry)
    return {"folds": list(test_names), "rows": rows, "mean": mean, "train_frames": len(scans) - 1}
