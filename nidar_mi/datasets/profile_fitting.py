"""The data a sensor profile is fitted on: a sensor's scans, or a training split's frames.

Both gather the returns (the model value, range, ring, elevation, incidence and the sensor's
intensity) and hand them to :func:`nidar_mi.profiles.fit`, the one fitting entry point:

* :func:`fit_values_profile` / :func:`fit_scan_profile`: per-return values (a NIDAR map, or any
  method's) against the intensities of a sensor's scans
  (:class:`~nidar_mi.datasets.scans.ScanFrame`); ``python -m nidar_mi.calibrate``, the ``kitti-hdl64e`` profile and the leave-one-frame-out
  evaluation use it.
* :func:`fit_split_calibration`: the paper's distance encoding and quantile map of a NIDAR map
  on the pixels of a training split that carry a LiDAR return (``python -m nidar_mi.train``
  writes its mapping as ``calibration.json`` beside the weights).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import NidarError
from ..profiles import SensorProfile, fit

if TYPE_CHECKING:
    from ..nidar.pipeline import NidarModel
    from .scans import ScanFrame

__all__ = [
    "CALIBRATION_BRANCHES",
    "fit_scan_profile",
    "fit_split_calibration",
    "fit_values_profile",
    "scan_branches",
    "scan_values",
    "select_frames",
]

log = logging.getLogger("nidar_mi.calibrate")

#: Maps :func:`fit_split_calibration` can calibrate: the reflectance branch, or the STN's
#: pseudo-NIR in place of it (a baseline).
CALIBRATION_BRANCHES = ("R", "pseudo_nir")


def scan_branches(
    model: NidarModel, scan: ScanFrame, branches: Sequence[str] = ("R", "I_hat")
) -> dict[str, np.ndarray]:
    """The model's maps sampled at a scan's returns: branch -> (N,) values (NaN where no camera
    gives one).

    The returns of a :class:`~nidar_mi.datasets.scans.ScanFrame` are already the visible
    ones, so the cameras are sampled without a second occlusion test. The networks run once per
    image for all ``branches``.
    """
    from ..geometry import sample_cameras

    maps = [model.predict_image(im) for im in scan.images]
    out = {}
    for branch in branches:
        if any(branch not in m for m in maps):
            raise NidarError(f"the model gives no '{branch}' map")
        values, seen, _ = sample_cameras(
            scan.xyz, scan.cameras, [m[branch] for m in maps], occlusion=False
        )
        out[branch] = np.where(seen, values, np.nan).astype(np.float64)
    return out


def scan_values(model: NidarModel, scan: ScanFrame, branch: str) -> np.ndarray:
    """One branch of :func:`scan_branches`."""
    return scan_branches(model, scan, (branch,))[branch]


def select_frames(scans: Sequence[ScanFrame], k: int | None) -> list[ScanFrame]:
    """``k`` of ``scans`` evenly spaced over their order (the first and the last among them;
    consecutive frames of a drive are alike, spread ones are not); None or ``k >= len``: all.

    Raises:
        NidarError: ``k`` below 1.
    """
    if k is None or k >= len(scans):
        return list(scans)
    if k < 1:
        raise NidarError(f"`max_frames` must be at least 1 (got {k})")
    idx = np.unique(np.round(np.linspace(0, len(scans) - 1, k)).astype(np.int64))
    return [scans[i] for i in idx]


def _scan_returns(scans, values, incidence: bool, progress: bool, name: str) -> dict:
    """The returns of ``scans`` with a finite value, concatenated: ``values``, ``range_m``,
    ``ring``, ``elevation_deg``, ``intensity`` and ``cos_incidence`` (None without
    ``incidence``) as (N,) arrays."""
    from ..progress import progress_bar

    cols: dict[str, list] = {k: [] for k in ("v", "d", "ring", "el", "y", "cos")}
    for scan in progress_bar(scans, show=progress, desc=f"profile {name}", unit="frame"):
        v = np.asarray(values(scan), dtype=np.float64).reshape(-1)
        log.debug("%s: %d returns", scan.name, v.size)
        if v.shape != scan.intensity.shape:
            raise NidarError(f"{scan.name}: {v.size} values for {scan.intensity.size} returns")
        ok = np.isfinite(v)
        cols["v"].append(v[ok])
        cols["d"].append(scan.range_m[ok])
        cols["ring"].append(scan.ring[ok].astype(np.int64))
        cols["el"].append(scan.elevation_deg[ok])
        cols["y"].append(scan.intensity[ok])
        if incidence:
            cols["cos"].append(scan.cos_incidence[ok])
    return {
        "values": np.concatenate(cols["v"]),
        "range_m": np.concatenate(cols["d"]),
        "ring": np.concatenate(cols["ring"]),
        "elevation_deg": np.concatenate(cols["el"]),
        "intensity": np.concatenate(cols["y"]),
        "cos_incidence": np.concatenate(cols["cos"]) if incidence else None,
    }


def fit_values_profile(
    scans: Sequence[ScanFrame],
    values: Callable[[ScanFrame], np.ndarray],
    *,
    name: str,
    sensor: str,
    input: str,
    form: str = "gbm",
    progress: bool = False,
    incidence: bool = False,
    **options: Any,
) -> SensorProfile:
    """Fit a profile mapping per-return values to the scans' intensities.

    Returns whose value is not finite (no camera gives one) are left out of the fit. Rings are
    used when every return has one. The profile's ``model`` is None (any model) and its
    provenance counts the frames, returns and rings (:func:`fit_scan_profile` adds the model).

    Args:
        scans: the sensor's scans (:func:`nidar_mi.datasets.scans.load_scans`).
        values: the model value at a scan's returns, ``(N,)`` per scan.
        name, sensor, input: the profile's fields.
        form: a profile form (:data:`nidar_mi.profiles.FORMS`).
        progress: show a progress bar.
        incidence: the profile also reads the returns' incidence cosines, estimated from each
            scan's points (``ScanFrame.cos_incidence``; ``gbm`` form only).
        **options: the form's fitting options (:func:`nidar_mi.profiles.fit`).

    Raises:
        NidarError: no scans, or no return with a finite value.
    """
    if not scans:
        raise NidarError("no scans to fit a profile on")
    data = _scan_returns(scans, values, incidence, progress, name)
    n = int(data["values"].size)
    if n == 0:
        raise NidarError("no return of these scans has a value")
    has_rings = bool(np.all(data["ring"] >= 0))
    if not has_rings:
        data["ring"] = None
    info = {
        "frames": len(scans),
        "returns": n,
        "rings": "given" if has_rings else "none (elevation only)",
    }
    mapping = fit(form, **data, input=input, **options)
    return SensorProfile(
        name=name,
        sensor=sensor,
        form=form,
        input=input,
        mapping=mapping,
        provenance=info,
    )


def fit_scan_profile(
    model: NidarModel,
    scans: Sequence[ScanFrame],
    *,
    name: str,
    sensor: str,
    form: str = "gbm",
    branch: str = "R",
    provenance: dict[str, Any] | None = None,
    progress: bool = True,
    **options: Any,
) -> SensorProfile:
    """Fit a profile mapping ``model``'s ``branch`` to the scans' intensities.

    Args:
        model: the NIDAR model whose values the profile maps.
        scans: the sensor's scans.
        name, sensor: the profile's name and sensor description.
        form: a profile form (:data:`nidar_mi.profiles.FORMS`).
        branch: the NIDAR map (``"R"`` or ``"I_hat"``).
        provenance: extra provenance entries (the data, the command).
        progress: show a progress bar.
        **options: passed to :func:`fit_values_profile` (``incidence``) and the form's fit.
    """
    profile = fit_values_profile(
        scans,
        lambda s: scan_values(model, s, branch),
        name=name,
        sensor=sensor,
        input=f"nidar:{branch}",
        form=form,
        progress=progress,
        **options,
    )
    record = {"branch": branch, "weights": str(model.weights_dir)} | dict(provenance or {})
    return replace(profile, model=model.identity(), provenance=profile.provenance | record)


def fit_split_calibration(
    model: NidarModel,
    data_dir: str | os.PathLike,
    split: str = "train",
    *,
    branch: str = "R",
    **options: Any,
) -> SensorProfile:
    """Fit the distance encoding + quantile map on a dataset split (pixels with a LiDAR return).

    The ``branch`` map of :meth:`NidarModel.predict_image` at every masked pixel is paired with
    the LiDAR range and the scaled LiDAR intensity there (``intensity / intensity_scale``
    clipped to [0, 1], the source-domain distribution).

    Args:
        model: the networks whose maps are calibrated.
        data_dir: training-data directory (``meta.json`` and the split folders).
        split: split to fit on.
        branch: one of :data:`CALIBRATION_BRANCHES`: ``"R"`` (NIDAR-Full) or ``"pseudo_nir"``
            (the STN's pseudo-NIR in place of R, a baseline); the map's ``branch``.
        **options: the ``distance_quantile`` form's fitting options (``tau``, ``K``, ...).

    Returns:
        A ``distance_quantile`` profile of ``nidar:<branch>``; its ``mapping`` is what
        ``calibration.json`` holds (:meth:`~nidar_mi.profiles.DistanceQuantileMap.save_json`).

    Raises:
        NidarError: unknown branch, a model without that map, or no frames in the split.
    """
    from ..training_frames import list_frames, load_frame, load_meta

    if branch not in CALIBRATION_BRANCHES:
        raise NidarError(
            f"calibration branch must be one of {', '.join(CALIBRATION_BRANCHES)} (got '{branch}')"
        )
    scale = float(load_meta(data_dir).get("intensity_scale", 1.0))
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
    v, d = np.concatenate(preds), np.concatenate(dists)
    mapping = fit("distance_quantile", v, d, np.concatenate(refs), input=branch, **options)
    return SensorProfile(
        name=f"{split}-{branch}",
        sensor=f"the source domain: the '{split}' frames of {data_dir}",
        form="distance_quantile",
        input=f"nidar:{branch}",
        mapping=mapping,
        model=model.identity(),
        provenance={"data": str(data_dir), "split": split, "returns": int(v.size)},
    )
