"""What a render asks for, and the set-up every render shares: checks, scene, memory, provenance.

:class:`RenderOptions` is the request of :func:`nidar_mi.simulate.render_scene` (and of each
frame of :func:`nidar_mi.sequence.render_sequence`): which scene, which outputs, which seeds.
:meth:`RenderOptions.key` is its cache key (:class:`nidar_mi.render_folder.RenderRequest`).
:class:`RenderSession` is one render's set-up, in order: check the options
(:func:`check_options`) -> load the scene and check its sensors -> refuse a render estimated to
need more memory than allowed (:meth:`RenderSession.check_memory`); it also gives what a
manifest records of the run (the variant, :func:`versions`, the NIR bands).

The Mitsuba variant is not chosen here: the entry point sets it
(:func:`nidar_mi.backend.set_variant`) and the scene is loaded in the active one.
"""

from __future__ import annotations

import platform
import time
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from . import render_folder as rf
from .errors import NidarError, check_seed

__all__ = [
    "INTENSITY_SOURCES",
    "NIDAR_BRANCHES",
    "RenderOptions",
    "RenderSession",
    "check_options",
    "nir_wavelengths",
    "profile_key",
    "versions",
]

#: ``physics``: only the simulated intensity; ``nidar``: also NIDAR's prediction from the cameras.
INTENSITY_SOURCES = ("physics", "nidar")
#: NIDAR branches a render can assign.
NIDAR_BRANCHES = ("R", "I_hat")


@dataclass(frozen=True)
class RenderOptions:
    """What to render of a scene, and how (the request of a render folder).

    Attributes:
        scene: scene XML path.
        formats: point-cloud formats (:data:`nidar_mi.render_folder.FORMATS`).
        seed: overrides every LiDAR's seed; the camera sampler seed (None: each LiDAR's own
            seed and sampler seed 0; the manifest records the seeds used), in [0, 2**32).
        spp: camera samples per pixel.
        rgb_twin: load the RGB-only twin of the scene.
        params: values for the scene's ``<default>`` parameters (None: none).
        cameras: render the cameras.
        intensity: ``physics``, or ``nidar`` to add NIDAR's intensity from the cameras
            (:data:`INTENSITY_SOURCES`).
        weights: NIDAR weights folder (None: the shipped model); ``nidar`` only.
        nidar_branch: ``R`` or ``I_hat`` (None: the profile's branch, ``R`` without one);
            ``nidar`` only; another branch than the profile's is refused.
        profile: a :class:`~nidar_mi.profiles.SensorProfile` for NIDAR's intensity
            (:func:`nidar_mi.datasets.sensor_profiles.resolve_profile` turns a name or file into one);
            None: the weights' own ``sim-905`` (``profiles/sim-905.json``, else
            ``calibration.json``); ``nidar`` only.
        bin_intensity: ``unit`` (KITTI's [0, 1]) or ``raw``: see
            :func:`nidar_mi.render_folder.write_lidar`.
        max_memory: bytes a scan or camera render may use (None:
            :func:`nidar_mi.lidar.memory.default_limit`); larger requests are refused before
            anything runs. Not part of the cache key.
        deskew: add ``xyz_deskewed`` to the points (equal to ``xyz`` for a scan from one pose).
            Not part of the cache key.
        progress: show a progress bar on stderr. Not part of the cache key.
        weather: a :class:`nidar_mi.weather.Weather` for every LiDAR (their ``fog``, ``rain``,
            ``snow`` replaced) and the cameras; None: the scene's own. Not with ``intensity``
            nidar.
        labels: read the shapes' semantic labels (:func:`nidar_mi.scene.load_scene`). False:
            every point ``unlabeled``, and Mitsuba merges the meshes that share a BSDF (a
            generated city scans ~7x faster, the same returns).
    """

    scene: str
    formats: tuple[str, ...] = rf.DEFAULT_FORMATS
    seed: int | None = None
    spp: int = 16
    rgb_twin: bool = False
    params: dict[str, str] | None = None
    cameras: bool = True
    intensity: str = "physics"
    weights: str | None = None
    nidar_branch: str | None = None
    profile: Any = None
    bin_intensity: str = "unit"
    max_memory: int | None = None
    deskew: bool = False
    progress: bool = True
    weather: Any = None
    labels: bool = True

    def branch(self) -> str:
        """The NIDAR branch read: ``nidar_branch``, else the profile's, else ``R``."""
        if self.nidar_branch is not None:
            return self.nidar_branch
        return getattr(self.profile, "branch", None) or "R"

    def key(self) -> rf.RenderRequest:
        """The cache key of this render (hashes the scene file; NidarError when it is missing)."""
        return rf.RenderRequest.of(
            self.scene,
            params=self.params,
            seed=self.seed,
            spp=self.spp,
            formats=tuple(self.formats),
            cameras=self.cameras,
            rgb_twin=self.rgb_twin,
            intensity=self.intensity,
            weights=self.weights,
            nidar_branch=self.branch(),
            profile=profile_key(self.profile),
            bin_intensity=self.bin_intensity,
            weather=None if self.weather is None else self.weather.to_dict(),
            labels=self.labels,
        )


