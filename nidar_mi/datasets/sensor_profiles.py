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
  the key covers the weights, the folders and the recipe). Form :data:`KITTI_PROFILE_FORM`: a
  ``context`` profile (:mod:`nidar_mi.profiles.context`, :data:`KITTI_PROFILE_OPTIONS`) of the
  returns' range, elevation, incidence, laser, local geometry, image context and NIDAR's maps,
  input the ``R`` branch, fitted on every frame of those folders; it reads the camera image.
  The default of ``assign --kitti``, where it is fitted instead on up to
  :data:`KITTI_ASSIGN_FRAMES` other frames of the ``--kitti`` folder, never on the frame it
  assigns (:func:`kitti_frame_profile`; cached per set of frames).
* ``generic-compensated``: a range-compensated sensor of unknown make, from physics, not from
  data: ``I = clip(ρ·|cos θ|, 0, 1)`` with ``ρ`` the NIDAR ``R`` value (a ``physical`` profile,
  :class:`~nidar_mi.profiles.PhysicalMap`, gain 1, no range term). The default of ``assign``
  for a cloud of an unknown sensor, with a warning.
* ``generic-raw``: a raw sensor of unknown make: ``I = clip(k·ρ·|cos θ|/d², 0, 1)`` (``d`` in m,
  at least 1 m), ``k`` = :data:`GENERIC_RAW_GAIN` so that a 10 %-reflective target seen
  head-on at 10 m reads :data:`GENERIC_RAW_LEVEL`; nearer and brighter targets saturate at 1.

Which profile applies when none is named is :func:`default_profile`'s choice: ``kitti-hdl64e``
for a KITTI frame, the weights' own (``sim-905``) for the simulator's own renders, else
``generic-compensated`` with a warning naming ``python -m nidar_mi.calibrate``
(:func:`warn_unknown_sensor`).

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

import numpy as np

from ..errors import NidarError
from ..nidar.pipeline import SIM_PROFILE
from ..profiles import PhysicalMap, SensorProfile, load_profile

if TYPE_CHECKING:
    from ..nidar.pipeline import NidarModel

__all__ = [
    "DEFAULT_GENERIC_PROFILE",
    "DEFAULT_KITTI_PROFILE",
    "DEFAULT_SIM_PROFILE",
    "GENERIC_COMPENSATED_PROFILE",
    "GENERIC_RAW_GAIN",
    "GENERIC_RAW_LEVEL",
    "GENERIC_RAW_PROFILE",
    "KITTI_ASSIGN_FRAMES",
    "KITTI_PROFILE_FORM",
    "KITTI_PROFILE_INCIDENCE",
    "KITTI_PROFILE_OPTIONS",
    "PROFILE_NAMES",
    "default_profile",
    "generic_profile",
    "kitti_frame_profile",
    "profile_line",
    "resolve_profile",
    "warn_unknown_sensor",
]

