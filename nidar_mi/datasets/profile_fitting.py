"""The data a sensor profile is fitted on: a sensor's scans, or a training split's frames.

Both gather the returns (the model value, range, ring, elevation, incidence and the sensor's
intensity) and hand them to :func:`nidar_mi.profiles.fit`, the one fitting entry point:

* :func:`fit_values_profile` / :func:`fit_scan_profile`: per-return values (a NIDAR map, or any
  method's) against the intensities of a sensor's scans
  (:class:`~nidar_mi.datasets.scans.ScanFrame`); ``python -m nidar_mi.calibrate``, the ``kitti-hdl64e`` profile and the leave-one-frame-out
  evaluation use it.
* a ``context`` profile (:mod:`nidar_mi.profiles.context`) reads named inputs besides: the
  scan's local geometry and, when it reads the image, the image around each return and all of
  NIDAR's maps there (:func:`scan_inputs`); at most its ``points_per_frame`` returns of each
  frame are kept (seeded), so memory grows with the frames, not their returns.
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
    "scan_inputs",
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


def scan_inputs(
    model: NidarModel | None, scan: ScanFrame, *, image: bool = True
) -> dict[str, np.ndarray]:
    """The named inputs of a scan's returns (:mod:`nidar_mi.profiles.inputs`): name -> (N,)
    float64, NaN where missing.

    The image-free groups come from the points (:attr:`ScanFrame.local_geometry`, computed once
    per scan); with ``image``, the image inputs at each return's pixel and NIDAR's four maps
    there (the networks run once per image; the returns of a scan are the visible ones, so no
    second occlusion test).
    """
    from ..geometry import locate_in_cameras, sample_cameras
    from ..profiles.inputs import NIDAR_MAPS, camera_inputs, return_inputs

    out = return_inputs(scan.xyz, scan.ring, scan.local_geometry)
    if not image:
        return out
    if model is None:
        raise NidarError("the image inputs need the NIDAR model")
    images = scan.images
    sightings = locate_in_cameras(scan.xyz, scan.cameras, occlusion=False)
    maps = [model.predict_image(im, outputs=NIDAR_MAPS) for im in images]
    _, _, cam = sample_cameras(scan.xyz, scan.cameras, [m["R"] for m in maps], sightings=sightings)
    return out | camera_inputs(sightings, images, cam, maps)


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


def _scan_returns(scans, values, incidence: bool, progress: bool, name: str, inputs=None) -> dict:
    """The returns of ``scans`` with a finite value, concatenated: ``values``, ``range_m``,
    ``ring``, ``elevation_deg``, ``intensity`` and ``cos_incidence`` (None without
    ``incidence``) as (N,) arrays. With ``inputs`` (``(inputs(scan), rows(n))``: a scan's
    named inputs and the rows of its ``n`` returns to keep) also ``context``, name -> (N,), with
    ``"frame"`` and ``"group"``, (N,) the index of each return's scan and of its recording
    (``ScanFrame.group``); only the kept returns."""
    from ..progress import progress_bar

    cols: dict[str, list] = {k: [] for k in ("v", "d", "ring", "el", "y", "cos", "frame", "group")}
    groups: dict[str, int] = {}
    ctx: dict[str, list] = {}
    for i, scan in enumerate(
        progress_bar(scans, show=progress, desc=f"profile {name}", unit="frame")
    ):
        v = np.asarray(values(scan), dtype=np.float64).reshape(-1)
        log.debug("%s: %d returns", scan.name, v.size)
        if v.shape != scan.intensity.shape:
            raise NidarError(f"{scan.name}: {v.size} values for {scan.intensity.size} returns")
        ok = np.flatnonzero(np.isfinite(v))
        named = None
        if inputs is not None:
            named = inputs[0](scan)
            ok = ok[inputs[1](len(ok))]
            for k, col in named.items():
                ctx.setdefault(k, []).append(np.asarray(col, dtype=np.float64)[ok])
        cols["v"].append(v[ok])
        cols["d"].append(scan.range_m[ok])
        cols["ring"].append(scan.ring[ok].astype(np.int64))
        cols["el"].append(scan.elevation_deg[ok])
        cols["y"].append(scan.intensity[ok])
        cols["frame"].append(np.full(len(ok), i))
        cols["group"].append(np.full(len(ok), groups.setdefault(scan.group, len(groups))))
        if incidence:
            cos = named["cos_incidence"] if named is not None else scan.cos_incidence
            cols["cos"].append(cos[ok])
    out = {
        "values": np.concatenate(cols["v"]),
        "range_m": np.concatenate(cols["d"]),
        "ring": np.concatenate(cols["ring"]),
        "elevation_deg": np.concatenate(cols["el"]),
        "intensity": np.concatenate(cols["y"]),
        "cos_incidence": np.concatenate(cols["cos"]) if incidence else None,
    }
    if inputs is not None:
        out["context"] = {k: np.concatenate(v) for k, v in ctx.items()}
        out["context"]["frame"] = np.concatenate(cols["frame"])
        out["context"]["group"] = np.concatenate(cols["group"])
    return out


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
        **options: the form's fitting options (:func:`nidar_mi.profiles.fit`), and for the
            ``context`` form ``inputs``: a scan's named inputs, name -> (N,)
            (:func:`scan_inputs`; required), of which the form's ``points_per_frame`` returns
            of each scan are kept (drawn with its ``seed``).

    Raises:
        NidarError: no scans, or no return with a finite value.
    """
    if not scans:
        raise NidarError("no scans to fit a profile on")
    draw, inputs = None, options.pop("inputs", None)
    if form == "context":
        from ..profiles.context import ContextFitOptions, frame_rows

        if inputs is None:
            raise NidarError("a context profile is fitted on the returns' named inputs")
        o = ContextFitOptions(**options)
        rng = np.random.default_rng(o.seed)
        draw = (inputs, lambda n: frame_rows(n, o.points_per_frame, rng))
        incidence = False  # the incidence is one of the inputs
    data = _scan_returns(scans, values, incidence, progress, name, draw)
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
    if form == "context":
        info["inputs"] = list(mapping.groups)
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
        **options: passed to :func:`fit_values_profile` (``incidence``) and the form's fit
            (a ``context`` profile's ``features``: default its default inputs, the image's among them).
    """
    values = lambda s: scan_values(model, s, branch)  # noqa: E731
    if form == "context":
        values, options["inputs"] = _context_values(model, branch, options.get("features"))
    profile = fit_values_profile(
        scans,
        values,
        name=name,
        sensor=sensor,
        input=f"nidar:{branch}",
        form=form,
        progress=progress,
        **options,
    )
    record = {"branch": branch, "weights": str(model.weights_dir)} | dict(provenance or {})
    return replace(profile, model=model.identity(), provenance=profile.provenance | record)


def _context_values(model: NidarModel, branch: str, features) -> tuple[Callable, Callable]:
    """``(values, inputs)`` of a scan for a ``context`` profile reading ``features`` (None:
    all): one run of the networks per scan gives both when the profile reads the image."""
    from ..profiles.inputs import IMAGE_GROUPS, feature_group

    image = features is None or any(feature_group(f) in IMAGE_GROUPS for f in features)
    memo: dict[str, Any] = {}

    def inputs(scan: ScanFrame) -> dict:
        if memo.get("scan") is not scan:
            memo.update(scan=scan, inputs=scan_inputs(model, scan, image=image))
        return memo["inputs"]

    if image:
        return (lambda s: inputs(s)[branch]), inputs
    return (lambda s: scan_values(model, s, branch)), inputs


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
