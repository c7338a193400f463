"""The render folder: what ``render`` writes, and what the dataset builder and the evaluation read.

One module owns the layout (the table of files is in the README, "Rendering")::

    OUT/manifest.json                           the request, versions, resolved parameters, timings
    OUT/<lidar_id>/points.{npz,ply,las,bin,pcd} valid returns (schema: nidar_mi.io.points)
    OUT/<lidar_id>/range_image.exr, range.png, intensity.png
    OUT/<camera_id>/rgb.{png,exr}, nir.{png,exr}, depth.exr, reflectance.exr, albedo.exr,
        surface_reflectance.exr, calib.json
    OUT/<camera_id>/nir_<λ>nm.{png,exr}          further NIR bands (LiDARs at other wavelengths)

Writers take the in-memory results (:class:`~nidar_mi.lidar.scan.ScanResult`,
:class:`~nidar_mi.camera.CameraRender`); :func:`read_render` gives them back as arrays and camera
models. A :class:`RenderRequest` holds every input that determines a render; it is stored in the
manifest, and :func:`is_current` tells whether a folder already holds the render of a request
(the cache key of the dataset builder and the evaluation).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from .errors import NidarError
from .io.cache_key import file_sha256
from .io.ownership import Owner

__all__ = [
    "BIN_INTENSITY",
    "DEFAULT_FORMATS",
    "FORMATS",
    "MANIFEST",
    "RENDER_OWNER",
    "SEQUENCE_OWNER",
    "RenderRequest",
    "RenderedCamera",
    "RenderedScan",
    "bin_intensity_values",
    "folder_bytes",
    "is_current",
    "read_manifest",
    "read_render",
    "write_camera",
    "write_lidar",
    "write_manifest",
]

#: Point-cloud formats a LiDAR folder can hold (``laz``: LAS compressed by laspy's lazrs back
#: end, the ``laz`` extra).
FORMATS = ("npz", "ply", "las", "laz", "bin", "pcd")
#: The formats written when none are asked for.
DEFAULT_FORMATS = ("npz", "ply", "las", "bin")
#: ``bin_intensity`` values: KITTI's [0, 1] convention, or the simulator's own intensity.
BIN_INTENSITY = ("unit", "raw")
#: The manifest's file name; its presence marks a folder as a render folder.
MANIFEST = "manifest.json"
#: Version of the folder layout; part of the cache key, so folders of an older layout (e.g.
#: without ``reflectance.exr`` or ``albedo.exr``) are rendered again.
LAYOUT_VERSION = 3


#: The files of a NIDAR weights folder that decide its output (those present are hashed).
WEIGHTS_FILES = (
    "stn.safetensors",
    "irnet.safetensors",
    "config.json",
    "calibration.json",
    "profiles/sim-905.json",
)


def weights_sha256(weights: str | os.PathLike | None) -> str:
    """Hex SHA-256 over the :data:`WEIGHTS_FILES` of a weights folder (None: the shipped one),
    each file's name and bytes, in order; a missing file counts as absent."""
    shipped = os.path.join(os.path.dirname(os.path.abspath(__file__)), "nidar", "weights")
    root = os.fspath(weights) if weights is not None else shipped
    h = hashlib.sha256()
    for name in WEIGHTS_FILES:
        path = os.path.join(root, name)
        h.update(name.encode() + b"\0")
        h.update(file_sha256(path).encode() if os.path.isfile(path) else b"absent")
    return h.hexdigest()