DEFAULT_SIM_PROFILE = SIM_PROFILE
DEFAULT_KITTI_PROFILE = "kitti-hdl64e"
GENERIC_RAW_PROFILE = "generic-raw"
GENERIC_COMPENSATED_PROFILE = "generic-compensated"
#: The profile of a sensor nobody calibrated (:func:`default_profile`).
DEFAULT_GENERIC_PROFILE = GENERIC_COMPENSATED_PROFILE
PROFILE_NAMES = (
    DEFAULT_SIM_PROFILE,
    DEFAULT_KITTI_PROFILE,
    GENERIC_COMPENSATED_PROFILE,
    GENERIC_RAW_PROFILE,
)
#: The intensity of a 10 %-reflective target seen head-on at 10 m under ``generic-raw``.
GENERIC_RAW_LEVEL = 0.05
#: ``generic-raw``'s gain k, m²: ``k · 0.1 / 10² = GENERIC_RAW_LEVEL``.
GENERIC_RAW_GAIN = GENERIC_RAW_LEVEL * 10.0**2 / 0.1
#: Form of the ``kitti-hdl64e`` profile and of ``calibrate`` by default: the ``context`` form,
#: ahead of the ``gbm`` recipe of value, range, elevation and incidence on every group of the
#: leave-one-group-out evaluation (docs/NIDAR.md, "Local geometry and image context").
KITTI_PROFILE_FORM = "context"
#: The ``context`` form's options of ``kitti-hdl64e`` (its default ``features``, the inputs of
#: :data:`nidar_mi.profiles.inputs.DEFAULT_GROUPS`).
KITTI_PROFILE_OPTIONS: dict = {"kind": "gbm"}
#: Whether a ``gbm`` profile reads the returns' incidence by default (it lifted every
#: leave-one-frame-out metric but the camera-map SSIM, docs/RESULTS.md).
KITTI_PROFILE_INCIDENCE = True
#: Version of the fitting procedure (part of the cache key).
_FIT_VERSION = 7
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
    from .kitti_frames import default_kitti_dirs, kitti_training_data
    from .paths import data_root
    from .scans import frames_from_data

    dirs = [Path(d) for d in kitti_dirs] if kitti_dirs else default_kitti_dirs()
    if not dirs:
        raise NidarError(
            f"the {DEFAULT_KITTI_PROFILE} profile is fitted on KITTI frames at first use (it is "
            f"not shipped: KITTI is non-commercial data) and none were found under {data_root()}; "
            "set NIDAR_MI_DATA, or fit one with python -m nidar_mi.calibrate and pass --profile FILE"
        )
    data = {"dirs": [str(d.resolve()) for d in dirs]}
    where = f"the KITTI frames in {', '.join(map(str, dirs))}"
    return _cached_fit(
        model,
        data,
        where,
        lambda: frames_from_data(kitti_training_data(dirs, progress=progress)),
        progress,
    )


def _cached_fit(model: NidarModel, data: dict, where: str, scans, progress: bool) -> SensorProfile:
    """``kitti-hdl64e`` fitted on ``scans()`` (the frames ``data`` names, ``where`` in words),
    cached in the user's cache folder under a key of ``data``, the weights, the form and the
    fitting version; one warning when it is fitted."""
    from ..io.atomic import atomic_write_json, folder_lock
    from ..io.cache_key import cache_key
    from .paths import cache_dir
    from .profile_fitting import fit_scan_profile

    settings = {"form": KITTI_PROFILE_FORM, "options": KITTI_PROFILE_OPTIONS}
    key = cache_key({"model": model.identity(), **data, **settings, "version": _FIT_VERSION})
    path = cache_dir("profiles", f"{DEFAULT_KITTI_PROFILE}-{key}.json")
    if path.is_file():
        return load_profile(path)
    # a second process fitting it at the same time waits, then reads the first one's
    with folder_lock(path.parent, f"the {DEFAULT_KITTI_PROFILE} profile"):
        if path.is_file():
            return load_profile(path)
        warnings.warn(
            f"fitting the {DEFAULT_KITTI_PROFILE} profile on {where} (once; cached in {path})",
            stacklevel=4,
        )
        profile = fit_scan_profile(
            model,
            scans(),
            name=DEFAULT_KITTI_PROFILE,
            sensor=_KITTI_SENSOR,
            form=KITTI_PROFILE_FORM,
            branch="R",
            provenance={**data, "cache": str(path)},
            progress=progress,
            **KITTI_PROFILE_OPTIONS,
        )
        atomic_write_json(path, profile.to_dict())
    return profile


#: How many frames of the ``--kitti`` folder ``kitti-hdl64e`` is fitted on for ``assign --kitti``
#: (evenly spread; ten frames of a sensor calibrate it about as well as all, docs/NIDAR.md).
KITTI_ASSIGN_FRAMES = 10


