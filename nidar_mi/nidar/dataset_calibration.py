"""Fitting NIDAR's source-domain calibration on a dataset split.

The distance encoding and quantile map (:mod:`nidar_mi.nidar.calibration`) are fitted on the
pixels of the training frames that carry a LiDAR return: the network's map there against the
LiDAR range and intensity (``python -m nidar_mi.train`` writes the result as
``calibration.json`` beside the weights).
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np

from ..errors import NidarError
from .calibration import Calibration, fit_calibration

if TYPE_CHECKING:
    from .pipeline import NidarModel

__all__ = ["CALIBRATION_BRANCHES", "fit_dataset_calibration"]

#: Maps :func:`fit_dataset_calibration` can calibrate: the reflectance branch, or the STN's
#: pseudo-NIR in place of it (a baseline).
CALIBRATION_BRANCHES = ("R", "pseudo_nir")


def fit_dataset_calibration(
    model: NidarModel,
    data_dir: str | os.PathLike,
    split: str = "train",
    *,
    branch: str = "R",
    **kw,
) -> Calibration:
    """Fit the distance encoding + quantile map on a dataset split (pixels with a LiDAR return).

    The ``branch`` map of :meth:`NidarModel.predict_image` at every masked pixel is paired with
    the LiDAR range and the scaled LiDAR intensity there (``intensity / intensity_scale``
    clipped to [0, 1], the source-domain distribution).

    Args:
        model: the networks whose maps are calibrated.
        data_dir: training-data directory (``meta.json`` and the split folders).
        split: split to fit on.
        branch: one of :data:`CALIBRATION_BRANCHES`: ``"R"`` (NIDAR-Full) or ``"pseudo_nir"``
            (the STN's pseudo-NIR in place of R, a baseline); stored with the calibration.
        **kw: passed to :func:`~nidar_mi.nidar.calibration.fit_calibration`.

    Raises:
        NidarError: unknown branch, a model without that map, or no frames in the split.
    """
    from ..frames import list_frames, load_frame, load_meta

    if branch not in CALIBRATION_BRANCHES:
        raise NidarError(
            f"calibration branch must be one of {', '.join(CALIBRATION_BRANCHES)} (got '{branch}')"
        )
    meta = load_meta(data_dir)
    scale = float(meta.get("intensity_scale", 1.0))
    preds, dists, refs = [], [], []
    for path in list_frames(data_dir, split):
        f = load_frame(path, keys=("rgb", "intensity", "mask"))
        with np.load(path, allow_pickle=False) as z:
            rng = z["range"].astype(np.float32)
        m = f["mask"]
        maps = model.predict_image(f["rgb"])
        if branch not in maps:
            raise NidarError(f"the model gives no '{branch}' map to calibrate")
        preds.append(maps[branch][m])
        dists.append(rng[m])
        refs.append(np.clip(f["intensity"][m].astype(np.float64) / scale, 0.0, 1.0))
    if not preds:
        raise NidarError(f"{data_dir}: no '{split}' frames to fit the {branch} calibration on")
    return fit_calibration(
        np.concatenate(preds), np.concatenate(dists), np.concatenate(refs), branch=branch, **kw
    )