def profile_key(profile) -> str | None:
    """``<name>@<sha256 of its JSON, 16 digits>``: what a render's request and manifest record of
    a profile (None: None)."""
    if profile is None:
        return None
    from .io.cache_key import cache_key

    return f"{profile.name}@{cache_key(profile.to_dict())}"


def check_options(options: RenderOptions) -> rf.RenderRequest:
    """Refuse options that cannot be rendered, before anything is loaded; the cache key.

    Raises:
        NidarError: one line naming the offending option.
    """
    if options.intensity != "nidar" and options.weights is not None:
        raise NidarError("`weights` is used only with `intensity` nidar")
    if options.intensity != "nidar" and options.nidar_branch is not None:
        raise NidarError("`nidar_branch` is used only with `intensity` nidar")
    fitted = getattr(options.profile, "branch", None)
    if options.nidar_branch is not None and fitted is not None and options.nidar_branch != fitted:
        b = options.nidar_branch
        raise NidarError(
            f"`nidar_branch` {b}: profile {options.profile.name} maps the {fitted} branch; leave "
            f"out `nidar_branch` or fit a profile on {b} (calibrate --branch {b})"
        )
    if options.max_memory is None:
        from .lidar.memory import default_limit

        default_limit()  # a bad NIDAR_MAX_MEMORY is named before anything loads
    _check_weather(options.intensity, options.weather)
    req = options.key()
    _check_request(req)
    return req


def _check_weather(intensity: str, weather) -> None:
    """Weather must be possible, and cannot go with NIDAR's intensity."""
    if weather is None:
        return
    from .weather import check_weather

    check_weather(weather)
    if intensity == "nidar" and not weather.clear:
        raise NidarError(
            "`intensity` nidar reads the surfaces from the camera images, which the weather "
            "veils (NIDAR learned clear days): render weather with `intensity` physics"
        )


def _check_request(req: rf.RenderRequest) -> None:
    if req.spp < 1:
        raise NidarError(f"`spp` must be >= 1 (got {req.spp})")
    if req.intensity not in INTENSITY_SOURCES:
        raise NidarError(
            f"`intensity` must be one of {', '.join(INTENSITY_SOURCES)} (got '{req.intensity}')"
        )
    if req.intensity == "nidar" and not req.cameras:
        raise NidarError("`intensity` nidar needs the camera renders (`cameras` is off)")
    if req.intensity == "nidar" and req.nidar_branch not in NIDAR_BRANCHES:
        raise NidarError(f"`nidar_branch` must be one of {', '.join(NIDAR_BRANCHES)}")
    if req.seed is not None:
        check_seed(req.seed)
    if req.bin_intensity not in rf.BIN_INTENSITY:
        raise NidarError(
            f"`bin_intensity` must be one of {', '.join(rf.BIN_INTENSITY)} "
            f"(got '{req.bin_intensity}')"
        )
    bad = [f for f in req.formats if f not in rf.FORMATS]
    if bad or not req.formats:
        raise NidarError(
            f"`formats`: unknown '{','.join(bad)}' (choose from {', '.join(rf.FORMATS)})"
        )