def _assign_frames(ids: list[str], frame_id: str) -> list[str]:
    """:data:`KITTI_ASSIGN_FRAMES` of ``ids`` evenly spread, ``frame_id`` never among them (its
    next neighbour not chosen takes its place, so that most frames share one choice)."""
    if len(ids) <= KITTI_ASSIGN_FRAMES + 1:
        return [i for i in ids if i != frame_id]
    pick = np.unique(np.round(np.linspace(0, len(ids) - 1, KITTI_ASSIGN_FRAMES)).astype(int))
    chosen = [ids[i] for i in pick]
    if frame_id in chosen:
        free = [i for i in ids if i not in chosen and i != frame_id]
        at = ids.index(frame_id)
        chosen[chosen.index(frame_id)] = min(free, key=lambda i: (abs(ids.index(i) - at), i))
    return sorted(chosen)


def kitti_frame_profile(
    model: NidarModel, kitti_dir: str | os.PathLike, frame_id: str, *, progress: bool = True
) -> SensorProfile:
    """``kitti-hdl64e`` for assigning the KITTI frame ``frame_id`` of ``kitti_dir``: fitted on up
    to :data:`KITTI_ASSIGN_FRAMES` other frames of that folder (evenly spread), never on the
    frame itself, cached in the user's cache folder under a key of the frames used (their
    files' sizes and times), the weights, the form and the fitting version.

    Raises:
        NidarError: the folder holds no other frame.
    """
    from .kitti_frames import kitti_training_frame
    from .kitti_objects import frame_ids, load_kitti_frame
    from .scans import scan_frame

    folder = Path(kitti_dir).resolve()
    chosen = _assign_frames(frame_ids(folder), frame_id)
    if not chosen:
        raise NidarError(
            f"the {DEFAULT_KITTI_PROFILE} profile of a KITTI frame is fitted on the other frames "
            f"of its folder, and {kitti_dir} holds no other: give --profile FILE (python -m "
            "nidar_mi.calibrate fits one)"
        )
    stamps = {
        i: [(f.stat().st_size, f.stat().st_mtime_ns) for f in sorted(folder.glob(f"*/{i}.*"))]
        for i in chosen
    }

    def scans():
        out = []
        for fid in chosen:
            frame, _ = kitti_training_frame(load_kitti_frame(folder, fid))
            out.append(scan_frame(frame, fid, str(folder), 1.0, lambda f=frame: [f["rgb"]]))
        return out

    data = {"data": str(folder), "frames": chosen, "stamps": stamps}
    where = f"{len(chosen)} other frames of {kitti_dir} (not on {frame_id})"
    return _cached_fit(model, data, where, scans, progress)


def generic_profile(name: str) -> SensorProfile:
    """``generic-raw`` or ``generic-compensated`` (module docstring): closed forms, no data.

    Raises:
        NidarError: another name.
    """
    if name == GENERIC_COMPENSATED_PROFILE:
        mapping = PhysicalMap(gain=1.0, range_exponent=0.0)
        sensor, formula = "a range-compensated LiDAR (not calibrated)", "I = clip(R*|cos t|, 0, 1)"
    elif name == GENERIC_RAW_PROFILE:
        mapping = PhysicalMap(gain=GENERIC_RAW_GAIN, range_exponent=2.0)
        sensor = "a raw LiDAR with a 1/d^2 range fall-off (not calibrated)"
        formula = f"I = clip({GENERIC_RAW_GAIN:g}*R*|cos t|/max(d, 1 m)^2, 0, 1)"
    else:
        raise NidarError(
            f"no generic profile {name!r} (one of {GENERIC_COMPENSATED_PROFILE}, "
            f"{GENERIC_RAW_PROFILE})"
        )
    provenance = {"data": None, "formula": formula, "source": "closed form (physics), no data"}
    return SensorProfile(
        name=name,
        sensor=sensor,
        form=PhysicalMap.form,
        input="nidar:R",
        mapping=mapping,
        provenance=provenance,
    )


