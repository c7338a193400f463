"""The ``context`` profile form: a gradient-boosted regression on a return's named inputs.

A sensor-profile form (:mod:`nidar_mi.profiles`). Where the ``gbm`` form reads the model value,
range, elevation and incidence, this one reads any of the inputs of
:mod:`nidar_mi.profiles.inputs` by name: the return's range, elevation and incidence, the laser
index, the local geometry of the scan around it, the image around its pixel, and NIDAR's maps
there:

    I = clip(F(x), 0, 1)

with ``F`` a LightGBM regression on the inputs ``x`` (:attr:`ContextMap.features`; ``kind``
``"gbm"``), or a small learned head in its place (``kind`` ``"mlp"``: a two-layer perceptron,
:mod:`nidar_mi.profiles.head`, some thirty times cheaper to evaluate). The profile
file says which inputs it reads (``features``, and their ``groups``); a profile that reads the
image or NIDAR's maps (:attr:`ContextMap.needs_image`) refuses, in one line, to run without the
camera image. ``F`` is free in every input (no monotone constraint): which way the geometry and
the image act on the intensity is what it learns.

Fitting (:class:`ContextFitOptions`): :data:`DEFAULT_TREES` trees of at most
:data:`DEFAULT_LEAVES` leaves, learning rate :data:`DEFAULT_LEARNING_RATE`, at least
:data:`DEFAULT_MIN_LEAF` returns per leaf, each tree grown on :data:`DEFAULT_FEATURE_FRACTION` of
the inputs and :data:`DEFAULT_BAGGING_FRACTION` of the rows, L2 penalty :data:`DEFAULT_L2`, on
:data:`POINTS_PER_FRAME` returns drawn per frame (seeded: a frame's neighbouring returns, which
say the same thing, are thinned), every recording weighing the same (``balance="group"``: the
frames of a drive share its weight, so that 78 frames of one drive do not outweigh five of
another), deterministic and single-threaded unless ``threads`` says otherwise. The weighing and
the regularisation were chosen by nested leave one group out on the KITTI groups (each held-out
group's choice made on the other seven alone; docs/NIDAR.md, "Each drive weighs the same").
``target="rank"`` fits the per-frame rank of the intensity (in [0, 1]) instead and maps the
prediction back through the quantiles of the training intensities (:data:`QUANTILES` of them,
stored): the same ranking, on the sensor's scale. ``target="blend"`` fits both regressions on the
same rows and averages them on the sensor's scale,

    I = clip((F_I(x) + Q(F_u(x))) / 2, 0, 1),

with ``F_I`` the intensity's regression, ``F_u`` the rank's and ``Q`` the weighted quantile
function of the training intensities; the two fits err differently (the rank's does not chase the
frames' intensity scale), and their mean ranks unseen drives better than either (chosen by nested
leave one group out, docs/NIDAR.md, "Two regressions, averaged"), at twice the trees' cost.

Missing inputs (NaN: no ring, a neighbourhood without a shape) take the branch LightGBM learnt
for them; the model is stored as LightGBM's text model, checked line by line before LightGBM
parses it (:func:`nidar_mi.profiles.gbm.load_booster`), never pickled.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ..errors import NidarError
from .forest import compile_forest
from .gbm import MAX_LEAVES, MAX_TREES, lightgbm_module, load_booster, predict_threads
from .head import fit_head, head_from_dict, head_predict, head_to_dict
from .inputs import DEFAULT_INPUTS, GROUPS, IMAGE_GROUPS, feature_group

__all__ = [
    "BALANCES",
    "DEFAULT_BAGGING_FRACTION",
    "DEFAULT_FEATURE_FRACTION",
    "DEFAULT_L2",
    "DEFAULT_LEARNING_RATE",
    "DEFAULT_LEAVES",
    "DEFAULT_TARGET",
    "DEFAULT_TREES",
    "KINDS",
    "POINTS_PER_FRAME",
    "QUANTILES",
    "TARGETS",
    "ContextFitOptions",
    "ContextMap",
    "frame_rows",
    "frame_weights",
    "train_context_booster",
    "training_rows",
    "weighted_quantiles",
]

#: Boosting rounds.
DEFAULT_TREES = 400
#: Most leaves per tree.
DEFAULT_LEAVES = 63
#: Shrinkage per round.
DEFAULT_LEARNING_RATE = 0.05
#: Fewest training returns in a leaf.
DEFAULT_MIN_LEAF = 100
#: Share of the inputs each tree may split on (drawn per tree).
DEFAULT_FEATURE_FRACTION = 0.5
#: Share of the training rows each tree is grown on (drawn per tree).
DEFAULT_BAGGING_FRACTION = 0.7
#: L2 penalty on the leaves' values.
DEFAULT_L2 = 10.0
#: Training returns drawn per frame (all of a smaller frame).
POINTS_PER_FRAME = 4000
#: What the regression is fitted on: the intensity, its per-frame rank, or both averaged.
TARGETS = ("intensity", "rank", "blend")
#: The trees' target unless told (chosen by nested leave one group out).
DEFAULT_TARGET = "blend"
#: The models a context map may hold: LightGBM's trees, or the small learned head.
KINDS = ("gbm", "mlp")
#: Quantiles of the training intensities a ``rank`` map keeps (its output scale).
QUANTILES = 101
#: How the training frames weigh: each recording (``group``) alike, its frames sharing its
#: weight, or each frame alike.
BALANCES = ("group", "frame")


@dataclass(frozen=True)
class ContextFitOptions:
    """How a ``context`` map is fitted (keyword options of :func:`nidar_mi.profiles.fit`).

    Attributes:
        features: the input names to read (:mod:`nidar_mi.profiles.inputs`); None: those
            of :data:`~nidar_mi.profiles.inputs.DEFAULT_INPUTS` the fitting data give.
        target: ``"intensity"``, ``"rank"`` or ``"blend"`` (module docstring; ``blend`` with
            ``kind="gbm"`` only); None: :data:`DEFAULT_TARGET` for the trees, ``"intensity"``
            for the head.
        kind: ``"gbm"`` (LightGBM) or ``"mlp"`` (the head of :mod:`nidar_mi.profiles.head`,
            its own fixed settings).
        trees, leaves, learning_rate, min_leaf: LightGBM's rounds, leaves per tree,
            shrinkage and fewest returns per leaf (``gbm``).
        feature_fraction, bagging_fraction, l2: the share of the inputs and of the rows each
            tree sees (drawn with ``seed``) and the L2 penalty on leaf values (``gbm``).
        points_per_frame: training returns drawn per frame.
        balance: ``"group"``: every recording (the ``"group"`` labels of the fit's inputs: a
            drive, a folder) weighs the same and its frames share that weight, so that a long
            drive does not outweigh short ones; ``"frame"``: every frame weighs the same.
            Without group labels the two agree.
        threads: LightGBM's threads while fitting (the model does not depend on them).
        seed: the seed of the draw and of LightGBM.
    """

    features: tuple[str, ...] | None = None
    target: str | None = None
    kind: str = "gbm"
    trees: int = DEFAULT_TREES
    leaves: int = DEFAULT_LEAVES
    learning_rate: float = DEFAULT_LEARNING_RATE
    min_leaf: int = DEFAULT_MIN_LEAF
    feature_fraction: float = DEFAULT_FEATURE_FRACTION
    bagging_fraction: float = DEFAULT_BAGGING_FRACTION
    l2: float = DEFAULT_L2
    points_per_frame: int = POINTS_PER_FRAME
    balance: str = "group"
    threads: int = 1
    seed: int = 0

    def __post_init__(self) -> None:
        if self.target is None:
            object.__setattr__(
                self, "target", DEFAULT_TARGET if self.kind == "gbm" else "intensity"
            )
        if self.target not in TARGETS:
            raise NidarError(f"fit context: target must be one of {', '.join(TARGETS)}")
        if self.kind not in KINDS:
            raise NidarError(f"fit context: kind must be one of {', '.join(KINDS)}")
        if self.target == "blend" and self.kind != "gbm":
            raise NidarError("fit context: target 'blend' needs kind 'gbm'")
        if self.balance not in BALANCES:
            raise NidarError(f"fit context: balance must be one of {', '.join(BALANCES)}")
        if not 1 <= int(self.trees) <= MAX_TREES or not 2 <= int(self.leaves) <= MAX_LEAVES:
            raise NidarError(f"fit context: 1-{MAX_TREES} trees of 2-{MAX_LEAVES} leaves expected")
        if not 0 < self.learning_rate <= 1 or self.min_leaf < 1 or self.points_per_frame < 1:
            raise NidarError(
                "fit context: learning_rate in (0, 1], min_leaf and points_per_frame >= 1"
            )
        if int(self.threads) < 1:
            raise NidarError("fit context: threads must be at least 1")
        fractions = (self.feature_fraction, self.bagging_fraction)
        if not all(0 < f <= 1 for f in fractions) or not self.l2 >= 0:
            raise NidarError("fit context: feature_fraction, bagging_fraction in (0, 1], l2 >= 0")


def _params(o: ContextFitOptions) -> dict[str, Any]:
    return {
        "objective": "regression",
        "num_leaves": int(o.leaves),
        "learning_rate": float(o.learning_rate),
        "min_data_in_leaf": int(o.min_leaf),
        "feature_fraction": float(o.feature_fraction),
        "bagging_fraction": float(o.bagging_fraction),
        "bagging_freq": 1 if o.bagging_fraction < 1 else 0,
        "lambda_l2": float(o.l2),
        "max_bin": 255,
        "deterministic": True,
        "force_row_wise": True,
        "num_threads": int(o.threads),
        "seed": int(o.seed),
        "verbose": -1,
    }


def train_context_booster(
    x: np.ndarray,
    y: np.ndarray,
    feats: tuple[str, ...],
    o: ContextFitOptions,
    weight: np.ndarray | None = None,
):
    """A LightGBM regression of ``y`` (N,) on ``x`` (N, F) (columns ``feats``) with the
    options' settings, rows weighted by ``weight`` (N,) (None: alike); the trained
    ``lightgbm.Booster``."""
    lgb = lightgbm_module()
    data = lgb.Dataset(x, label=y, weight=weight, feature_name=list(feats), params={"verbose": -1})
    return lgb.train(_params(o), data, num_boost_round=int(o.trees))


def _rank01(y: np.ndarray) -> np.ndarray:
    """(N,) average ranks of ``y`` scaled to [0, 1] (ties share their mean rank)."""
    from scipy.stats import rankdata

    return (rankdata(y) - 1.0) / max(len(y) - 1, 1)


def frame_rows(n: int, limit: int, rng: np.random.Generator) -> np.ndarray:
    """(m,) sorted indices of the returns of a frame of ``n`` kept for training: all when
    ``n <= limit``, else ``limit`` drawn without replacement by ``rng``."""
    if n <= limit:
        return np.arange(n)
    return np.sort(rng.choice(n, limit, replace=False))


def training_rows(
    designs: Sequence[np.ndarray],
    intensities: Sequence[np.ndarray],
    o: ContextFitOptions,
    groups: Sequence[Any] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The training rows of frames: ``(x, y, w)``, at most ``o.points_per_frame`` returns of
    each frame drawn without replacement (one seeded generator over the frames in order), ``y``
    the intensity or its rank within the frame (``o.target``), ``w`` the rows' weights: a
    row weighs its frame's share (:func:`frame_weights`), scaled to a mean of 1 (all 1 when
    every frame weighs the same).

    Args:
        designs: per frame, (N_f, F) inputs.
        intensities: per frame, (N_f,) intensities in [0, 1].
        groups: per frame, the recording it belongs to (any hashable label); with
            ``o.balance == "group"`` every recording weighs the same and its frames share that
            weight equally; None (or ``balance="frame"``): every frame weighs the same.
    """
    rng = np.random.default_rng(o.seed)
    if groups is not None and len(groups) != len(designs):
        raise NidarError(f"fit context: {len(groups)} group labels for {len(designs)} frames")
    share = frame_weights(groups if o.balance == "group" else None, len(designs))
    xs, ys, ws = [], [], []
    for x, y, s in zip(designs, intensities, share, strict=True):
        y = np.asarray(y, dtype=np.float64).reshape(-1)
        if len(x) != len(y):
            raise NidarError(f"fit context: {len(x)} returns but {len(y)} intensities")
        t = _rank01(y) if o.target == "rank" else y
        keep = frame_rows(len(y), o.points_per_frame, rng)
        xs.append(x[keep])
        ys.append(t[keep])
        ws.append(np.full(len(keep), s))
    if not xs:
        raise NidarError("fit context: no frames")
    w = np.concatenate(ws)
    return np.concatenate(xs).astype(np.float64), np.concatenate(ys), w / w.mean()