@dataclass(frozen=True)
class RenderRequest:
    """Every input that determines a render (the cache key of a render folder).

    Attributes:
        scene: absolute path of the scene XML.
        scene_sha256: hash of its bytes (an edited scene is a new request).
        params: the scene's ``<default>`` values given on the command line (``-D``).
        seed: scan and sampler seed; None keeps each LiDAR's own.
        spp: camera samples per pixel.
        formats: point-cloud formats written.
        cameras: whether the cameras were rendered.
        rgb_twin: whether the scene's RGB-only twin was loaded.
        intensity: ``physics`` or ``nidar``.
        weights: NIDAR weights folder (``nidar`` only; None: the shipped model).
        weights_sha256: hash of the weights folder's contents that decide NIDAR's output
            (:func:`weights_sha256`; ``nidar`` only): retrained weights or a refitted default
            profile at the same path are a new request.
        nidar_branch: NIDAR branch (``nidar`` only).
        profile: NIDAR sensor profile as ``<name>@<hash of its content>`` (``nidar`` only;
            None: the weights' own ``sim-905``).
        bin_intensity: intensity convention of ``points.bin`` (:data:`BIN_INTENSITY`).
        layout: :data:`LAYOUT_VERSION` of the folder.
        weather: the weather set for the render (:meth:`nidar_mi.weather.Weather.to_dict`);
            None (and absent from :meth:`to_dict`, as before weather existed): the scene's own.
        labels: whether the shapes' labels were read; recorded only when False, so that the
            requests of renders with labels read as they always did.
    """

    scene: str
    scene_sha256: str
    params: dict[str, str] = field(default_factory=dict)
    seed: int | None = None
    spp: int = 16
    formats: tuple[str, ...] = DEFAULT_FORMATS
    cameras: bool = True
    rgb_twin: bool = False
    intensity: str = "physics"
    weights: str | None = None
    weights_sha256: str | None = None
    nidar_branch: str | None = None
    profile: str | None = None
    bin_intensity: str = "unit"
    layout: int = LAYOUT_VERSION
    weather: dict | None = None
    labels: bool = True

    @classmethod
    def of(cls, scene_path: str | os.PathLike, **options: Any) -> RenderRequest:
        """The request for a scene file (hashes the file); ``options`` are the fields."""
        from .io.atomic import file_problem

        path = os.path.abspath(scene_path)
        problem = file_problem(path, "scene file")
        if problem:
            raise NidarError(f"{scene_path}: {problem}")
        params = {str(k): str(v) for k, v in sorted((options.pop("params", None) or {}).items())}
        options["formats"] = tuple(options.get("formats", DEFAULT_FORMATS))
        if options.get("intensity", "physics") != "nidar":
            options["weights"] = options["nidar_branch"] = options["profile"] = None
        else:
            if options.get("weights") is not None:
                options["weights"] = os.path.abspath(options["weights"])
            options["weights_sha256"] = weights_sha256(options.get("weights"))
        return cls(scene=path, scene_sha256=file_sha256(path), params=params, **options)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict (what the manifest stores under ``request``)."""
        d = asdict(self)
        d["formats"] = list(self.formats)
        if d["weather"] is None:
            del d["weather"]
        if self.labels:
            del d["labels"]
        return d


def write_manifest(folder: str | os.PathLike, manifest: dict) -> None:
    """Write ``folder/manifest.json`` atomically."""
    from .io.atomic import atomic_write_json

    atomic_write_json(os.path.join(folder, MANIFEST), manifest)


def _manifest_files(folder) -> list[str]:
    """The files a render or sequence folder of nidar_mi 0.1.0 (no record) lists."""
    manifest = read_manifest(folder)
    return [MANIFEST, *manifest["files"]]


#: Who writes a render folder (one render) and a sequence folder (``render --trajectory``):
#: :mod:`nidar_mi.io.ownership`; an unrecorded folder of either is recognised by its manifest.
RENDER_OWNER = Owner("render", "scene", names=(MANIFEST,), listed=_manifest_files)
SEQUENCE_OWNER = Owner(
    "render", "sequence", names=(MANIFEST,), listed=_manifest_files, label="render --trajectory"
)


def read_manifest(folder: str | os.PathLike) -> dict:
    """The manifest of a render folder.

    Raises:
        NidarError: missing, unreadable or not a JSON object.
    """
    path = os.path.join(folder, MANIFEST)
    try:
        with open(path, encoding="utf-8") as f:
            manifest = json.load(f)
    except OSError as e:
        raise NidarError(f"{folder}: no readable {MANIFEST} ({e.strerror})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise NidarError(f"{path}: not valid JSON ({e})") from None
    if not isinstance(manifest, dict):
        raise NidarError(f"{path}: not a render manifest")
    return manifest


def is_current(folder: str | os.PathLike, request: RenderRequest) -> bool:
    """Whether ``folder`` holds a complete render of exactly ``request``."""
    try:
        manifest = read_manifest(folder)
    except NidarError:
        return False
    if manifest.get("request") != request.to_dict():
        return False
    return all(os.path.isfile(os.path.join(folder, f)) for f in manifest.get("files", []))


# --------------------------------------------------------------------------- size

#: Bytes per point of each format, the simulator's columns (:mod:`nidar_mi.io.points`), rounded
#: up; LAS adds its point record (LAZ, compressed, is counted as LAS), ``bin`` holds x, y, z and
#: intensity only.
POINT_BYTES = {"npz": 64, "ply": 64, "pcd": 64, "las": 80, "laz": 80, "bin": 16}
#: Bytes per point of ``xyz_deskewed`` (every format but ``bin``).
DESKEW_BYTES = 12
#: Bytes per beam of ``range_image.exr`` (4 float32 channels, uncompressed).
RANGE_IMAGE_BYTES = 16
#: Bytes per pixel of a camera: rgb.exr, nir.exr, depth.exr, reflectance.exr, albedo.exr,
#: surface_reflectance.exr, rgb.png, nir.png.
PIXEL_BYTES = 44
#: Bytes per pixel of each further NIR band (its .exr and .png).
BAND_PIXEL_BYTES = 5
#: A manifest's entry and calib.json, per sensor, bytes (a LiDAR's laser table is most of it).
SENSOR_META_BYTES = 32 << 10


def _preview_bytes(rings: int, columns: int) -> int:
    """A range or intensity preview (:func:`nidar_mi.io.range_preview.write_range_preview`):
    one byte per pixel of its figure, more than its PNG takes."""
    w = max(columns, 640)
    return (w + 80) * (max(rings, min(w // 6, rings * 8)) + 104)


def folder_bytes(lidars, cameras, formats, *, deskew: bool = False, bands: int = 1) -> int:
    """Estimated size of one render folder, bytes: an upper bound for the points (every beam
    returns ``max_returns`` times) and the uncompressed images, the previews and manifests.

    Args:
        lidars: the LiDARs' :class:`~nidar_mi.lidar.config.LidarConfig`.
        cameras: (width, height) of each camera rendered, pixels.
        formats: point formats written (:data:`FORMATS`).
        deskew: ``xyz_deskewed`` is written.
        bands: NIR bands per camera (one per distinct LiDAR wavelength).
    """
    per_point = sum(
        POINT_BYTES[f] + (DESKEW_BYTES if deskew and f != "bin" else 0) for f in formats
    )
    total = 0
    for cfg in lidars:
        beams = cfg.rings * cfg.horizontal_resolution
        total += beams * (cfg.max_returns * per_point + RANGE_IMAGE_BYTES) + SENSOR_META_BYTES
        total += 2 * _preview_bytes(cfg.rings, cfg.horizontal_resolution)
    pixel = PIXEL_BYTES + BAND_PIXEL_BYTES * (bands - 1)
    total += sum(w * h * pixel + SENSOR_META_BYTES for w, h in cameras)
    return total


# --------------------------------------------------------------------------- writing


def bin_intensity_values(intensity: np.ndarray, config, bin_intensity: str = "unit") -> np.ndarray:
    """The intensity a KITTI ``.bin`` of this simulator holds, per frame or in a sequence.

    Args:
        intensity: (N,) the simulated intensity (``points["intensity"]``).
        config: the LiDAR's :class:`~nidar_mi.lidar.config.LidarConfig`.
        bin_intensity: ``unit``: KITTI's [0, 1], ``clip(I / I_full, 0, 1)`` with ``I_full`` the
            sensor's :func:`~nidar_mi.lidar.return_model.full_scale_intensity`; ``raw``: as it is.

    Returns:
        (N,) float32.
    """
    from .lidar.return_model import full_scale_intensity

    if bin_intensity not in BIN_INTENSITY:
        raise NidarError(f"`bin_intensity` must be one of {', '.join(BIN_INTENSITY)}")
    intensity = np.asarray(intensity, dtype=np.float32)
    if bin_intensity == "raw":
        return intensity
    full = full_scale_intensity(config.gain, config.intensity_mode)
    return np.clip(intensity / np.float32(full), 0, 1).astype(np.float32)


def write_lidar(
    folder: str | os.PathLike,
    result,
    formats,
    extra: dict | None = None,
    bin_intensity: str = "unit",
    *,
    deskew: bool = False,
    previews: bool = True,
) -> list[str]:
    """Write one LiDAR's points, range image and previews into ``folder/<lidar id>/``.

    Intensity encodings are fixed per sensor, never per frame: LAS stores
    ``round(clip(I / I_full, 0, 1) · 65535)`` counts and KITTI ``.bin`` (``bin_intensity``
    ``unit``, the default) ``clip(I / I_full, 0, 1)``, with ``I_full`` the sensor's
    :func:`~nidar_mi.lidar.return_model.full_scale_intensity`; ``bin_intensity="raw"`` writes
    the intensity as it is. npz and PLY always hold the float intensity unchanged.

    Args:
        folder: the render folder (or its staging copy).
        result: a :class:`~nidar_mi.lidar.scan.ScanResult`.
        formats: point formats from :data:`FORMATS`.
        extra: further per-point columns (e.g. ``intensity_nidar``).
        bin_intensity: ``unit`` or ``raw`` (:data:`BIN_INTENSITY`).
        deskew: add ``xyz_deskewed`` (the points in the LiDAR frame at the sweep's start).
        previews: write the ``range.png`` and ``intensity.png`` previews.

    Returns:
        The paths written.
    """
    from .io import images
    from .io import points as pio
    from .io.kitti import write_kitti_bin
    from .io.las import write_las
    from .io.pcd import write_pcd
    from .io.range_preview import write_range_preview
    from .lidar.return_model import full_scale_intensity

    if bin_intensity not in BIN_INTENSITY:
        raise NidarError(f"`bin_intensity` must be one of {', '.join(BIN_INTENSITY)}")
    cfg = result.config
    d = os.path.join(folder, cfg.name)
    os.makedirs(d, exist_ok=True)
    pts = result.points(deskew=deskew) | dict(extra or {})
    full = full_scale_intensity(cfg.gain, cfg.intensity_mode)
    bin_i = bin_intensity_values(pts["intensity"], cfg, bin_intensity)
    writers = {
        "npz": lambda p: pio.write_npz(p, pts),
        "ply": lambda p: pio.write_ply(p, pts),
        "las": lambda p: write_las(p, pts, intensity_scale=65535.0 / full),
        "laz": lambda p: write_las(p, pts, intensity_scale=65535.0 / full),
        "bin": lambda p: write_kitti_bin(p, pts["xyz"], bin_i),
        "pcd": lambda p: write_pcd(p, pts),
    }
    written = []
    for fmt in formats:
        path = os.path.join(d, f"points.{fmt}")
        writers[fmt](path)
        written.append(path)
    valid = result.valid
    channels = {
        "range": np.where(valid, result.range, 0.0).astype(np.float32),
        "intensity": np.where(valid, result.intensity, 0.0).astype(np.float32),
        "reflectance": np.where(valid, result.reflectance, 0.0).astype(np.float32),
        "valid": valid.astype(np.float32),
    }
    path = os.path.join(d, "range_image.exr")
    images.write_exr(path, channels)
    written.append(path)
    if not previews:
        return written
    azimuth = np.degrees(np.arctan2(result.directions[0, :, 1], result.directions[0, :, 0]))
    unit = "1/m²" if cfg.intensity_mode == "raw" else "unitless"
    for key, label in (("range", "range (m)"), ("intensity", f"intensity ({unit})")):
        path = os.path.join(d, f"{key}.png")
        write_range_preview(path, channels[key], valid, azimuth, label=label)
        written.append(path)
    return written


def _gray8(img: np.ndarray) -> np.ndarray:
    from .io.images import linear_to_srgb

    return np.round(linear_to_srgb(np.clip(img, 0.0, 1.0)) * 255.0).astype(np.uint8)


def nir_file(wavelength: float) -> str:
    """File name of a further NIR band image, e.g. ``nir_1550nm.exr``."""
    return f"nir_{wavelength:g}nm.exr"


def write_camera(
    folder: str | os.PathLike, render, lidar_poses: dict[str, np.ndarray]
) -> tuple[dict, list[str]]:
    """Write one camera's images and calibration into ``folder/<camera id>/``.

    Args:
        folder: the render folder (or its staging copy).
        render: a :class:`~nidar_mi.camera.CameraRender`.
        lidar_poses: LiDAR id -> (4, 4) LiDAR-to-world pose, for ``T_cam_lidar``.

    Returns:
        ``(calib, paths)``: the calibration written to ``calib.json`` and the paths written.
    """
    from .io import atomic, images

    d = os.path.join(folder, render.name)
    os.makedirs(d, exist_ok=True)
    exposure = render.exposure()
    outputs = {
        "rgb.png": lambda p: images.write_png(p, render.srgb8()),
        "rgb.exr": lambda p: images.write_exr(
            p, {"R": render.rgb[..., 0], "G": render.rgb[..., 1], "B": render.rgb[..., 2]}
        ),
        "nir.png": lambda p: images.write_png(p, _gray8(render.nir * exposure)),
        "nir.exr": lambda p: images.write_exr(p, {"Y": render.nir}),
        "depth.exr": lambda p: images.write_exr(p, {"Z": render.depth}),
    }
    if render.reflectance is not None:
        outputs["reflectance.exr"] = lambda p: images.write_exr(p, {"Y": render.reflectance})
    if render.albedo is not None:
        a = render.albedo
        outputs["albedo.exr"] = lambda p: images.write_exr(
            p, {"R": a[..., 0], "G": a[..., 1], "B": a[..., 2]}
        )
    if render.surface_reflectance is not None:
        rs = render.surface_reflectance
        outputs["surface_reflectance.exr"] = lambda p: images.write_exr(p, {"Y": rs})
    nir_images = {f"{render.wavelength:g}": "nir.exr"}
    for wl, band in render.other_nir.items():
        name = nir_file(wl)
        nir_images[f"{wl:g}"] = name
        outputs[name] = lambda p, b=band: images.write_exr(p, {"Y": b})
        outputs[name[:-4] + ".png"] = lambda p, b=band: images.write_png(p, _gray8(b * exposure))
    written = []
    for fname, fn in outputs.items():
        path = os.path.join(d, fname)
        fn(path)
        written.append(path)
    T_cam_world = np.linalg.inv(render.T_world_cam)
    calib = {
        "convention": "opencv",
        "width": int(render.rgb.shape[1]),
        "height": int(render.rgb.shape[0]),
        "K": render.K.tolist(),
        "T_world_cam": render.T_world_cam.tolist(),
        "T_cam_lidar": {k: (T_cam_world @ T).tolist() for k, T in lidar_poses.items()},
        "nir_wavelength_nm": render.wavelength,
        "nir_images": nir_images,
        "png_exposure": exposure,
    }
    path = os.path.join(d, "calib.json")
    atomic.atomic_write_json(path, calib)
    written.append(path)
    return calib, written


# --------------------------------------------------------------------------- reading


@dataclass
class RenderedCamera:
    """One camera of a render folder.

    Attributes:
        name: camera id.
        folder: its output folder (rgb.png, nir.exr, depth.exr, calib.json).
        model: camera model with ``T_cam_lidar`` of the scan's LiDAR.
        depth: (H, W) float32 z-depth in m, 0 where no surface.
        calib: its ``calib.json`` entry of the manifest.
    """

    name: str
    folder: str
    model: object
    depth: np.ndarray
    calib: dict = field(default_factory=dict)

    def rgb8(self) -> np.ndarray:
        """(H, W, 3) uint8 sRGB (rgb.png)."""
        from .io.images import read_png

        return read_png(os.path.join(self.folder, "rgb.png"))[..., :3]

    def nir(self, wavelength: float | None = None) -> np.ndarray:
        """(H, W) float32 NIR band radiance at ``wavelength`` nm (default: ``nir.exr``, the band
        of the render's first LiDAR by id).

        Raises:
            NidarError: the render holds no band at ``wavelength``.
        """
        from .io.images import read_exr

        name = "nir.exr"
        if wavelength is not None:
            images = self.calib.get("nir_images") or {
                f"{self.calib.get('nir_wavelength_nm', 0):g}": "nir.exr"
            }
            name = images.get(f"{float(wavelength):g}")
            if name is None:
                raise NidarError(
                    f"{self.folder}: no NIR image at {wavelength:g} nm (has {', '.join(images)} nm)"
                )
        return _single_channel(read_exr(os.path.join(self.folder, name)))

    def reflectance(self) -> np.ndarray:
        """(H, W) float32 monostatic ρ(λ)·T² per pixel centre (reflectance.exr).

        Raises:
            NidarError: the folder has no reflectance.exr.
        """
        from .io.images import read_exr

        return _single_channel(read_exr(os.path.join(self.folder, "reflectance.exr")))

    def albedo(self) -> np.ndarray:
        """(H, W, 3) float32 linear sRGB of the surfaces' diffuse reflectance (albedo.exr).

        Raises:
            NidarError: the folder has no albedo.exr.
        """
        from .io.images import read_exr

        channels = read_exr(os.path.join(self.folder, "albedo.exr"))
        return np.stack([channels[c] for c in "RGB"], -1).astype(np.float32)

    def surface_reflectance(self) -> np.ndarray:
        """(H, W) float32 the surfaces' diffuse reflectance at λ (surface_reflectance.exr).

        Raises:
            NidarError: the folder has no surface_reflectance.exr.
        """
        from .io.images import read_exr

        return _single_channel(read_exr(os.path.join(self.folder, "surface_reflectance.exr")))


@dataclass
class RenderedScan:
    """A render folder seen from one LiDAR.

    Attributes:
        folder: the render folder.
        manifest: its manifest.json.
        lidar: the LiDAR id.
        parameters: its resolved parameters.
        points: its points dict (``points.npz``).
        compensated: (N,) float32 range-compensated intensity ``g·ρ·cosθ·exp(-2αd)`` (+ noise·d²
            in ``raw`` mode).
        cameras: every camera, sorted by id.
    """

    folder: str
    manifest: dict
    lidar: str
    parameters: dict
    points: dict
    compensated: np.ndarray
    cameras: list[RenderedCamera]


def _single_channel(channels: dict[str, np.ndarray]) -> np.ndarray:
    return next(iter(channels.values())).astype(np.float32)


def read_render(folder: str | os.PathLike, lidar_id: str | None = None) -> RenderedScan:
    """Read a render folder (the first LiDAR by id unless ``lidar_id`` names one).

    Raises:
        NidarError: missing or malformed manifest, or an unknown LiDAR id.
    """
    from .io.calib import render_calib_model
    from .io.images import read_exr
    from .io.points import read_npz
    from .lidar.return_model import compensate

    folder = os.fspath(folder)
    manifest = read_manifest(folder)
    lidars = sorted(manifest.get("lidars", {}))
    if not lidars:
        raise NidarError(f"{folder}: the manifest lists no lidar")
    lid = lidar_id or lidars[0]
    if lid not in manifest["lidars"]:
        raise NidarError(f"{folder}: no lidar '{lid}' (has {', '.join(lidars)})")
    params = manifest["lidars"][lid]["parameters"]
    pts = read_npz(os.path.join(folder, lid, "points.npz"))
    comp = compensate(pts["intensity"], pts["range"], params["intensity_mode"])
    cameras = []
    for cam_id, cam in sorted(manifest.get("cameras", {}).items()):
        cam_dir = os.path.join(folder, cam_id)
        model = render_calib_model(cam, cam_id, lid, f"{folder}: camera {cam_id}")
        depth = _single_channel(read_exr(os.path.join(cam_dir, "depth.exr")))
        cameras.append(RenderedCamera(cam_id, cam_dir, model, depth, cam))
    return RenderedScan(folder, manifest, lid, params, pts, comp, cameras)