def _load_checked(req: rf.RenderRequest):
    """The scene of a request, in the active variant; it must have a LiDAR and unique ids."""
    from .scene import load_scene

    loaded = load_scene(req.scene, rgb_twin=req.rgb_twin, params=req.params, labels=req.labels)
    if not loaded.lidars:
        raise NidarError(f'{req.scene}: no lidar sensor (add <sensor type="lidar">)')
    names = [s.id() for s in loaded.lidars + loaded.cameras]
    dup = {n for n in names if names.count(n) > 1 or not n}
    if dup:
        raise NidarError(f"{req.scene}: every sensor needs a unique id (offending: {sorted(dup)})")
    return loaded


def versions() -> dict[str, str]:
    """The versions a manifest records: nidar_mi, Mitsuba, Dr.Jit, NumPy, Python."""
    import drjit
    import mitsuba

    from . import __version__

    return {
        "nidar_mi": __version__,
        "mitsuba": mitsuba.__version__,
        "drjit": drjit.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
    }


def nir_wavelengths(loaded) -> list[float]:
    """The NIR bands a render gives each camera, nm: every distinct LiDAR wavelength, that of
    the first LiDAR by id first (``nir.exr``; the others are ``nir_<λ>nm.exr``)."""
    return list(dict.fromkeys(float(s.config.wavelength) for s in loaded.lidars))


@dataclass
class RenderSession:
    """One render's set-up: the checked options, their cache key and the loaded scene.

    Attributes:
        options: the render's options.
        request: their cache key (:meth:`RenderOptions.key`).
        loaded: the scene (:class:`~nidar_mi.scene.LoadedScene`), its sensors sorted by id.
        load_s: time the scene took to load, s.
    """

    options: RenderOptions
    request: rf.RenderRequest
    loaded: Any
    load_s: float = 0.0

    @classmethod
    def open(cls, options: RenderOptions, request: rf.RenderRequest | None = None):
        """Check ``options`` (unless ``request``, their checked key, is given) and load the
        scene in the active Mitsuba variant.

        Raises:
            NidarError: a bad option, scene, or sensor set (no LiDAR, ids not unique).
        """
        request = check_options(options) if request is None else request
        t0 = time.perf_counter()
        loaded = _load_checked(request)
        if options.weather is not None:  # the render's weather replaces the LiDARs' own
            for sensor in loaded.lidars:
                sensor.weather = None if options.weather.clear else options.weather
        _check_weather(options.intensity, loaded.weather)  # one weather, which NIDAR cannot see
        return cls(options=options, request=request, loaded=loaded, load_s=time.perf_counter() - t0)

    @property
    def variant(self) -> str:
        """The Mitsuba variant the scene was loaded in."""
        return self.loaded.variant

    @property
    def lidars(self) -> list:
        """The LiDAR sensors, sorted by id."""
        return self.loaded.lidars

    @property
    def cameras(self) -> list:
        """The cameras rendered: every camera of the scene, none without ``options.cameras``."""
        return list(self.loaded.cameras) if self.options.cameras else []

    @cached_property
    def versions(self) -> dict[str, str]:
        """:func:`versions` (read once per session)."""
        return versions()

    @property
    def nir_wavelengths(self) -> list[float]:
        """:func:`nir_wavelengths` of the scene, nm."""
        return nir_wavelengths(self.loaded)

    def check_memory(self) -> None:
        """Refuse, before any work, a scan or camera render estimated to need more than
        ``options.max_memory`` bytes.

        Raises:
            NidarError: names the sensor and the estimate.
        """
        from .camera import check_render_memory
        from .lidar.memory import check_scan_memory

        for sensor in self.lidars:
            check_scan_memory(sensor.config, self.options.max_memory)
        for cam in self.cameras:
            check_render_memory(cam, self.options.spp, self.options.max_memory)
