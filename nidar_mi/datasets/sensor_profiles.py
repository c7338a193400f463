"""The named sensor profiles: the weights' own, and those fitted on real data at first use.

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
  (``<cache>/profiles/kitti-hdl64e-<key>.json``, :func:`~nidar_mi.datasets.paths.cache_dir`;
  the key covers the weights, the folders and the form). Form :data:`KITTI_PROFILE_FORM` with
  the incidence (:data:`KITTI_PROFILE_INCIDENCE`), input the ``R`` branch, fitted on every frame
  of those folders. The default of ``assign --kitti``.

A profile fitted for other weights still applies, with a warning: it maps another network's
values. ``python -m nidar_mi.calibrate`` fits a profile for any sensor
(:func:`~nidar_mi.datasets.profile_fitting.fit_scan_profile`).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import NidarError
from ..nidar.pipeline import SIM_PROFILE
from ..profiles import SensorProfile, load_profile

if TYPE_CHECKING:
    from ..nidar.pipeline import NidarModel

__all__ = [
    "DEFAULT_KITTI_PROFILE",
    "DEFAULT_SIM_PROFILE",
    "KITTI_PROFILE_FORM",
    "KITTI_PROFILE_INCIDENCE",
    "PROFILE_NAMES",
    "resolve_profile",
]

DEFAULT_SIM_PROFILE = SIM_PROFILE
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
_KITTI_SENSOR = "Velodyne HDL-64E (KITTI), stored reflectance in [0, 1]"


def _sim_profile(model: NidarModel) -> SensorProfile:
    wdir = Path(model.weights_dir)
    own = wdir / "profiles" / f"{DEFAULT_SIM_PROFILE}.json"
    if own.is_file():
        return load_profile(own)
    if model.calibration is None:
        raise NidarError(f"{wdir}: no calibration.json or profiles/{DEFAULT_SIM_PROFILE}.json")
    return model.calibration


def _kitti_profile(model: NidarModel, kitti_dirs, progress: bool) -> SensorProfile:
    from ..io.atomic import atomic_write_json
    from ..io.cache_key import cache_key
    from .kitti_frames import default_kitti_dirs, kitti_training_data
    from .paths import cache_dir, data_root
    from .profile_fitting import fit_scan_profile
    from .scans import frames_from_data

    dirs = [Path(d) for d in kitti_dirs] if kitti_dirs else default_kitti_dirs()
    if not dirs:
        raise NidarError(
            f"the {DEFAULT_KITTI_PROFILE} profile is fitted on KITTI frames at first use (it is "
            f"not shipped: KITTI is non-commercial data) and none were found under {data_root()}; "
            "set NIDAR_MI_DATA, or fit one with python -m nidar_mi.calibrate and pass --profile FILE"
        )
    key = cache_key(
        {
            "model": model.identity(),
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
    if profile.model is not None and profile.model != model.identity():
        warnings.warn(
            f"profile {profile.name} was fitted for other NIDAR weights; it maps their values, "
            "not these (fit one with python -m nidar_mi.calibrate)",
            stacklevel=2,
        )
    return profile