def default_profile(*, kitti: bool = False, simulator: bool = False) -> str | None:
    """The profile of a cloud given none: ``kitti-hdl64e`` for a KITTI frame, None (the
    weights' own, ``sim-905``) for a render of the simulator, else ``generic-compensated``
    (an unknown sensor: :func:`warn_unknown_sensor`)."""
    if kitti:
        return DEFAULT_KITTI_PROFILE
    return None if simulator else DEFAULT_GENERIC_PROFILE


def warn_unknown_sensor() -> None:
    """Warn that the sensor is unknown, which profile applies and how to calibrate it."""
    warnings.warn(
        f"unknown sensor: the {DEFAULT_GENERIC_PROFILE} profile applies (intensity = R x "
        f"|cos incidence|; {GENERIC_RAW_PROFILE} for a sensor without range compensation); "
        "calibrate yours with python -m nidar_mi.calibrate SCANS -o profile.json and use that "
        "profile file",
        stacklevel=2,
    )


def profile_line(spec: str | os.PathLike | None, *, branch: str | None = None) -> str:
    """One line naming the profile a command uses, ``profile: <name> (<what it is>)``, from its
    name or file alone (neither the weights nor any data are read; an unreadable file is named
    as given, :func:`resolve_profile` reports it). ``spec`` None: the weights' own on the ``R``
    branch (``branch`` None or ``"R"``), none on ``I_hat``."""
    if spec is None:
        if branch not in (None, "R"):
            return f"profile: none (the {branch} head, raw)"
        spec = DEFAULT_SIM_PROFILE
    name = str(spec)
    if name == DEFAULT_SIM_PROFILE:
        return f"profile: {name} (the simulator's 905 nm LiDAR, the weights' own)"
    if name == DEFAULT_KITTI_PROFILE:
        return f"profile: {name} ({_KITTI_SENSOR}; fitted on KITTI frames at first use)"
    if name in (GENERIC_COMPENSATED_PROFILE, GENERIC_RAW_PROFILE):
        p = generic_profile(name)
        return f"profile: {name} ({p.sensor}: {p.provenance['formula']})"
    try:
        p = load_profile(spec)
    except NidarError:
        return f"profile: {name}"
    return f"profile: {p.name} ({p.form}, {p.sensor}; file {name})"


def resolve_profile(
    spec: str | os.PathLike | None,
    model: NidarModel,
    *,
    kitti_dirs: Sequence[str | os.PathLike] | None = None,
    progress: bool = True,
    kitti_frame: tuple[str | os.PathLike, str] | None = None,
) -> SensorProfile:
    """The profile named by ``spec``: a file, or one of :data:`PROFILE_NAMES` (module docstring).

    Args:
        spec: a profile name or a path to a profile file; None: ``sim-905``.
        model: the NIDAR model the profile is used with.
        kitti_dirs: KITTI folders for ``kitti-hdl64e`` (default: those under the data root).
        progress: show progress while fitting.
        kitti_frame: ``(folder, frame id)`` of the KITTI frame the profile is for:
            ``kitti-hdl64e`` is then fitted on that folder's other frames
            (:func:`kitti_frame_profile`), never on the frame.

    Raises:
        NidarError: an unknown name, an invalid file, or no data to fit ``kitti-hdl64e``.
    """
    spec = DEFAULT_SIM_PROFILE if spec is None else spec
    if str(spec) == DEFAULT_SIM_PROFILE:
        profile = _sim_profile(model)
    elif str(spec) == DEFAULT_KITTI_PROFILE and kitti_frame is not None:
        profile = kitti_frame_profile(model, *kitti_frame, progress=progress)
    elif str(spec) == DEFAULT_KITTI_PROFILE:
        profile = _kitti_profile(model, kitti_dirs, progress)
    elif str(spec) in (GENERIC_COMPENSATED_PROFILE, GENERIC_RAW_PROFILE):
        profile = generic_profile(str(spec))
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