def frame_weights(groups: Sequence[Any] | None, n: int) -> np.ndarray:
    """(n,) each frame's share of the training weight: ``1 / (G · n_g)`` for a frame of a
    group of ``n_g`` frames among ``G`` groups (None: ``1 / n`` each); the shares sum to 1."""
    if groups is None:
        return np.full(n, 1.0 / max(n, 1))
    labels = list(groups)
    count = {g: labels.count(g) for g in set(labels)}
    return np.array([1.0 / (len(count) * count[g]) for g in labels])


def _frames(context: Mapping[str, Any], n: int) -> tuple[list[np.ndarray], list | None]:
    """The rows of each frame of ``n`` returns (the ``"frame"`` labels of ``context``; one frame
    without them) and each frame's ``"group"`` label (None without group labels).

    Raises:
        NidarError: labels of another length, or a frame in two groups.
    """
    frame, group = context.get("frame"), context.get("group")
    labels = np.zeros(n) if frame is None else np.asarray(frame).reshape(-1)
    if labels.shape != (n,):
        raise NidarError(f"fit context: {labels.size} frame labels for {n} returns")
    _, inverse = np.unique(labels, return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    parts = np.split(order, np.flatnonzero(np.diff(inverse[order])) + 1)
    if group is None:
        return parts, None
    g = np.asarray(group).reshape(-1)
    if g.shape != (n,):
        raise NidarError(f"fit context: {g.size} group labels for {n} returns")
    if any(np.any(g[p] != g[p[0]]) for p in parts):
        raise NidarError("fit context: the returns of one frame carry different group labels")
    return parts, [g[p[0]].item() for p in parts]


@dataclass(frozen=True, eq=False)
class ContextMap:
    """A fitted ``context`` sensor response (module docstring).

    Attributes:
        features: the input names in column order.
        target: ``"intensity"`` or ``"rank"``.
        kind: ``"gbm"`` or ``"mlp"``.
        model: LightGBM's text model (``gbm``; empty for ``mlp``); a ``blend`` map's
            regression of the intensity.
        rank_model: a ``blend`` map's LightGBM text model of the per-frame rank (empty
            otherwise).
        head: the head's JSON numbers (``mlp``, :func:`nidar_mi.profiles.head.head_to_dict`;
            None for ``gbm``).
        quantiles: a ``rank`` or ``blend`` map's :data:`QUANTILES` quantiles of the training
            intensities (the rank's output scale); empty for an ``intensity`` map.
        params: the fitting parameters (for the record).
    """

    form: ClassVar[str] = "context"
    reads_incidence: ClassVar[bool] = True
    #: Whether the form reads named inputs (``context=`` of :meth:`__call__` and of the fit).
    reads_context: ClassVar[bool] = True
    fit_options: ClassVar[type] = ContextFitOptions

    features: tuple[str, ...]
    target: str
    model: str = ""
    kind: str = "gbm"
    head: Mapping[str, Any] | None = None
    quantiles: tuple[float, ...] = ()
    params: dict[str, Any] = field(default_factory=dict)
    rank_model: str = ""

    def __post_init__(self) -> None:
        feats = tuple(self.features)
        if not feats or len(set(feats)) != len(feats):
            raise NidarError("context: 'features' must be distinct input names")
        for name in feats:
            feature_group(name)  # an unknown name is an error
        object.__setattr__(self, "features", feats)
        if self.target not in TARGETS:
            raise NidarError(f"context: 'target' must be one of {', '.join(TARGETS)}")
        q = np.asarray(self.quantiles, dtype=np.float64)
        if self.target in ("rank", "blend") and (
            q.shape != (QUANTILES,) or not np.all(np.isfinite(q)) or np.any(np.diff(q) < 0)
        ):
            raise NidarError(
                f"context: a {self.target} map needs {QUANTILES} rising finite quantiles"
            )
        if bool(self.rank_model) != (self.target == "blend") or (
            self.target == "blend" and self.kind != "gbm"
        ):
            raise NidarError("context: a 'rank_model' belongs to (and only to) a gbm blend map")
        object.__setattr__(self, "quantiles", tuple(float(v) for v in q))
        if not isinstance(self.params, Mapping):
            raise NidarError("context: 'params' must be an object")
        if self.kind not in KINDS:
            raise NidarError(f"context: 'kind' must be one of {', '.join(KINDS)}")
        if self.kind == "gbm":
            if self.head is not None:
                raise NidarError("context: a gbm map holds no 'head'")
            object.__setattr__(self, "_predict", _booster_predict(self.model, feats))
            if self.rank_model:
                object.__setattr__(self, "_rank", _booster_predict(self.rank_model, feats))
        else:
            if self.model:
                raise NidarError("context: an mlp map holds no LightGBM 'model'")
            head = head_from_dict(self.head, len(feats))
            object.__setattr__(self, "_predict", lambda x: head_predict(head, x))

    @property
    def groups(self) -> tuple[str, ...]:
        """The input groups the map reads (:data:`nidar_mi.profiles.inputs.GROUPS`), in order."""
        used = {feature_group(f) for f in self.features}
        return tuple(g for g in GROUPS if g in used)

    @property
    def needs_image(self) -> bool:
        """Whether the map reads the camera image (or NIDAR's maps of it)."""
        return any(g in IMAGE_GROUPS for g in self.groups)

    @property
    def uses_incidence(self) -> bool:
        """Whether the map reads the returns' incidence cosine."""
        return "cos_incidence" in self.features

    def __call__(
        self,
        values: Any,
        range_m: Any,
        *,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
        context: Mapping[str, Any] | None = None,
    ) -> np.ndarray:
        """Intensities of returns from their named inputs.

        Args:
            values: (N,) model values (their length is checked; the map reads its inputs from
                ``context``, NIDAR's maps among them).
            range_m: (N,) ranges, m (length check).
            ring, elevation_deg, cos_incidence: not read (they are inputs in ``context``).
            context: name -> (N,) inputs, at least :attr:`features` (NaN: missing).

        Returns:
            (N,) float64 in [0, 1].

        Raises:
            NidarError: no inputs, an input missing (the image, for a map that reads it) or of
                another length.
        """
        n = np.asarray(range_m).reshape(-1).size
        if np.asarray(values).reshape(-1).size != n:
            raise NidarError("context profile: values and ranges differ in length")
        x = _design(self.features, context, n)
        out = self._predict(x)
        grid = np.linspace(0.0, 1.0, QUANTILES)
        if self.target == "rank":
            out = np.interp(np.clip(out, 0.0, 1.0), grid, np.asarray(self.quantiles))
        elif self.target == "blend":
            u = np.clip(self._rank(x), 0.0, 1.0)
            out = 0.5 * (out + np.interp(u, grid, np.asarray(self.quantiles)))
        return np.clip(out, 0.0, 1.0)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe representation: the inputs and their groups, the target, the model."""
        return (
            {
                "features": list(self.features),
                "groups": list(self.groups),
                "needs_image": self.needs_image,
                "target": self.target,
                "kind": self.kind,
                "quantiles": list(self.quantiles),
                "params": dict(self.params),
            }
            | (
                {"lightgbm": lightgbm_module().__version__, "model": self.model}
                if self.kind == "gbm"
                else {"head": dict(self.head)}
            )
            | ({"rank_model": self.rank_model} if self.rank_model else {})
        )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ContextMap:
        """Inverse of :meth:`to_dict`; :class:`NidarError` on malformed input (``groups`` and
        ``needs_image`` are checked against the features)."""
        if not isinstance(data, Mapping):
            raise NidarError("context: expected an object")
        keys = {"features", "groups", "needs_image", "target", "kind", "quantiles", "lightgbm"}
        missing = [k for k in ("features", "target") if k not in data]
        if missing or ("model" not in data and "head" not in data):
            raise NidarError(f"context: missing key(s) {', '.join(missing) or 'model'}")
        unknown = sorted(set(data) - keys - {"params", "model", "head", "rank_model"})
        if unknown:
            raise NidarError(f"context: unknown key(s) {', '.join(unknown)}")
        feats = data["features"]
        if not isinstance(feats, list) or not all(isinstance(f, str) for f in feats):
            raise NidarError("context: 'features' must be a list of input names")
        q = data.get("quantiles") or []
        if not isinstance(q, list) or not all(isinstance(v, int | float) for v in q):
            raise NidarError("context: 'quantiles' must be a list of numbers")
        out = cls(
            features=tuple(feats),
            target=data["target"],
            model=data.get("model", ""),
            kind=data.get("kind", "gbm"),
            head=data.get("head"),
            quantiles=tuple(q),
            params=data.get("params") or {},
            rank_model=data.get("rank_model", ""),
        )
        if "groups" in data and list(data["groups"]) != list(out.groups):
            raise NidarError("context: 'groups' do not match the features")
        if "needs_image" in data and data["needs_image"] is not out.needs_image:
            raise NidarError("context: 'needs_image' does not match the features")
        return out

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
        context: Mapping[str, Any] | None = None,
        options: ContextFitOptions | None = None,
    ) -> ContextMap:
        """Fit the map on training returns (:func:`nidar_mi.profiles.fit` is the entry point).

        Args:
            values, range_m: (N,) the returns' model values and ranges (length checks).
            intensity: (N,) the sensor's intensities in [0, 1].
            ring, elevation_deg, cos_incidence, input: not read (inputs are in ``context``).
            context: name -> (N,) inputs (:mod:`nidar_mi.profiles.inputs`), and optionally
                ``"frame"``: (N,) the frame of each return (any labels; without it, one frame)
                and ``"group"``: (N,) the recording of each return (any labels; the frames of
                one recording must share it; :attr:`ContextFitOptions.balance`).
            options: :class:`ContextFitOptions`.

        Raises:
            NidarError: no inputs, unknown or missing input names, mismatched lengths,
                intensities not finite, too few returns.
        """
        o = options or ContextFitOptions()
        if context is None:
            raise NidarError("fit context: the returns' named inputs are needed (context=)")
        feats = tuple(o.features) if o.features is not None else _known(context)
        y = np.asarray(intensity, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(y)):
            raise NidarError("fit context: intensities must be finite")
        if y.size < 2 * o.min_leaf:
            raise NidarError(f"fit context: {y.size} returns are too few")
        x = _design(feats, context, y.size)
        parts, groups = _frames(context, y.size)
        designs = [x[p] for p in parts]
        xt, yt, wt = training_rows(designs, [y[p] for p in parts], o, groups)
        record = {"samples": int(yt.size), "points_per_frame": int(o.points_per_frame)}
        record |= {"seed": int(o.seed), "balance": o.balance, "groups": len(set(groups or [0]))}
        weight = None if np.all(wt == 1.0) else wt
        if o.target == "blend":
            # the same draw of rows (one seed), the per-frame rank as the label
            _, ut, _ = training_rows(designs, [_rank01(y[p]) for p in parts], o, groups)
            return cls._fit_blend(feats, (xt, yt, ut, wt), o, record)
        q = np.quantile(y, np.linspace(0, 1, QUANTILES)) if o.target == "rank" else ()
        if o.kind == "mlp":
            head = fit_head(xt, yt, seed=o.seed, threads=o.threads, weight=weight)
            head = head_to_dict(head)
            return cls(
                features=feats,
                target=o.target,
                kind="mlp",
                head=head,
                quantiles=tuple(float(v) for v in q),
                params=record,
            )
        booster = train_context_booster(xt, yt, feats, o, weight)
        record |= {k: v for k, v in _params(o).items() if k not in ("verbose", "num_threads")}
        record["trees"] = int(booster.num_trees())
        return cls(
            features=feats,
            target=o.target,
            model=booster.model_to_string(),
            quantiles=tuple(float(v) for v in q),
            params=record,
        )

    @classmethod
    def _fit_blend(cls, feats, rows, o: ContextFitOptions, record: dict) -> ContextMap:
        """A ``blend`` map from training ``rows`` = (x (N, F), intensity (N,), per-frame rank
        (N,), weight (N,)): both regressions on the same rows, the weighted quantiles of the
        intensities as the rank's scale."""
        x, y, u, w = rows
        weight = None if np.all(w == 1.0) else w
        level = train_context_booster(x, y, feats, o, weight)
        rank = train_context_booster(x, u, feats, o, weight)
        record |= {k: v for k, v in _params(o).items() if k not in ("verbose", "num_threads")}
        record["trees"] = int(level.num_trees()) + int(rank.num_trees())
        return cls(
            features=feats,
            target="blend",
            model=level.model_to_string(),
            rank_model=rank.model_to_string(),
            quantiles=tuple(float(v) for v in weighted_quantiles(y, w, QUANTILES)),
            params=record,
        )


def weighted_quantiles(y: np.ndarray, w: np.ndarray, n: int) -> np.ndarray:
    """(n,) the quantiles at ``linspace(0, 1, n)`` of values ``y`` (N,) weighted by ``w`` (N,)
    (the midpoint rule of the weighted empirical distribution; equal weights give
    ``np.quantile``'s ``hazen`` estimate)."""
    order = np.argsort(y, kind="stable")
    ys, ws = np.asarray(y, np.float64)[order], np.asarray(w, np.float64)[order]
    c = np.cumsum(ws)
    return np.interp(np.linspace(0.0, 1.0, n), (c - 0.5 * ws) / c[-1], ys)


def _design(features: tuple[str, ...], context: Mapping[str, Any] | None, n: int) -> np.ndarray:
    """(n, F) float64 inputs in ``features`` order; an error naming what is missing."""
    missing = [f for f in features if context is None or f not in context]
    if missing:
        groups = sorted({feature_group(f) for f in missing})
        if any(g in IMAGE_GROUPS for g in groups):
            raise NidarError(
                "context profile: this profile reads the camera image "
                f"({', '.join(g for g in groups if g in IMAGE_GROUPS)} inputs); give the "
                "image of a camera that sees the returns"
            )
        raise NidarError(f"context profile: inputs missing: {', '.join(missing)}")
    cols = [np.asarray(context[f], dtype=np.float64).reshape(-1) for f in features]
    if any(c.shape != (n,) for c in cols):
        raise NidarError(f"context profile: every input needs {n} values")
    x = np.stack(cols, axis=1)
    if np.isinf(x).any():
        raise NidarError("context profile: inputs must be finite or NaN (missing)")
    return x


def _booster_predict(model: str, feats: tuple[str, ...]):
    """The prediction function of a checked LightGBM text model on ``feats``: its compiled
    :class:`~nidar_mi.profiles.forest.Forest` (LightGBM's predictions, bit for bit), or the
    booster's own ``predict`` without numba."""
    booster = load_booster(model, feats, missing=True)
    forest = functools.cache(lambda: compile_forest(model, len(feats)))  # at the first call

    def predict(x: np.ndarray) -> np.ndarray:
        if forest() is not None:
            return forest()(x, threads=predict_threads())
        return np.asarray(booster.predict(x, num_threads=predict_threads()), np.float64)

    return predict


def _known(context: Mapping[str, Any]) -> tuple[str, ...]:
    """The names of ``context`` that are default inputs
    (:data:`~nidar_mi.profiles.inputs.DEFAULT_INPUTS`), in their order."""
    return tuple(f for f in DEFAULT_INPUTS if f in context)
