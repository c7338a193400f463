"""Leave-one-frame-out rows for an IRNet trained per fold on the real frames.

:func:`irnet_methods` gives :class:`~nidar_mi.eval.loo.LooMethod` rows for
:func:`~nidar_mi.eval.loo.leave_one_out`: in each fold an IRNet is trained on the fold's
training frames only (:func:`nidar_mi.nidar.training.train_irnet` with the fold's frame list, a
fixed STN, the given configuration: e.g. a compact ``unet`` at quarter resolution) and its
maps at the returns feed the rows:

* ``irnet_R_<form>``: the reflectance branch ``R`` through a sensor profile of ``form`` fitted
  on the fold's training frames (:func:`~nidar_mi.eval.loo.profile_method`);
* ``irnet_I_hat_raw``: the dense intensity head ``Î`` itself, clipped to [0, 1];
* ``irnet_I_hat_<form>``: ``Î`` through a profile of ``form``;
* ``irnet_R_gbm_inc`` (with the ``gbm`` form): ``R`` through an incidence-aware ``gbm`` profile
  (the returns' ``|cos θ|`` from normals estimated on each scan).

One network is trained per fold and serves every row of that fold (:class:`FoldModels`). Each
fold's run lives in ``WORK/fold-<held-out frame>`` (weights, log, checkpoints: an interrupted
evaluation resumes where it stopped, a finished fold is reused); the pseudo-NIR cache is shared
by the folds (``WORK/cache``). No row is scored on a frame its network or profile was fitted on.
"""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import NidarError
from ..io.cache_key import file_sha256
from .loo import CachedValues, LooMethod, profile_method, raw_method

__all__ = ["FoldModels", "irnet_methods"]

log = logging.getLogger(__name__)


@dataclass
class FoldModels:
    """IRNet trained per fold, on demand, and its maps at the returns.

    Attributes:
        cfg: training configuration (a :class:`~nidar_mi.nidar.config.TrainConfig`).
        data_dir: the data folder the scans come from (:func:`nidar_mi.datasets.scans.frames_from_data`;
            a scan's ``source`` is its frame file).
        work_dir: where the folds' runs are written.
        stn_weights: the STN every fold uses (fixed; fitted on other data).
        progress: show training progress bars.
        init_weights: IRNet weights every fold starts from (e.g. pretrained on renders; not
            fitted on any real frame), None for a random initialisation.
        render_frames: rendered frames every fold mixes in to supervise the decomposition
            (:func:`~nidar_mi.nidar.training.train_irnet`), None for none.
    """

    cfg: Any
    data_dir: Path
    work_dir: Path
    stn_weights: Path | None
    progress: bool = False
    init_weights: Path | None = None
    render_frames: list[Path] | None = None
    _values: dict[str, CachedValues] = field(default_factory=dict)
    _models: dict[str, Any] = field(default_factory=dict)
    train_seconds: dict[str, float] = field(default_factory=dict)

    def fold_dir(self, train: Sequence[Any]) -> Path:
        """``WORK/fold-<held-out frames>`` of the fold that trains on ``train``."""
        from ..training_frames import SPLITS, list_frames

        names = {s.name for s in train}
        every = sorted(f.stem for split in SPLITS for f in list_frames(self.data_dir, split))
        held = [n for n in every if n not in names]
        if 1 <= len(held) <= 3:
            return self.work_dir / ("fold-" + "+".join(held))
        digest = hashlib.sha256("\n".join(sorted(names)).encode()).hexdigest()[:12]
        return self.work_dir / f"fold-{digest}"

    def values(self, train: Sequence[Any]) -> CachedValues:
        """``scan -> {"R": (N,), "I_hat": (N,)}`` of the network trained on ``train`` (trained
        at the first call of a fold)."""
        key = str(self.fold_dir(train))
        if key not in self._values:
            model = self.model(train)

            def branches(scan, model=model):
                from ..datasets.profile_fitting import scan_branches

                return scan_branches(model, scan, ("R", "I_hat"))

            self._values[key] = CachedValues(branches)
        return self._values[key]

    def model(self, train: Sequence[Any]):
        """The :class:`~nidar_mi.nidar.pipeline.NidarModel` trained on ``train`` (trained at the
        first call of a fold, reused after)."""
        fold = self.fold_dir(train)
        if str(fold) not in self._models:
            self._models[str(fold)] = self._train(fold, train)
        return self._models[str(fold)]

    def _check_finished(self, fold: Path) -> None:
        """A finished fold is reused only if it was trained as this evaluation would train it
        (configuration, initial weights, rendered frames)."""

        try:
            record = json.loads((fold / "config.json").read_text())
            # settings added since the fold was trained take their defaults
            recorded = type(self.cfg).from_dict(record["train"]).to_dict()
            have = _fold_identity(recorded, record.get("data", {}))
        except (OSError, json.JSONDecodeError, KeyError, TypeError, NidarError) as exc:
            raise NidarError(f"cannot read {fold / 'config.json'}: {exc}") from None
        init = None
        if self.init_weights is not None:
            init = {"sha256": file_sha256(self.init_weights)}
        renders = sorted(str(f) for f in self.render_frames) if self.render_frames else None
        want = _fold_identity(self.cfg.to_dict(), {"init": init, "renders": renders})
        if have != want:
            raise NidarError(
                f"{fold} holds a finished run of another configuration, initial weights or "
                "renders: use a new WORK folder"
            )

    def _train(self, fold: Path, train: Sequence[Any]):
        import time

        from ..nidar.loop import read_train_log
        from ..nidar.pipeline import NidarModel
        from ..nidar.training import train_irnet

        done = (fold / "irnet.safetensors").is_file() and read_train_log(fold).get("irnet", {}).get(
            "done"
        )
        if done:
            self._check_finished(fold)
        else:
            frames = [Path(s.source) for s in train]
            missing = [f for f in frames if not f.is_file()]
            if missing:
                raise NidarError(f"{missing[0]}: frame file not found (scans of another folder?)")
            log.info("training IRNet for %s on %d frames", fold.name, len(frames))
            t0 = time.perf_counter()
            train_irnet(
                self.cfg,
                self.data_dir,
                fold,
                self.stn_weights,
                resume=True,
                progress=self.progress,
                frames={"train": frames, "val": []},
                cache_dir=self.work_dir / "cache",
                init_weights=self.init_weights,
                render_frames=self.render_frames,
            )
            self.train_seconds[fold.name] = time.perf_counter() - t0
            _write_timing(fold, self.train_seconds[fold.name])
        return NidarModel.load(fold, device="cpu")


