"""NIDAR end to end: camera images -> per-point LiDAR intensity.

RGB -> STN pseudo-NIR -> IRNet (R, S, Î) -> the R branch sampled at each point by calibrated
projection (:func:`nidar_mi.geometry.fusion.sample_cameras`, occlusion test on; on the host
whatever the networks' device, the geometry beside the networks) -> the sensor's
response, a sensor profile (:mod:`nidar_mi.profiles`): by default the weights' own
(:meth:`NidarModel.default_profile`). Points no camera sees get 0 and ``observed = False``.

A weights folder holds ``stn.safetensors``, ``irnet.safetensors``, ``config.json`` (written by
``python -m nidar_mi.train``) and ``calibration.json`` (the paper's distance encoding and
quantile map fitted on the training split,
:func:`nidar_mi.datasets.profile_fitting.fit_split_calibration`; read as a ``distance_quantile``
profile named :data:`SIM_PROFILE`), and optionally ``profiles/sim-905.json``: the simulator's
sensor profile, which then replaces ``calibration.json`` as the default mapping of the R branch.
The package ships one in ``nidar_mi/nidar/weights``.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import NidarError
from ..geometry import CameraModel, incidence_cosine, locate_in_cameras, sample_cameras
from ..geometry.local_features import local_geometry
from ..profiles import DistanceQuantileMap, SensorProfile, load_profile

__all__ = [
    "NidarModel",
    "shipped_weights_dir",
    "PointIntensity",
    "BRANCHES",
    "SIM_PROFILE",
    "SIM_SENSOR",
]

#: Branches :meth:`NidarModel.point_intensity` can assign: the paper's calibrated reflectance, or
#: the dense intensity head.
BRANCHES = ("R", "I_hat")
#: Name of the weights' own profile: the simulator's 905 nm LiDAR in compensated mode, fitted on
#: the rendered training scenes of the weights (``profiles/sim-905.json``, else
#: ``calibration.json``).
SIM_PROFILE = "sim-905"
#: The sensor that profile describes.
SIM_SENSOR = "simulated 905 nm LiDAR, range-compensated intensity g·ρ·cosθ·exp(-2αd)"


def shipped_weights_dir() -> Path:
    """The weights folder shipped inside the package."""
    return Path(__file__).resolve().parent / "weights"


def _optimized(stn, irnet):
    """The networks with BatchNorm folded and channels-last memory (checked on a small input)."""
    import torch

    from .fold import prepare_for_inference

    side = 2 * max(irnet.stride, stn.stride if stn is not None else 1)
    device = next(irnet.parameters()).device
    irnet = prepare_for_inference(
        irnet,
        torch.rand(1, irnet.in_channels, side, side, generator=torch.Generator().manual_seed(0)).to(
            device
        ),
    )
    if stn is not None:
        stn = prepare_for_inference(
            stn, torch.rand(1, 3, side, side, generator=torch.Generator().manual_seed(0)).to(device)
        )
    return stn, irnet


@dataclass
class PointIntensity:
    """NIDAR intensity of a point cloud.

    Attributes:
        intensity: (N,) float32 calibrated intensity in [0, 1], 0 where unobserved.
        observed: (N,) bool, a camera saw the point.
        raw_R: (N,) float32 branch value sampled at the points (before calibration), 0 where
            unobserved.
        camera_index: (N,) int64 camera that gave the value, -1 where unobserved.
        reflectance: (N,) float32 IRNet's reflectance R at the points (the per-surface cue,
            about [0, 1]), from the same camera as the value, 0 where unobserved; equal to
            ``raw_R`` when the branch is R.
    """

    intensity: np.ndarray
    observed: np.ndarray
    raw_R: np.ndarray
    camera_index: np.ndarray
    reflectance: np.ndarray | None = None


class NidarModel:
    """Trained NIDAR networks plus their source-domain calibration (``calibration.json``)."""

    def __init__(
        self, stn, irnet, config, calibration: DistanceQuantileMap | None, weights_dir: Path
    ):
        self.stn, self.irnet, self.config = stn, irnet, config
        self._calibration_map = calibration
        self._calibration: SensorProfile | None = None
        self.weights_dir = weights_dir
        self.scale = 1.0
        self._default_profile: SensorProfile | None | bool = False  # False: not read yet

    @property
    def calibration(self) -> SensorProfile | None:
        """``calibration.json`` as the ``distance_quantile`` profile :data:`SIM_PROFILE` of its
        branch (built once), None when the weights folder has none."""
        if self._calibration is None and self._calibration_map is not None:
            self._calibration = SensorProfile(
                name=SIM_PROFILE,
                sensor=SIM_SENSOR,
                form="distance_quantile",
                input=f"nidar:{self._calibration_map.branch}",
                mapping=self._calibration_map,
                model=self.identity(),
                provenance={
                    "data": (
                        "the rendered training split of these weights (see their MODEL_CARD.md)"
                    ),
                    "file": str(Path(self.weights_dir) / "calibration.json"),
                },
            )
        return self._calibration

    def identity(self) -> dict[str, str]:
        """SHA-256 of the weight files (``irnet_sha256``, ``stn_sha256`` when it has one): what
        a sensor profile records of the networks it was fitted for (computed once)."""
        if getattr(self, "_identity", None) is None:
            from ..io.cache_key import file_sha256

            ident = {}
            for key in ("irnet", "stn"):
                path = Path(self.weights_dir) / f"{key}.safetensors"
                if path.is_file():
                    ident[f"{key}_sha256"] = file_sha256(path)
            self._identity = ident
        return dict(self._identity)

    def default_profile(self) -> SensorProfile | None:
        """The mapping of the R branch when :meth:`point_intensity` is given no profile: the
        weights folder's ``profiles/sim-905.json`` (read once), else :attr:`calibration`; also
        :attr:`calibration` when that file was fitted for other networks (retrained weights: a
        warning). None when the folder has neither."""
        if self._default_profile is False:
            import warnings

            path = Path(self.weights_dir) / "profiles" / f"{SIM_PROFILE}.json"
            profile = load_profile(path) if path.is_file() else None
            if profile is not None and profile.model not in (None, self.identity()):
                warnings.warn(
                    f"{path} was fitted for other networks than {self.weights_dir}'s (retrained?):"
                    " ignored, calibration.json maps R; refit it with python -m nidar_mi.calibrate",
                    stacklevel=2,
                )
                profile = None
            self._default_profile = profile
        return self._default_profile or self.calibration

    @classmethod
    def load(
        cls,
        weights_dir: str | os.PathLike | None = None,
        device: str | None = "auto",
        *,
        optimize: bool = True,
        scale: float | None = None,
    ) -> NidarModel:
        """Load a weights folder (default: the shipped one); safetensors only, nothing unpickled.

        Args:
            weights_dir: the folder; None: the shipped model.
            device: ``"auto"`` (CUDA when available), ``"cpu"``, ``"cuda[:N]"``.
            optimize: prepare the networks for inference (BatchNorm folded into the
                convolutions, channels-last memory: :mod:`nidar_mi.nidar.fold`); the outputs
                change by less than 1e-5.
            scale: default inference resolution relative to the image, in (0, 1]
                (:mod:`nidar_mi.nidar.infer`); None: the resolution IRNet was trained at
                (``config.json``'s ``train.scale``, 1 when absent).
        """
        from .infer import reduced_size
        from .model_io import load_pipeline

        if scale is not None:
            reduced_size(1, 1, scale)  # checks the scale
        wdir = Path(weights_dir) if weights_dir is not None else shipped_weights_dir()
        if not (wdir / "irnet.safetensors").is_file():
            raise NidarError(f"{wdir}: no NIDAR weights (irnet.safetensors) found")
        stn, irnet, cfg = load_pipeline(wdir, device=device)
        if scale is None:
            scale = cfg.scale
        if optimize:
            stn, irnet = _optimized(stn, irnet)
        calib_path = wdir / "calibration.json"
        calib = DistanceQuantileMap.load_json(calib_path) if calib_path.is_file() else None
        model = cls(stn, irnet, cfg, calib, wdir)
        model.scale = float(scale)
        return model

    def predict_image(
        self,
        rgb: np.ndarray,
        *,
        scale: float | None = None,
        as_tensors: bool = False,
        outputs: tuple[str, ...] | None = None,
    ) -> dict:
        """Dense maps of one (H, W, 3) uint8 sRGB image: pseudo_nir, R, S, I_hat (H, W) float32.

        Args:
            rgb: the camera image.
            scale: inference resolution relative to the image (None: the model's default).
            as_tensors: keep the maps on the networks' device, as tensors
                (:func:`nidar_mi.nidar.infer.predict`); else NumPy arrays.
            outputs: the maps to compute, any of :data:`nidar_mi.nidar.infer.OUTPUTS`; None:
                all four.
        """
        from .infer import OUTPUTS, predict

        rgb = np.asarray(rgb)
        if rgb.ndim != 3 or rgb.shape[2] < 3 or rgb.dtype != np.uint8:
            raise NidarError(f"expected an (H, W, 3) uint8 image, got {rgb.shape} {rgb.dtype}")
        s = self.scale if scale is None else float(scale)
        rgb = np.ascontiguousarray(rgb[..., :3])
        return predict(
            self.stn, self.irnet, rgb, scale=s, as_tensors=as_tensors, outputs=outputs or OUTPUTS
        )

    def point_intensity(
        self,
        xyz_lidar: np.ndarray,
        cameras: Sequence[CameraModel],
        images: Sequence[np.ndarray],
        *,
        depth_images: Sequence[np.ndarray | None] | None = None,
        occlusion: bool = True,
        maps: Sequence[dict[str, np.ndarray]] | None = None,
        branch: str = "R",
        profile: SensorProfile | None = None,
        ring: np.ndarray | None = None,
        cos_incidence: np.ndarray | None = None,
    ) -> PointIntensity:
        """Intensity of LiDAR-frame points seen by calibrated cameras.

        The networks run on a second thread (on their device) while the points are located in
        the cameras and their incidence estimated on the host (the result is that of the stages
        in turn); on two cores one torch thread (``torch.set_num_threads(1)``) makes the faster
        frame (docs/BENCHMARKS.md).

        ``branch="R"`` (default, the paper's NIDAR-Full): the reflectance branch through the
        weights' own profile (:meth:`default_profile`: ``profiles/sim-905.json`` when the
        folder has one, else ``calibration.json``'s distance encoding and quantile map).
        ``branch="I_hat"``: IRNet's dense intensity head sampled at the points and clipped to
        [0, 1], no calibration. A ``context`` profile reads the observed points' local geometry,
        the image around them and NIDAR's maps there (:meth:`_context_intensity`).

        Args:
            xyz_lidar: (N, 3) points in the LiDAR frame, m (the LiDAR sits at the origin).
            cameras: C camera models (intrinsics + LiDAR-to-camera extrinsics).
            images: C (H, W, 3) uint8 sRGB images.
            depth_images: optional C rendered depth images for the occlusion test (else the
                cloud's own z-buffer).
            occlusion: reject points hidden from the camera.
            maps: precomputed :meth:`predict_image` outputs (skips the networks).
            branch: ``"R"`` or ``"I_hat"`` (ignored with a ``profile``).
            profile: a sensor profile (:mod:`nidar_mi.profiles`): its NIDAR map at the
                points through its mapping (range, ring, elevation) instead of ``branch``.
            ring: optional (N,) ring of each point (-1 unknown), for a ``range_ring`` profile.
            cos_incidence: optional (N,) ``|cos θ|`` of the rays on the surfaces, for a profile
                that reads it; None: estimated from the observed points themselves
                (:func:`nidar_mi.geometry.incidence_cosine` on the returns the cameras see, as
                such profiles are fitted: on a scan's camera-visible returns).
        """
        if profile is None and branch == "R":
            profile = self.default_profile()
            if profile is None:
                raise NidarError(f"{self.weights_dir}: no calibration.json beside the weights")
        if profile is not None:
            branch = profile.branch
            if branch is None:
                raise NidarError(f"profile {profile.name} does not map a NIDAR branch")
        if branch not in BRANCHES:
            raise NidarError(f"branch must be one of {', '.join(BRANCHES)} (got '{branch}')")
        xyz = np.asarray(xyz_lidar, dtype=np.float64)
        if ring is not None and np.asarray(ring).reshape(-1).shape != (len(xyz),):
            raise NidarError(f"{np.asarray(ring).size} rings for {len(xyz)} points")
        if len(cameras) != len(images):
            raise NidarError("one image per camera is needed")
        opts = {"depth_images": depth_images, "occlusion": occlusion}
        if profile is not None and profile.reads_context:
            return self._context_intensity(xyz, cameras, images, maps, profile, opts, ring)
        wants_cos = profile is not None and profile.uses_incidence and cos_incidence is None
        values, observed, cam_idx, r_vals, seen_cos = self._sampled_maps(
            xyz, cameras, images, maps, branch, opts, wants_cos
        )
        observed = observed & np.isfinite(values)
        if profile is None:  # the dense head, raw
            out = np.where(observed, np.clip(values, 0.0, 1.0), 0.0).astype(np.float32)
        else:
            out = _profile_intensity(
                profile, xyz, values, observed, ring, cos_incidence, seen_cos=seen_cos
            )
        raw = np.where(observed, values, 0.0).astype(np.float32)
        refl = raw
        if r_vals is not None:
            refl = np.where(observed & np.isfinite(r_vals), r_vals, 0.0).astype(np.float32)
        return PointIntensity(out, observed, raw, np.where(observed, cam_idx, -1), refl)

    def _sampled_maps(self, xyz, cameras, images, maps, branch, opts, wants_cos):
        """``(values, observed, camera_index, R or None, seen_cos)``: :func:`_sample` of the
        networks' maps of ``images`` (``maps`` when given) at the points, the geometry located
        beside the networks (:meth:`_maps_beside_geometry`; ``seen_cos`` as there)."""
        keys = tuple(dict.fromkeys((branch, "R")))  # the maps sampled
        maps, sightings, seen_cos = self._maps_beside_geometry(
            xyz, cameras, images, maps, keys, opts, wants_cos
        )
        return *_sample(xyz, cameras, maps, branch, sightings=sightings), seen_cos

    def _maps_beside_geometry(self, xyz, cameras, images, maps, keys, opts, wants_cos):
        """``(maps, sightings, seen_cos)``: the networks' ``keys`` maps of ``images`` (on a
        second thread; ``maps`` when given), while this thread locates the points in the
        cameras (:func:`~nidar_mi.geometry.locate_in_cameras` with ``opts``) and, when
        ``wants_cos``, estimates the incidence at the points they see: ``seen_cos`` is then
        ``(seen, cos, notes)``, (N,) bool, the cosines of ``xyz[seen]`` and the messages of
        the estimate's warnings (warned only if the cosines are used), else None. Both halves
        release the GIL for most of their work, so on a CPU of two or more cores they overlap
        (docs/BENCHMARKS.md); the results are those of running them in turn. ``wants_cos`` a
        tuple of neighbourhood sizes: ``seen_cos`` holds the seen points'
        :func:`~nidar_mi.geometry.local_features.local_geometry` at them in place of the
        cosines."""
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(1) as pool:
            pending = None
            if maps is None:
                pending = pool.submit(
                    lambda: [self.predict_image(im, outputs=keys) for im in images]
                )
            try:
                sightings = locate_in_cameras(xyz, cameras, **opts)
                seen_cos = None
                if wants_cos:  # scales: the local geometry at them, incidence among it
                    seen, notes = sightings.seen, []
                    p = xyz[seen]
                    if wants_cos is True:
                        est = incidence_cosine(p, notes=notes)
                    else:
                        est = local_geometry(p, wants_cos, notes=notes)
                    seen_cos = (seen, est, notes)
            except BaseException:
                if pending is not None:
                    pending.cancel()  # leaving the pool waits for a running one
                raise
            if pending is not None:
                maps = pending.result()
        return maps, sightings, seen_cos

    def _context_intensity(self, xyz, cameras, images, maps, profile, opts, ring) -> PointIntensity:
        """:meth:`point_intensity` through a ``context`` profile, on the CPU: the networks
        give the branch, R and the NIDAR maps the profile reads (on a second thread while the
        points are located and the seen points' local geometry computed); the observed points'
        inputs (:mod:`nidar_mi.profiles.inputs`) go to the profile.

        Raises:
            NidarError: a profile that reads the image given no image (``images`` of None).
        """
        from ..profiles.inputs import camera_inputs, return_inputs, scales_read

        if profile.needs_image and any(im is None for im in images):
            raise NidarError(
                f"profile {profile.name} reads the camera image at the returns; give the images"
            )
        keys = tuple(dict.fromkeys((profile.branch, "R", *_nidar_inputs(profile))))
        scales = scales_read(profile.mapping.features)  # only the sizes it reads
        maps, sightings, seen_geo = self._maps_beside_geometry(
            xyz, cameras, images, maps, keys, opts, scales
        )
        values, observed, cam_idx = sample_cameras(
            xyz, cameras, [_array(m[profile.branch]) for m in maps], sightings=sightings
        )
        observed &= np.isfinite(values)
        seen, geo, notes = seen_geo
        if not np.array_equal(seen, observed):
            geo, notes = None, []  # estimated again from the observed points, as fitted
        for message in notes:
            warnings.warn(message, stacklevel=3)
        rings = None if ring is None else np.asarray(ring).reshape(-1)[observed]
        named = return_inputs(xyz[observed], rings, geo, scales)
        if profile.needs_image:
            cam = np.where(observed, cam_idx, -1)
            pics = camera_inputs(sightings, images, cam, [{k: m[k] for k in keys} for m in maps])
            named |= {k: v[observed] for k, v in pics.items()}
        out = np.zeros(len(xyz), dtype=np.float32)
        out[observed] = profile(values[observed], named["range_m"], context=named)
        raw = np.where(observed, values, 0.0).astype(np.float32)
        r_vals = sample_cameras(xyz, cameras, [_array(m["R"]) for m in maps], sightings=sightings)[
            0
        ]
        refl = np.where(observed, r_vals, 0.0).astype(np.float32)
        return PointIntensity(out, observed, raw, np.where(observed, cam_idx, -1), refl)


def _nidar_inputs(profile: SensorProfile) -> tuple[str, ...]:
    """The NIDAR maps a ``context`` profile reads."""
    from ..profiles.inputs import NIDAR_MAPS

    return tuple(k for k in NIDAR_MAPS if k in profile.mapping.features)


def _sample(xyz, cameras, maps, branch: str, **opts):
    """``(values, observed, camera_index, R or None)`` (N,) arrays of ``branch``'s maps at the
    points (:func:`~nidar_mi.geometry.fusion.sample_cameras` with ``opts``), and of R when the
    branch is another."""
    keys = [branch] if branch == "R" else [branch, "R"]
    sampled = [sample_cameras(xyz, cameras, [_array(m[k]) for m in maps], **opts) for k in keys]
    return (*sampled[0], sampled[1][0] if len(sampled) > 1 else None)


def _array(a) -> np.ndarray:
    """A map as a NumPy array (a tensor copied to the host)."""
    return a.detach().cpu().numpy() if hasattr(a, "detach") else np.asarray(a)


def _profile_intensity(
    profile: SensorProfile,
    xyz: np.ndarray,
    values: np.ndarray,
    observed: np.ndarray,
    ring: np.ndarray | None,
    cos_incidence: np.ndarray | None,
    seen_cos: tuple[np.ndarray, np.ndarray, list[str]] | None = None,
) -> np.ndarray:
    """(N,) float32 intensity of the observed points through ``profile``, 0 elsewhere: their
    range, elevation, ring and incidence (given, or estimated from the observed points: taken
    from ``seen_cos``, ``(seen, cos, notes)``, when its points are exactly the observed ones,
    and its estimate's warnings, ``notes``, then warned)."""
    out = np.zeros(len(xyz), dtype=np.float32)
    if not observed.any():
        return out
    p = xyz[observed]
    r = None if ring is None else np.asarray(ring).reshape(-1)[observed]
    el = np.degrees(np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1])))
    cos = None
    if profile.uses_incidence:
        if cos_incidence is None and seen_cos is not None and np.array_equal(seen_cos[0], observed):
            cos = seen_cos[1]
            for message in seen_cos[2]:  # located here, as the estimate's own warning would be
                warnings.warn(message, stacklevel=1)
        elif cos_incidence is None:
            cos = incidence_cosine(p)
        else:
            cos = np.asarray(cos_incidence, dtype=np.float64).reshape(-1)
            if cos.shape != (len(xyz),):
                raise NidarError(f"{cos.size} incidence cosines for {len(xyz)} points")
            cos = cos[observed]
    out[observed] = profile(
        values[observed], np.linalg.norm(p, axis=1), ring=r, elevation_deg=el, cos_incidence=cos
    )
    return out
