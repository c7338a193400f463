"""The real-data groups of ``python -m nidar_mi.evaluate``: KITTI leave-one-frame-out and the
held-out RGB/NIR photos.

* :func:`evaluate_kitti_loo`: the KITTI folders become cached training frames
  (:func:`nidar_mi.datasets.kitti_frames.kitti_training_data`); the frames of the held-out
  ``test`` list (the six scattered frames of ``kitti/``) are the folds of
  :func:`nidar_mi.eval.loo.leave_one_out`, every other frame trains; the methods are
  :func:`nidar_mi.eval.loo.standard_methods`.
* :func:`evaluate_photos`: the seeded split by image of :mod:`nidar_mi.datasets.rgbnir`; the
  linear RGB -> NIR map is fitted on the training and validation photos (every photo that is
  not held out) and, with luminance and the model's pseudo-NIR, scored on the held-out ones
  (:mod:`nidar_mi.eval.photos`).
"""

from __future__ import annotations

import logging
from typing import Any

log = logging.getLogger("nidar_mi.evaluate")

__all__ = ["evaluate_kitti_loo", "evaluate_photos", "fit_linear_nir"]


def fit_linear_nir(root=None, *, seed: int = 0):
    """``(LinearNIR, split)``: the map fitted on the non-test photos of ``root``, and the split."""
    from ..datasets.rgbnir import list_pairs, load_pair, split_pairs
    from .baselines import LinearNIR

    pairs = list_pairs(root)
    split = split_pairs(pairs, seed=seed)
    by = {p.name: p for p in pairs}
    fit_on = split["train"] + split["val"]
    return LinearNIR.fit((load_pair(by[n]) for n in fit_on), seed=seed), split


def evaluate_photos(root, model, *, progress: bool = True) -> dict[str, Any]:
    """The held-out photo table (module docstring)."""
    from ..datasets.rgbnir import list_pairs
    from .photos import photo_table, standard_photo_methods

    linear, split = fit_linear_nir(root)
    methods = standard_photo_methods(linear, model)
    res = photo_table(list_pairs(root), split["test"], methods, progress=progress)
    return res | {
        "split": split,
        "linear_weights": [float(w) for w in linear.weights],
        "linear_fitted_on": "train + val",
    }


def evaluate_kitti_loo(
    kitti_dirs, model, *, linear_nir=None, progress: bool = True
) -> dict[str, Any]:
    """The leave-one-frame-out table on KITTI folders (module docstring).

    Returns:
        :func:`~nidar_mi.eval.loo.leave_one_out`'s result plus ``data`` (the cached frames),
        ``frames`` (how many) and ``skipped`` when no held-out test frame is among them.
    """
    import json

    from ..datasets.kitti_frames import kitti_training_data
    from ..datasets.scans import frames_from_data
    from ..datasets.sensor_profiles import resolve_profile
    from .loo import leave_one_out, standard_methods

    data = kitti_training_data(kitti_dirs, progress=progress)
    meta = json.loads((data / "meta.json").read_text())
    scans = frames_from_data(data)
    tests = [n for n in meta["frames"]["test"]]
    if not tests:
        return {"skipped": f"no held-out test frame among the KITTI frames of {kitti_dirs}"}
    methods = standard_methods(
        model=model,
        linear_nir=linear_nir,
        zero_shot_profile=resolve_profile(None, model) if model is not None else None,
    )
    log.info(
        "KITTI leave-one-out: %d frames, %d folds, %d methods", len(scans), len(tests), len(methods)
    )
    res = leave_one_out(scans, tests, methods, progress=progress)
    return res | {
        "data": str(data),
        "frames": len(scans),
        "kitti_dirs": [str(d) for d in kitti_dirs],
    }