def _fold_identity(train_record: dict, data: dict) -> tuple:
    from ..nidar.training import input_identity, resume_identity

    return (
        resume_identity({k: v for k, v in train_record.items() if k != "stn"}),
        input_identity(data.get("init")),
        data.get("renders"),
    )


def _write_timing(fold: Path, seconds: float) -> None:
    from ..nidar.checkpoint import atomic_write

    atomic_write(fold / "timing.json", json.dumps({"train_seconds": round(seconds, 1)}))


def _branch(models: FoldModels, train, branch: str):
    vals = models.values(train)
    return lambda scan: vals(scan)[branch]


def irnet_methods(
    models: FoldModels, forms: Sequence[str] = ("range_ring",)
) -> dict[str, LooMethod]:
    """The per-fold IRNet rows of the module docstring, in table order.

    Args:
        models: the per-fold networks.
        forms: profile forms (:data:`nidar_mi.profiles.FORMS`).
    """
    from ..profiles import FORMS

    unknown = [f for f in forms if f not in FORMS]
    if unknown:
        raise NidarError(f"unknown profile form(s) {', '.join(unknown)}; known: {', '.join(FORMS)}")
    net = f"IRNet {models.cfg.irnet.variant} w{models.cfg.irnet.width} x{models.cfg.scale:g}"

    def profiled(branch: str, form: str, label: str, **options) -> LooMethod:
        def fit(train):
            values = _branch(models, train, branch)
            return profile_method(label, values, form=form, input=f"nidar:{branch}", **options).fit(
                train
            )

        return LooMethod(label, fit, "network and profile fitted on the fold's training frames")

    def raw(label: str) -> LooMethod:
        def fit(train):
            return raw_method(label, _branch(models, train, "I_hat")).fit(train)

        return LooMethod(label, fit, "network fitted on the fold's training frames")

    methods = {f"irnet_R_{f}": profiled("R", f, f"{net}: R + {f} profile") for f in forms}
    if "gbm" in forms:
        methods["irnet_R_gbm_inc"] = profiled(
            "R", "gbm", f"{net}: R + gbm profile with incidence", incidence=True
        )
    methods["irnet_I_hat_raw"] = raw(f"{net}: Î raw")
    methods |= {f"irnet_I_hat_{f}": profiled("I_hat", f, f"{net}: Î + {f} profile") for f in forms}
    return methods
