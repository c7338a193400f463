"""The named sensor profiles, and fitting a profile to a NIDAR model on a sensor's scans.

Names :func:`resolve_profile` knows (besides a path to a profile file):

* ``sim-905``: the simulator's 905 nm LiDAR in compensated mode, fitted on the rendered
  training scenes of the weights in use: ``<weights>/profiles/sim-905.json`` when the weights
  folder has one, else its ``calibration.json`` (the paper's distance encoding + quantile map)
  as a ``distance_quantile`` profile. The default of ``render --intensity nidar``.
* ``kitti-hdl64e``: KITTI's Velodyne HDL-64E (the stored reflectance), fitted on the real KITTI
  frames. KITTI is non-commercial data and a table fitted on it is derived from it, so it is
  **not shipped**: it is fitted at first use from the KITTI folders under the data root
  (``../shared/data/kitti`` and ``kitti_raw_0926``, or ``$NIDAR_MI_DATA``; or the folders given)
  for the weights in use, and cached in the user's cache folder
  (``<cache>/profiles/kitti-hdl64e-<key>.json``, :func:`nidar_mi.datasets.paths.cache_dir`;
  the key covers the weights, the folders and the form). Form :data:`KITTI_PROFILE_FORM` with
  the incidence (:data:`KITTI_PROFILE_INCIDENCE`), input the ``R`` branch, fitted on every frame
  of those folders. The default of ``assign --kitti``.

A profile fitted for other weights still applies, with a warning: it maps another network's
values. ``python -m nidar_mi.calibrate`` fits a profile for any sensor (:func:`fit_scan_profile`).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import NidarError
from .profile import SensorProfile, fit_profile, load_profile

if TYPE_CHECKING:
    from ..datasets.scans import ScanFrame
    from .pipeline import NidarModel

__all__ = [
    "DEFAULT_KITTI_PROFILE",
    "DEFAULT_SIM_PROFILE",
    "KITTI_PROFILE_FORM",
    "KITTI_PROFILE_INCIDENCE",
    "PROFILE_NAMES",
    "fit_scan_profile",
    "fit_values_profile",
    "model_identity",
    "resolve_profile",
    "scan_branches",
    "scan_values",
]

DEFAULT_SIM_PROFILE = "sim-905"
DEFAULT_KITTI_PROFILE = "kitti-hdl64e"
PROFILE_NAMES = (DEFAULT_SIM_PROFILE, DEFAULT_KITTI_PROFILE)
#: Form of the ``kitti-hdl64e`` profile (the one that generalised better in the
#: leave-one-frame-out evaluation, docs/RESULTS.md).
KITTI_PROFILE_FORM = "gbm"
#: Whether ``kitti-hdl64e`` reads the returns' incidence (it lifted every leave-one-frame-out
#: metric but the camera-map SSIM, docs/RESULTS.md).
KITTI_PROFILE_INCIDENCE = True
#: Version of the fitting procedure (part of the cache key).
_FIT_VERSION = 3
_SIM_SENSOR = "simulated 905 nm LiDAR, range-compensated intensity g·ρ·cosθ·exp(-2αd)"
_KITTI_SENSOR = "Velodyne HDL-64E (KITTI), stored reflectance in [0, 1]"


def model_identity(model: NidarModel) -> dict[str, str]:
    """SHA-256 of the model's weight files (:meth:`NidarModel.identity`)."""
    return model.identity()


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


