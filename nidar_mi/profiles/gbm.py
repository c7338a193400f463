"""The ``gbm`` profile form: a gradient-boosted regression on the value and the return's geometry.

A sensor-profile form (:mod:`nidar_mi.profiles`). A model value ``v``
(reflectance-like) at a return of range ``d`` (m) and elevation ``e`` (degrees above the
sensor's xy plane, from the return's xyz in the sensor frame, so any sensor has it, with or
without rings) becomes the sensor's intensity

    I = clip(F(v, d, e), 0, 1)

where ``F`` is a LightGBM regression (least squares: the conditional mean of the training
intensities given the features) of a bounded size (:data:`DEFAULT_TREES` trees of at most
:data:`DEFAULT_LEAVES` leaves). Where :class:`~nidar_mi.profiles.range_ring.RangeRingMap` maps
quantiles per range bin and a gain per ring, ``F`` learns the range response, the per-laser
(per-elevation) response and their interaction with the value jointly; being a conditional mean
rather than a quantile map it also shrinks towards the mean where the value says little, which
is what RMSE and SSIM reward.

* ``monotone`` (default on): ``F`` is constrained non-decreasing in ``v`` (LightGBM's
  ``monotone_constraints``), so at one range and elevation a surface the model ranks brighter
  never comes out darker: the ranking of surfaces stays the model's.
* A **geometry-only** map (``use_value=False``) has the features ``(d, e)`` only: what a profile
  knows without any image (it ignores the values it is given).
* An **incidence-aware** map (fitted with ``cos_incidence=``) also reads ``c = |cos θ|``, the cosine of
  the angle between the ray and the surface normal at the return
  (:func:`nidar_mi.geometry.incidence_cosine`, normals estimated from the scan's own points):
  ``I = clip(F(v, d, e, c), 0, 1)``, constrained non-decreasing in ``c`` (a surface seen more
  head-on never comes out darker). The image carries the surface, the scan its orientation.
* A **value-and-incidence** map (``use_geometry=False``, with ``cos_incidence=``) reads
  ``(v, c)`` only: ``I = clip(F(v, c), 0, 1)``, the form of a range-compensated intensity
  ``g·ρ·cos θ`` with ``F`` in place of the product. It learns nothing about the range response,
  the lasers or where the training scenes put their surfaces, so it carries over to sensors
  and scenes of another layout (the simulator's ``sim-905``).

Fitting is deterministic (``deterministic``, one thread, row-wise histograms, a fixed seed, no
bagging): the same data and seed give the same model text. Prediction reads a lookup table when
the trees' split thresholds cut the feature space into at most :data:`MAX_TABLE_CELLS` cells
(:class:`_CellTable`: every return in a cell takes the same branch in every tree, so the cell's
value, LightGBM's own prediction at one point of it, is exactly LightGBM's prediction for any
return in it; the shipped value-and-incidence profile has about 3 500 cells and predicts in well
under a millisecond, LightGBM itself takes tens). Larger maps go to LightGBM with up to 8 threads
(at most ``$OMP_NUM_THREADS``; rows are independent: the same output with any number). The map is
stored in a profile file as LightGBM's own text model (``Booster.model_to_string``) with the features it reads; nothing
is pickled. :meth:`GbmMap.from_dict` checks the text before LightGBM parses it and turns any
failure into one :class:`~nidar_mi.errors.NidarError` line.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ..errors import NidarError
from ..extras import missing_extra

__all__ = [
    "DEFAULT_LEAVES",
    "DEFAULT_TREES",
    "FEATURES",
    "GEOMETRY_FEATURES",
    "INCIDENCE_FEATURE",
    "VALUE_INCIDENCE_FEATURES",
    "GbmFitOptions",
    "GbmMap",
]

#: Features of a map with the value, in column order: value, range (m), elevation (degrees).
FEATURES = ("v", "range_m", "elevation_deg")
#: Features of a geometry-only map.
GEOMETRY_FEATURES = ("range_m", "elevation_deg")
#: Boosting rounds (trees).
DEFAULT_TREES = 200
#: Most leaves per tree.
DEFAULT_LEAVES = 31
#: Shrinkage per round.
DEFAULT_LEARNING_RATE = 0.1
#: Fewest training returns in a leaf (returns of one frame are correlated: keep leaves broad).
DEFAULT_MIN_LEAF = 100
#: At most this many training returns are used (a seeded subsample beyond), bounding memory.
DEFAULT_MAX_SAMPLES = 2_000_000
#: Bounds on what a profile file may hold (a larger map is not one this module wrote).
MAX_TREES = 1000
MAX_LEAVES = 255
MAX_MODEL_CHARS = 8_000_000
#: Most cells of the prediction lookup table (:class:`_CellTable`); a map with more is evaluated
#: by LightGBM.
MAX_TABLE_CELLS = 1 << 17
#: The incidence feature (``|cos θ|`` of the ray on the surface), last column when used.
INCIDENCE_FEATURE = "cos_incidence"
#: Features of a value-and-incidence map (no range, no elevation).
VALUE_INCIDENCE_FEATURES = ("v", INCIDENCE_FEATURE)
_FEATURE_SETS = (
    FEATURES,
    GEOMETRY_FEATURES,
    (*FEATURES, INCIDENCE_FEATURE),
    (*GEOMETRY_FEATURES, INCIDENCE_FEATURE),
    VALUE_INCIDENCE_FEATURES,
)


def lightgbm_module():
    try:
        import lightgbm
    except ImportError:  # the `nidar` extra
        raise NidarError(missing_extra("nidar", "the gbm profile form", ("lightgbm",))) from None
    return lightgbm


def _params(
    features: tuple[str, ...],
    monotone: bool,
    *,
    leaves: int,
    learning_rate: float,
    min_leaf: int,
    seed: int,
) -> dict[str, Any]:
    p = {
        "objective": "regression",
        "num_leaves": int(leaves),
        "learning_rate": float(learning_rate),
        "min_data_in_leaf": int(min_leaf),
        "max_bin": 255,
        "bagging_fraction": 1.0,
        "feature_fraction": 1.0,
        "deterministic": True,
        "force_row_wise": True,
        "num_threads": 1,
        "seed": int(seed),
        "verbose": -1,
    }
    signs = [int((f == "v" and monotone) or f == INCIDENCE_FEATURE) for f in features]
    if any(signs):
        p["monotone_constraints"] = signs
        p["monotone_constraints_method"] = "basic"
    return p


@dataclass(frozen=True)
class GbmFitOptions:
    """How a ``gbm`` map is fitted (keyword options of :func:`nidar_mi.profiles.fit`).

    Attributes:
        use_value: False: a geometry-only map of ``(range_m, elevation_deg)``.
        use_geometry: False: a value-and-incidence map of ``(v, cos_incidence)`` (needs
            ``cos_incidence`` and the value; the ranges only set the number of returns).
        monotone: constrain the map non-decreasing in the value.
        trees: boosting rounds, 1 to :data:`MAX_TREES`.
        leaves: most leaves per tree, 2 to :data:`MAX_LEAVES`.
        learning_rate: shrinkage per round, in (0, 1].
        min_leaf: fewest training returns per leaf.
        max_samples: returns beyond this are subsampled (seeded) before fitting.
        seed: the seed of the subsample and of LightGBM.
    """

    use_value: bool = True
    use_geometry: bool = True
    monotone: bool = True
    trees: int = DEFAULT_TREES
    leaves: int = DEFAULT_LEAVES
    learning_rate: float = DEFAULT_LEARNING_RATE
    min_leaf: int = DEFAULT_MIN_LEAF
    max_samples: int = DEFAULT_MAX_SAMPLES
    seed: int = 0


@dataclass(frozen=True, eq=False)
class GbmMap:
    """A fitted gradient-boosted sensor response (module docstring).

    Attributes:
        features: the feature names in column order: :data:`FEATURES` or
            :data:`GEOMETRY_FEATURES` (geometry only), each optionally followed by
            :data:`INCIDENCE_FEATURE`, or :data:`VALUE_INCIDENCE_FEATURES`.
        monotone: whether the map was constrained non-decreasing in ``v``.
        model: LightGBM's text model (``Booster.model_to_string``).
        params: the fitting parameters (for the record).
    """

    #: The form's name in a profile file.
    form: ClassVar[str] = "gbm"
    #: Whether the form can read the returns' incidence cosines.
    reads_incidence: ClassVar[bool] = True
    #: The keyword options of its :meth:`fit`.
    fit_options: ClassVar[type] = GbmFitOptions

    features: tuple[str, ...]
    monotone: bool
    model: str
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        feats = tuple(self.features)
        if feats not in _FEATURE_SETS:
            raise NidarError(
                f"gbm: features must be {list(FEATURES)} or {list(GEOMETRY_FEATURES)}, "
                f"optionally followed by '{INCIDENCE_FEATURE}', or "
                f"{list(VALUE_INCIDENCE_FEATURES)} (got {list(feats)})"
            )
        object.__setattr__(self, "features", feats)
        if not isinstance(self.monotone, bool):
            raise NidarError("gbm: 'monotone' must be true or false")
        if not isinstance(self.params, Mapping):
            raise NidarError("gbm: 'params' must be an object")
        object.__setattr__(self, "_booster", load_booster(self.model, feats))

    @property
    def uses_value(self) -> bool:
        """Whether the map reads the model value (False: geometry only)."""
        return self.features[0] == "v"

    @property
    def uses_geometry(self) -> bool:
        """Whether the map reads the range and elevation (False: value and incidence only)."""
        return "range_m" in self.features

    @property
    def uses_incidence(self) -> bool:
        """Whether the map reads the returns' incidence cosine."""
        return self.features[-1] == INCIDENCE_FEATURE

    @property
    def n_trees(self) -> int:
        """Number of trees."""
        return int(self._booster.num_trees())

    def __call__(
        self,
        values: Any,
        range_m: Any,
        *,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
    ) -> np.ndarray:
        """Intensities of returns (module docstring).

        Args:
            values: (N,) model values (ignored by a geometry-only map).
            range_m: (N,) ranges, m.
            ring: ignored (the elevation stands for the laser).
            elevation_deg: (N,) elevations above the sensor's xy plane, degrees; required
                unless the map reads the value and incidence only.
            cos_incidence: (N,) ``|cos θ|`` in [0, 1]; required by an incidence-aware map,
                ignored otherwise.

        Returns:
            (N,) float64 in [0, 1].

        Raises:
            NidarError: no elevations (or incidences, for a map that reads them), mismatched
                lengths or non-finite inputs.
        """
        if elevation_deg is None and self.uses_geometry:
            raise NidarError("gbm profile: the returns' elevations are needed")
        if self.uses_incidence and cos_incidence is None:
            raise NidarError("gbm profile: this profile reads the returns' incidence cosines")
        x = _design(
            values,
            range_m,
            elevation_deg,
            self.uses_value,
            "gbm profile",
            cos_incidence if self.uses_incidence else None,
            use_geometry=self.uses_geometry,
        )
        return np.clip(self._predict(x), 0.0, 1.0)

    def _predict(self, x: np.ndarray) -> np.ndarray:
        """(N,) float64 raw predictions of the (N, F) design matrix: the lookup table when the
        map has one (built at the first call), else LightGBM."""
        table = getattr(self, "_table", None)
        if table is None:
            table = _CellTable.build(self._booster, self.model, len(self.features))
            object.__setattr__(self, "_table", table)
        if table:
            return table(x)
        out = self._booster.predict(x, num_threads=predict_threads())
        return np.asarray(out, dtype=np.float64)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe representation: the features, the flag, the parameters, the model text."""
        return {
            "features": list(self.features),
            "monotone": self.monotone,
            "lightgbm": lightgbm_module().__version__,
            "params": dict(self.params),
            "model": self.model,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GbmMap:
        """Inverse of :meth:`to_dict`; :class:`NidarError` on malformed input."""
        if not isinstance(data, Mapping):
            raise NidarError("gbm: expected an object")
        missing = [k for k in ("features", "monotone", "model") if k not in data]
        if missing:
            raise NidarError(f"gbm: missing key(s) {', '.join(missing)}")
        unknown = sorted(set(data) - {"features", "monotone", "lightgbm", "params", "model"})
        if unknown:
            raise NidarError(f"gbm: unknown key(s) {', '.join(unknown)}")
        feats = data["features"]
        if not isinstance(feats, list) or not all(isinstance(f, str) for f in feats):
            raise NidarError("gbm: 'features' must be a list of names")
        return cls(
            features=tuple(feats),
            monotone=data["monotone"],
            model=data["model"],
            params=data.get("params") or {},
        )

    @classmethod
    def fit(
        cls,
        values: Any,
        range_m: Any,
        intensity: Any,
        *,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
        input: str = "R",
        options: GbmFitOptions | None = None,
    ) -> GbmMap:
        """Fit the map on training returns (least squares, deterministic;
        :func:`nidar_mi.profiles.fit` is the entry point).

        Args:
            values: (N,) model values at the returns (ignored with ``use_value=False``).
            range_m: (N,) their ranges, m.
            intensity: (N,) the sensor's intensities there, in [0, 1].
            ring, input: not read by this form (the elevation stands for the laser).
            elevation_deg: (N,) their elevations above the sensor's xy plane, degrees (unused
                with ``use_geometry=False``).
            cos_incidence: (N,) ``|cos θ|`` of the returns in [0, 1]: given, the map is
                incidence-aware (module docstring); None: it is not.
            options: the fitting options (:class:`GbmFitOptions`; default its defaults).

        Raises:
            NidarError: mismatched, empty or non-finite inputs, or parameters out of range.
        """
        o = options or GbmFitOptions()
        _check_options(
            o, has_incidence=cos_incidence is not None, has_elevation=elevation_deg is not None
        )
        x = _design(
            values,
            range_m,
            elevation_deg,
            o.use_value,
            "fit gbm",
            cos_incidence,
            use_geometry=o.use_geometry,
        )
        y = _training_intensities(intensity, x.shape[0], o.min_leaf)
        if y.size > o.max_samples:
            rng = np.random.default_rng(o.seed)
            keep = np.sort(rng.choice(y.size, o.max_samples, replace=False))
            x, y = x[keep], y[keep]
        feats = FEATURES if o.use_value else GEOMETRY_FEATURES
        if cos_incidence is not None:
            feats = (*feats, INCIDENCE_FEATURE) if o.use_geometry else VALUE_INCIDENCE_FEATURES
        model, record = _train(x, y, feats, o)
        return cls(
            features=feats,
            monotone=bool(o.monotone and o.use_value),
            model=model,
            params=record,
        )


def _check_options(o: GbmFitOptions, *, has_incidence: bool, has_elevation: bool) -> None:
    """Refuse options out of range, or a feature set the data cannot give."""
    if not o.use_geometry and (not has_incidence or not o.use_value):
        raise NidarError(
            "fit gbm: a map without range and elevation reads the value and the incidence"
        )
    if not has_elevation and o.use_geometry:
        raise NidarError("fit gbm: the returns' elevations are needed")
    if not 1 <= int(o.trees) <= MAX_TREES or not 2 <= int(o.leaves) <= MAX_LEAVES:
        raise NidarError(f"fit gbm: 1-{MAX_TREES} trees of 2-{MAX_LEAVES} leaves expected")
    if not 0 < o.learning_rate <= 1 or o.min_leaf < 1 or o.max_samples < 1:
        raise NidarError("fit gbm: learning_rate in (0, 1], min_leaf and max_samples >= 1")


def _training_intensities(intensity: Any, n: int, min_leaf: int) -> np.ndarray:
    """(N,) float64 training intensities, one per row of the design matrix."""
    y = np.asarray(intensity, dtype=np.float64).reshape(-1)
    if y.shape != (n,) or not y.size:
        raise NidarError(f"fit gbm: {n} returns but {y.size} intensities")
    if not np.all(np.isfinite(y)):
        raise NidarError("fit gbm: intensities must be finite")
    if y.size < 2 * min_leaf:
        raise NidarError(
            f"fit gbm: {y.size} returns are too few for leaves of at least {min_leaf} returns "
            f"(need {2 * min_leaf}; fewer returns fit a constant)"
        )
    return y


def train_booster(x: np.ndarray, y: np.ndarray, feats: tuple[str, ...], o: GbmFitOptions):
    """A LightGBM regression of ``y`` on ``x`` with the ``gbm`` form's settings.

    Args:
        x: (N, F) float64 design matrix, one column per name in ``feats``.
        y: (N,) targets.
        feats: the F feature names; ``"v"`` (when ``o.monotone``) and the incidence are
            constrained non-decreasing.
        o: the fit's options (leaves, learning rate, leaf size, rounds, seed).

    Returns:
        The trained ``lightgbm.Booster`` (single-threaded, deterministic).
    """
    params = _params(
        feats,
        o.monotone,
        leaves=o.leaves,
        learning_rate=o.learning_rate,
        min_leaf=o.min_leaf,
        seed=o.seed,
    )
    lgb = lightgbm_module()
    data = lgb.Dataset(x, label=y, feature_name=list(feats), params={"verbose": -1})
    return lgb.train(params, data, num_boost_round=int(o.trees))


def _train(
    x: np.ndarray, y: np.ndarray, feats: tuple[str, ...], o: GbmFitOptions
) -> tuple[str, dict[str, Any]]:
    """LightGBM on the design matrix ``x`` (N, F): its text model and the parameters recorded
    in the profile file."""
    booster = train_booster(x, y, feats, o)
    record = {
        "num_leaves": int(o.leaves),
        "learning_rate": float(o.learning_rate),
        "min_data_in_leaf": int(o.min_leaf),
        "max_bin": 255,
        "seed": int(o.seed),
    } | {"trees": int(booster.num_trees()), "samples": int(y.size)}
    return booster.model_to_string(), record


#: LightGBM reads a feature value of at most this magnitude as 0 (``kZeroThreshold``).
_ZERO_THRESHOLD = 1e-35


@dataclass(frozen=True)
class _CellTable:
    """A map's predictions as a lookup table over the cells of its split thresholds.

    LightGBM sends a value ``x`` of feature ``j`` left at a split when ``x <= t``. With
    ``th_j`` the sorted distinct thresholds of feature ``j``, ``i_j = #{t in th_j : t < x}``
    fixes every such decision (the thresholds ``t >= x`` are ``th_j[i_j:]``), so the returns of
    one cell ``(i_0, ..., i_{F-1})`` share one leaf in every tree and one prediction.

    Attributes:
        thresholds: per feature, the sorted distinct split thresholds.
        values: (prod(len(th_j) + 1),) float64 LightGBM's predictions, one per cell, in C
            order of the cell index.
    """

    thresholds: tuple[np.ndarray, ...]
    values: np.ndarray

    def __bool__(self) -> bool:
        return self.values.size > 0

    @classmethod
    def build(cls, booster, text: str, n_features: int) -> _CellTable:
        """The table of a booster and its model text; an empty table (falsy) beyond
        :data:`MAX_TABLE_CELLS` cells."""
        th = _split_thresholds(text, n_features)
        cells = int(np.prod([len(t) + 1 for t in th], dtype=np.float64))
        if cells > MAX_TABLE_CELLS:
            return cls(th, np.zeros(0))
        # one point per cell: th_j[i] for i < len(th_j) (no threshold below it is >= it), and
        # one beyond the largest threshold
        reps = [np.append(t, t[-1] + abs(t[-1]) + 1.0) if len(t) else np.zeros(1) for t in th]
        grid = np.stack([g.ravel() for g in np.meshgrid(*reps, indexing="ij")], axis=1)
        values = booster.predict(grid, num_threads=predict_threads())
        return cls(th, np.asarray(values, dtype=np.float64))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """(N,) float64 predictions of an (N, F) finite design matrix."""
        x = np.where(np.abs(x) <= _ZERO_THRESHOLD, 0.0, x)  # as LightGBM reads its rows
        index = np.zeros(len(x), dtype=np.int64)
        for j, t in enumerate(self.thresholds):
            index = index * (len(t) + 1) + np.searchsorted(t, x[:, j], side="left")
        return self.values[index]


def _split_thresholds(text: str, n_features: int) -> tuple[np.ndarray, ...]:
    """Per feature, the sorted distinct split thresholds of a checked LightGBM text model."""
    feats, ths = [], []
    for line in text.split("\n"):
        if line.startswith("split_feature="):
            feats.extend(int(v) for v in line[len("split_feature=") :].split())
        elif line.startswith("threshold="):
            ths.extend(float(v) for v in line[len("threshold=") :].split())
    f, t = np.asarray(feats, dtype=np.int64), np.asarray(ths, dtype=np.float64)
    return tuple(np.unique(t[f == j]) for j in range(n_features))


def predict_threads() -> int:
    """Threads for prediction: the cores this process may use, at most 8 and at most
    ``$OMP_NUM_THREADS`` when set (rows are independent, so the output does not depend on it)."""
    import os

    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        n = os.cpu_count() or 1
    omp = os.environ.get("OMP_NUM_THREADS", "")
    if omp.isdigit() and int(omp) > 0:
        n = min(n, int(omp))
    return max(1, min(8, n))


def _design(
    values,
    range_m,
    elevation_deg,
    use_value: bool,
    who: str,
    cos_incidence=None,
    *,
    use_geometry: bool = True,
) -> np.ndarray:
    """(N, F) float64 feature matrix in a feature set's column order; checks lengths, finiteness
    and the incidence range. Without the geometry the ranges still set the expected length."""
    d = np.asarray(range_m, dtype=np.float64).reshape(-1)
    cols = [d, np.asarray(elevation_deg, dtype=np.float64).reshape(-1)] if use_geometry else []
    if use_value:
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        cols.insert(0, v)
    if cos_incidence is not None:
        c = np.asarray(cos_incidence, dtype=np.float64).reshape(-1)
        cols.append(c)
    if not cols or any(c.shape != d.shape for c in cols):
        raise NidarError(f"{who}: values, ranges, elevations and incidences differ in length")
    x = np.stack(cols, axis=1)
    if not np.all(np.isfinite(x)):
        raise NidarError(f"{who}: values, ranges, elevations and incidences must be finite")
    if cos_incidence is not None and not np.all((x[:, -1] >= 0) & (x[:, -1] <= 1)):
        raise NidarError(f"{who}: incidence cosines must lie in [0, 1]")
    return x


_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_INT = re.compile(r"-?\d+")
_FLOAT = re.compile(_NUM)
#: The lines of one tree of LightGBM's text model, in order (numerical splits only).
_TREE_KEYS = (
    "num_leaves",
    "num_cat",
    "split_feature",
    "split_gain",
    "threshold",
    "decision_type",
    "left_child",
    "right_child",
    "leaf_value",
    "leaf_weight",
    "leaf_count",
    "internal_value",
    "internal_weight",
    "internal_count",
    "is_linear",
    "shrinkage",
)


def _numbers(text: str, pattern: re.Pattern, what: str) -> list[float]:
    items = text.split(" ") if text else []
    if not all(pattern.fullmatch(x) for x in items):
        raise NidarError(f"gbm: malformed numbers in '{what}'")
    vals = [float(x) for x in items]
    if not all(np.isfinite(vals)):
        raise NidarError(f"gbm: non-finite numbers in '{what}'")
    return vals


def _check_tree(block: str, k: int, n_features: int, missing: bool = False) -> None:
    """Checks one ``Tree=k`` block: every field, lengths, a proper binary tree; ``missing``:
    numerical splits may send missing values (NaN) one way (LightGBM's missing type)."""
    lines = block.rstrip("\n").split("\n")
    if lines[0] != f"Tree={k}" or len(lines) != len(_TREE_KEYS) + 1:
        raise NidarError(f"gbm: tree {k} is malformed")
    f = {}
    for key, line in zip(_TREE_KEYS, lines[1:]):
        name, sep, val = line.partition("=")
        if name != key or not sep:
            raise NidarError(f"gbm: tree {k}: expected '{key}=' (got {line[:40]!r})")
        f[key] = val
    (n_leaves,) = _numbers(f["num_leaves"], _INT, "num_leaves") or [0]
    n_leaves = int(n_leaves)
    if not 1 <= n_leaves <= MAX_LEAVES or f["num_cat"] != "0" or f["is_linear"] != "0":
        raise NidarError(f"gbm: tree {k}: 1 to {MAX_LEAVES} leaves, numerical splits expected")
    n_int = n_leaves - 1
    ints = {
        key: _numbers(f[key], _INT, key)
        for key in ("split_feature", "decision_type", "left_child", "right_child")
    }
    for key in ("split_gain", "threshold", "internal_value", "internal_weight"):
        if len(_numbers(f[key], _FLOAT, key)) != n_int:
            raise NidarError(f"gbm: tree {k}: '{key}' needs {n_int} numbers")
    if len(_numbers(f["internal_count"], _INT, "internal_count")) != n_int:
        raise NidarError(f"gbm: tree {k}: 'internal_count' needs {n_int} numbers")
    if len(_numbers(f["leaf_value"], _FLOAT, "leaf_value")) != n_leaves:
        raise NidarError(f"gbm: tree {k}: 'leaf_value' needs {n_leaves} numbers")
    if len(_numbers(f["leaf_weight"], _FLOAT, "leaf_weight")) not in (0, n_leaves) or len(
        _numbers(f["leaf_count"], _INT, "leaf_count")
    ) not in (0, n_leaves):
        raise NidarError(f"gbm: tree {k}: one weight and count per leaf expected")
    _numbers(f["shrinkage"], _FLOAT, "shrinkage")
    if any(len(v) != n_int for v in ints.values()):
        raise NidarError(f"gbm: tree {k}: one split per internal node expected")
    if any(not 0 <= int(j) < n_features for j in ints["split_feature"]):
        raise NidarError(f"gbm: tree {k}: split on a feature the model does not have")
    kinds = (0, 2, 8, 10) if missing else (0, 2)  # bit 1: default left; bits 2-3: NaN missing
    if any(int(t) not in kinds for t in ints["decision_type"]):
        raise NidarError(f"gbm: tree {k}: only numerical splits without missing values")
    # every node but the root, and every leaf, is a child exactly once, of an earlier node
    seen_nodes, seen_leaves = set(), set()
    for i, (a, b) in enumerate(zip(ints["left_child"], ints["right_child"])):
        for c in (int(a), int(b)):
            if c >= 0:
                if not i < c < n_int or c in seen_nodes:
                    raise NidarError(f"gbm: tree {k}: not a binary tree")
                seen_nodes.add(c)
            else:
                if not 0 <= ~c < n_leaves or ~c in seen_leaves:
                    raise NidarError(f"gbm: tree {k}: not a binary tree")
                seen_leaves.add(~c)
    if len(seen_nodes) != max(n_int - 1, 0) or (n_int and len(seen_leaves) != n_leaves):
        raise NidarError(f"gbm: tree {k}: not a binary tree")


def _check_model_text(text: Any, features: tuple[str, ...], missing: bool = False) -> str:
    """The header and trees of a LightGBM text model, after checking every line of them
    (``missing``: splits may route missing values, :func:`_check_tree`).

    LightGBM's own parser can abort the process on a malformed text, so nothing reaches it
    that is not, line by line, a regression model of numerical splits on ``features``.
    """
    if not isinstance(text, str) or not text:
        raise NidarError("gbm: 'model' must be LightGBM's text model")
    if len(text) > MAX_MODEL_CHARS:
        raise NidarError(f"gbm: model text over {MAX_MODEL_CHARS} characters")
    body, sep, _ = text.partition("end of trees\n")
    head, sep2, trees = body.partition("\n\n")
    if not sep or not sep2 or not head.startswith("tree\n"):
        raise NidarError("gbm: 'model' is not a LightGBM text model")
    h = {}
    for line in head.split("\n")[1:]:
        key, eq, val = line.partition("=")
        if not eq or key in h:
            raise NidarError("gbm: malformed model header")
        h[key] = val
    expect = {
        "version": "v4",
        "num_class": "1",
        "num_tree_per_iteration": "1",
        "label_index": "0",
        "max_feature_idx": str(len(features) - 1),
        "feature_names": " ".join(features),
    }
    bad = [k for k, v in expect.items() if h.get(k) != v]
    if bad or h.get("objective", "").split(" ")[0] != "regression":
        raise NidarError(
            f"gbm: the model is not a regression on {list(features)} ({', '.join(bad) or 'objective'})"
        )
    if set(h) - set(expect) - {"objective", "monotone_constraints", "feature_infos", "tree_sizes"}:
        raise NidarError("gbm: unknown lines in the model header")
    if "monotone_constraints" in h:
        signs = _numbers(h["monotone_constraints"], _INT, "monotone_constraints")
        if len(signs) != len(features) or any(v not in (-1, 0, 1) for v in signs):
            raise NidarError(
                f"gbm: 'monotone_constraints' needs one of -1, 0, 1 per feature ({len(features)})"
            )
    sizes = [int(x) for x in _numbers(h.get("tree_sizes", ""), _INT, "tree_sizes")]
    if not 1 <= len(sizes) <= MAX_TREES:
        raise NidarError(f"gbm: the model has {len(sizes)} trees (1 to {MAX_TREES} expected)")
    if (
        any(n <= 0 for n in sizes)
        or sum(sizes) != len(trees.encode("utf-8"))
        or not trees.isascii()
    ):
        raise NidarError("gbm: the trees do not match the model's tree_sizes")
    pos = 0
    for k, n in enumerate(sizes):
        _check_tree(trees[pos : pos + n], k, len(features), missing)
        pos += n
    return body + sep


def load_booster(text: Any, features: tuple[str, ...], missing: bool = False):
    """LightGBM booster of a model text, after checks that it is one this module could write
    (``missing``: or one whose splits route missing values, the ``context`` form's)."""
    checked = _check_model_text(text, features, missing)
    lgb = lightgbm_module()
    try:
        booster = lgb.Booster(model_str=checked)
    except Exception as e:  # LightGBMError, ValueError: a malformed text
        msg = str(e).strip().splitlines()
        raise NidarError(
            f"gbm: LightGBM cannot read the model ({msg[0] if msg else type(e).__name__})"
        ) from None
    if booster.num_feature() != len(features) or booster.num_trees() < 1:
        raise NidarError(f"gbm: the model reads {booster.num_feature()} features")
    return booster