def fit_values_profile(
    scans: Sequence[ScanFrame],
    values: Callable[[ScanFrame], np.ndarray],
    *,
    name: str,
    sensor: str,
    input: str,
    form: str = KITTI_PROFILE_FORM,
    model: dict[str, str] | None = None,
    provenance: dict[str, Any] | None = None,
    progress: bool = False,
    incidence: bool = False,
    **options: Any,
) -> SensorProfile:
    """Fit a profile mapping per-return values to the scans' intensities.

    Returns whose value is not finite (no camera gives one) are left out of the fit. Rings are
    used when every return has one.

    Args:
        scans: the sensor's scans (:func:`nidar_mi.datasets.scans.load_scans`).
        values: the model value at a scan's returns, ``(N,)`` per scan.
        name, sensor, input, model: the profile's fields.
        form: ``"gbm"``, ``"range_ring"`` or ``"distance_quantile"``.
        provenance: extra provenance entries (the data, the command).
        progress: show a progress bar.
        incidence: the profile also reads the returns' incidence cosines, estimated from each
            scan's points (``ScanFrame.cos_incidence``; ``gbm`` form only).
        **options: passed to :func:`~nidar_mi.nidar.profile.fit_profile`.

    Raises:
        NidarError: no scans, or no return with a finite value.
    """
    from tqdm.auto import tqdm

    if not scans:
        raise NidarError("no scans to fit a profile on")
    vals, rng, ring, elev, ref, cos = [], [], [], [], [], []
    for scan in tqdm(scans, desc=f"profile {name}", unit="frame", disable=not progress):
        v = np.asarray(values(scan), dtype=np.float64).reshape(-1)
        if v.shape != scan.intensity.shape:
            raise NidarError(f"{scan.name}: {v.size} values for {scan.intensity.size} returns")
        ok = np.isfinite(v)
        vals.append(v[ok])
        rng.append(scan.range_m[ok])
        ring.append(scan.ring[ok].astype(np.int64))
        elev.append(scan.elevation_deg[ok])
        ref.append(scan.intensity[ok])
        if incidence:
            cos.append(scan.cos_incidence[ok])
    n = int(sum(len(v) for v in vals))
    if n == 0:
        raise NidarError("no return of these scans has a value")
    ring_all = np.concatenate(ring)
    has_rings = bool(np.all(ring_all >= 0))
    info = {
        "frames": len(scans),
        "returns": n,
        "rings": "given" if has_rings else "none (elevation only)",
    } | dict(provenance or {})
    return fit_profile(
        np.concatenate(vals),
        np.concatenate(rng),
        np.concatenate(ref),
        form=form,
        name=name,
        sensor=sensor,
        input=input,
        ring=ring_all if has_rings else None,
        elevation_deg=np.concatenate(elev),
        cos_incidence=np.concatenate(cos) if incidence else None,
        model=model,
        provenance=info,
        **options,
    )


def fit_scan_profile(
    model: NidarModel,
    scans: Sequence[ScanFrame],
    *,
    name: str,
    sensor: str,
    form: str = KITTI_PROFILE_FORM,
    branch: str = "R",
    values: Callable[[ScanFrame], np.ndarray] | None = None,
    provenance: dict[str, Any] | None = None,
    progress: bool = True,
    **options: Any,
) -> SensorProfile:
    """Fit a profile mapping ``model``'s ``branch`` to the scans' intensities.

    Args:
        model: the NIDAR model whose values the profile maps.
        scans: the sensor's scans.
        name, sensor: the profile's name and sensor description.
        form: ``"gbm"``, ``"range_ring"`` or ``"distance_quantile"``.
        branch: the NIDAR map (``"R"`` or ``"I_hat"``).
        values: the branch at a scan's returns (default :func:`scan_values`; a cache of it).
        provenance: extra provenance entries (the data, the command).
        progress: show a progress bar.
        **options: passed to :func:`~nidar_mi.nidar.profile.fit_profile`.
    """
    return fit_values_profile(
        scans,
        values if values is not None else (lambda s: scan_values(model, s, branch)),
        name=name,
        sensor=sensor,
        input=f"nidar:{branch}",
        form=form,
        model=model_identity(model),
        provenance={"branch": branch, "weights": str(model.weights_dir)} | dict(provenance or {}),
        progress=progress,
        **options,
    )


def _sim_profile(model: NidarModel) -> SensorProfile:
    wdir = Path(model.weights_dir)
    own = wdir / "profiles" / f"{DEFAULT_SIM_PROFILE}.json"
    if own.is_file():
        return load_profile(own)
    if model.calibration is None:
        raise NidarError(f"{wdir}: no calibration.json or profiles/{DEFAULT_SIM_PROFILE}.json")
    return SensorProfile(
        name=DEFAULT_SIM_PROFILE,
        sensor=_SIM_SENSOR,
        form="distance_quantile",
        input=f"nidar:{model.calibration.branch}",
        mapping=model.calibration,
        model=model_identity(model),
        provenance={
            "data": "the rendered training split of these weights (see their MODEL_CARD.md)",
            "file": str(wdir / "calibration.json"),
        },
    )


def _kitti_profile(model: NidarModel, kitti_dirs, progress: bool) -> SensorProfile:
    from ..datasets.kitti_frames import default_kitti_dirs, kitti_training_data
    from ..datasets.paths import cache_dir, cache_key, data_root
    from ..datasets.scans import frames_from_data
    from ..io.atomic import atomic_write_json

    dirs = [Path(d) for d in kitti_dirs] if kitti_dirs else default_kitti_dirs()
    if not dirs:
        raise NidarError(
            f"the {DEFAULT_KITTI_PROFILE} profile is fitted on KITTI frames at first use (it is "
            f"not shipped: KITTI is non-commercial data) and none were found under {data_root()}; "
            "set NIDAR_MI_DATA, or fit one with python -m nidar_mi.calibrate and pass --profile FILE"
        )
    key = cache_key(
        {
            "model": model_identity(model),
            "dirs": [str(d.resolve()) for d in dirs],
            "form": KITTI_PROFILE_FORM,
            "incidence": KITTI_PROFILE_INCIDENCE,
            "version": _FIT_VERSION,
        }
    )
    path = cache_dir("profiles", f"{DEFAULT_KITTI_PROFILE}-{key}.json")
    if path.is_file():
        return load_profile(path)
    warnings.warn(
        f"fitting the {DEFAULT_KITTI_PROFILE} profile on the KITTI frames in "
        f"{', '.join(map(str, dirs))} (once; cached in {path})",
        stacklevel=3,
    )
    scans = frames_from_data(kitti_training_data(dirs, progress=progress))
    profile = fit_scan_profile(
        model,
        scans,
        name=DEFAULT_KITTI_PROFILE,
        sensor=_KITTI_SENSOR,
        form=KITTI_PROFILE_FORM,
        branch="R",
        provenance={"data": [str(d.resolve()) for d in dirs], "cache": str(path)},
        progress=progress,
        incidence=KITTI_PROFILE_INCIDENCE,
    )
    os.makedirs(path.parent, exist_ok=True)
    atomic_write_json(path, profile.to_dict())
    return profile


def resolve_profile(
    spec: str | os.PathLike | None,
    model: NidarModel,
    *,
    kitti_dirs: Sequence[str | os.PathLike] | None = None,
    progress: bool = True,
) -> SensorProfile:
    """The profile named by ``spec``: a file, ``sim-905``, ``kitti-hdl64e`` (module docstring).

    Args:
        spec: a profile name or a path to a profile file; None: ``sim-905``.
        model: the NIDAR model the profile is used with.
        kitti_dirs: KITTI folders for ``kitti-hdl64e`` (default: those under the data root).
        progress: show progress while fitting.

    Raises:
        NidarError: an unknown name, an invalid file, or no data to fit ``kitti-hdl64e``.
    """
    spec = DEFAULT_SIM_PROFILE if spec is None else spec
    if str(spec) == DEFAULT_SIM_PROFILE:
        profile = _sim_profile(model)
    elif str(spec) == DEFAULT_KITTI_PROFILE:
        profile = _kitti_profile(model, kitti_dirs, progress)
    elif Path(spec).is_file() or str(spec).endswith(".json"):
        profile = load_profile(spec)
    else:
        raise NidarError(
            f"unknown profile {str(spec)!r}: give a profile file or one of {', '.join(PROFILE_NAMES)}"
        )
    if profile.branch is None:
        raise NidarError(f"profile {profile.name} maps {profile.input!r}, not a NIDAR map")
    if profile.model is not None and profile.model != model_identity(model):
        warnings.warn(
            f"profile {profile.name} was fitted for other NIDAR weights; it maps their values, "
            "not these (fit one with python -m nidar_mi.calibrate)",
            stacklevel=2,
        )
    return profile
