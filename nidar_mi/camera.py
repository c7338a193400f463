"""Camera renders: RGB, a NIR band image at the LiDAR wavelength, z-depth and calibration.

* RGB: the scene's own ``perspective`` sensor and film (``hdrfilm``), linear sRGB primaries.
* NIR: the same camera with a ``specfilm`` whose response is a trapezoid around λ (flat over
  λ ± :data:`NIR_HALF_PLATEAU_NM`, linear ramps of :data:`NIR_RAMP_NM` on each side). Mitsuba's
  specfilm integrates ``∫ L(λ') r(λ') dλ'``; the image is divided by ``∫ r`` so it reads band-averaged
  radiance: a uniform sky of radiance 1 reads 1. This NIR twin is loaded once per lens, film, band
  and spp and moved with the camera (its pose is data: a sequence compiles its kernels once). One band image per wavelength asked for (a scene
  with LiDARs at 905 and 1550 nm gets both).
* Cameras: ``perspective`` and ``thinlens`` sensors (:data:`CAMERA_CLASSES`); a thin-lens camera's
  NIR image has the same aperture and focus distance, and its calibration is the pinhole through
  the lens centre.
* Depth: z-depth (m, along the optical axis) of the first surface through each pixel centre, by
  casting the camera's own rays; 0 where nothing is hit.
* Reflectance: ρ(λ) at the LiDAR wavelength of the surface through each pixel centre, seen
  monostatically along the camera ray (π · f_r(ω, ω; λ), as a LiDAR at the camera would see it:
  :func:`nidar_mi.lidar.raycast.cast` and :func:`~nidar_mi.lidar.raycast.monostatic_reflectance`),
  times the two-way transmittance T² of any glass on the way; 0 where nothing is hit, at grazing
  incidence, or where the material has no finite value at λ.
* Passes: a render of more than :func:`pass_samples` samples (pixels × spp) is traced in passes
  of whole samples per pixel, each with its own seed, and averaged weighted by their spp (the
  same expected image, another noise pattern); between passes Python handles a pending signal,
  so Ctrl-C and SIGTERM stop a long render within about a pass (~1 s on 2 CPU cores). A render
  within the budget is one pass with the seed given, as before.
* Calibration: OpenCV pinhole intrinsics ``K`` (x right, y down, z forward; the centre of pixel
  (0, 0) at (0, 0)) and ``T_world_cam`` (camera-to-world, OpenCV camera axes). Mitsuba's camera
  space is x left, y up, z forward, hence ``T_world_cam = to_world · diag(-1, -1, 1, 1)``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from .errors import NidarError
from .geometry.se3 import transform_matrix
from .io.images import REC709_LUMA, linear_to_srgb

__all__ = [
    "CameraRender",
    "auto_exposure",
    "render_camera",
    "camera_calibration",
    "NIR_HALF_PLATEAU_NM",
    "NIR_RAMP_NM",
    "CAMERA_CLASSES",
    "nir_response",
    "render_memory",
    "check_render_memory",
    "pass_samples",
    "render_passes",
]

#: Mitsuba sensor classes rendered as cameras.
CAMERA_CLASSES = ("PerspectiveCamera", "ThinLensCamera")

#: Path-tracing depth used when a scene declares no integrator.
DEFAULT_MAX_DEPTH = 6
NIR_HALF_PLATEAU_NM = 5.0
NIR_RAMP_NM = 5.0


@dataclass
class CameraRender:
    """Images of one camera. Shapes: (H, W) or (H, W, 3).

    Attributes:
        name: camera id.
        rgb: (H,W,3) float32 linear sRGB.
        nir: (H,W) float32 band-averaged radiance at ``wavelength`` (W·m⁻²·sr⁻¹·nm⁻¹ units of the
            scene's emitters).
        depth: (H,W) float32 z-depth in m, 0 where no surface.
        K: (3,3) float64 OpenCV intrinsics.
        T_world_cam: (4,4) float64 camera-to-world, OpenCV axes.
        wavelength: NIR band centre of ``nir`` in nm.
        timings: seconds per stage.
        other_nir: further band centre (nm) -> (H,W) float32 band image, when several
            wavelengths were asked for.
        reflectance: (H,W) float32 monostatic ρ(λ)·T² per pixel centre at ``wavelength``
            (module docstring), or None when not rendered.
        albedo: (H,W,3) float32 linear sRGB of the surfaces' diffuse reflectance (their
            shading-free colour, :func:`_albedo`), or None when not rendered.
        surface_reflectance: (H,W) float32 the surfaces' diffuse reflectance at ``wavelength``
            (no viewing-direction effect), or None when not rendered.
    """

    name: str
    rgb: np.ndarray
    nir: np.ndarray
    depth: np.ndarray
    K: np.ndarray
    T_world_cam: np.ndarray
    wavelength: float
    timings: dict[str, float] = field(default_factory=dict)
    other_nir: dict[float, np.ndarray] = field(default_factory=dict)
    reflectance: np.ndarray | None = None
    albedo: np.ndarray | None = None
    surface_reflectance: np.ndarray | None = None

    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def exposure(self) -> float:
        """Auto exposure of this render (:func:`auto_exposure` of its RGB image; computed once:
        the images are not changed after the render)."""
        if "exposure" not in self._cache:
            self._cache["exposure"] = auto_exposure(self.rgb)
        return self._cache["exposure"]

    def srgb8(self) -> np.ndarray:
        """(H, W, 3) uint8: the image as a camera delivers it (auto exposure, sRGB, 8 bit); what
        ``rgb.png`` holds and what NIDAR sees (computed once; do not modify it)."""
        if "srgb8" not in self._cache:
            rgb = np.clip(self.rgb * self.exposure(), 0.0, 1.0).astype(np.float64)
            srgb = np.nan_to_num(linear_to_srgb(rgb), nan=0.0)
            self._cache["srgb8"] = np.round(srgb * 255).astype(np.uint8)
        return self._cache["srgb8"]


def auto_exposure(rgb: np.ndarray, key: float = 0.85, percentile: float = 99.5) -> float:
    """Scale that maps the ``percentile`` of an image's luminance to ``key`` (a camera's auto
    exposure). The same scale is applied to the NIR preview so that RGB and NIR PNGs compare."""
    wr, wg, wb = REC709_LUMA
    lum = rgb[..., 0] * wr + rgb[..., 1] * wg + rgb[..., 2] * wb
    ref = float(np.percentile(lum, percentile)) if lum.size else 0.0
    return key / ref if ref > 1e-12 else 1.0


def nir_response(wavelength: float) -> tuple[list[tuple[float, float]], float]:
    """Trapezoidal band response around ``wavelength`` (nm) and its integral (nm)."""
    a, r = NIR_HALF_PLATEAU_NM, NIR_RAMP_NM
    pts = [
        (wavelength - a - r, 0.0),
        (wavelength - a, 1.0),
        (wavelength + a, 1.0),
        (wavelength + a + r, 0.0),
    ]
    return pts, 2.0 * a + r


def camera_calibration(camera) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """OpenCV intrinsics, camera-to-world pose and (W, H) of a Mitsuba perspective camera.

    The intrinsics are measured from the camera's own rays (so principal-point offsets and the
    fov axis are honoured): the ray through the film centre gives (cx, cy), rays one pixel away
    give (fx, fy).
    """
    import mitsuba as mi

    W, H = (int(v) for v in camera.film().size())
    T_world_cam = transform_matrix(camera.world_transform()) @ np.diag([-1.0, -1.0, 1.0, 1.0])
    R_cw = T_world_cam[:3, :3].T
    # film positions (fractions): centre, +1 px in x, +1 px in y
    fx_pos = np.array([0.5, 0.5 + 1.0 / W, 0.5])
    fy_pos = np.array([0.5, 0.5, 0.5 + 1.0 / H])
    ray, _ = camera.sample_ray(
        0.0, 0.5, mi.Point2f(fx_pos.astype(np.float32), fy_pos.astype(np.float32)), mi.Point2f(0.5)
    )
    d = (
        np.stack([ray.d.x.numpy(), ray.d.y.numpy(), ray.d.z.numpy()], -1).astype(np.float64)
        @ R_cw.T
    )
    xn, yn = d[:, 0] / d[:, 2], d[:, 1] / d[:, 2]
    fx = 1.0 / (xn[1] - xn[0])
    fy = 1.0 / (yn[2] - yn[0])
    # film centre lies at continuous pixel W/2, i.e. OpenCV coordinate W/2 - 0.5
    cx = W / 2.0 - 0.5 - fx * xn[0]
    cy = H / 2.0 - 0.5 - fy * yn[0]
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return K, T_world_cam, (W, H)


def _depth(scene, camera, W: int, H: int, T_world_cam: np.ndarray) -> np.ndarray:
    import drjit as dr
    import mitsuba as mi

    idx = dr.arange(mi.UInt32, W * H)
    px = (mi.Float(idx % W) + 0.5) / W
    py = (mi.Float(idx // W) + 0.5) / H
    ray, _ = camera.sample_ray(0.0, 0.5, mi.Point2f(px, py), mi.Point2f(0.5))
    si = scene.ray_intersect(ray)
    # opaque: a moved camera (a sequence) reuses the kernel
    fwd = dr.opaque(mi.Vector3f, [float(v) for v in T_world_cam[:3, 2]])
    eye = dr.opaque(mi.Point3f, [float(v) for v in T_world_cam[:3, 3]])
    # rays start on the near plane: measure from the eye
    z = dr.dot(ray.o + si.t * ray.d - eye, fwd)
    z = dr.select(si.is_valid(), z, 0.0)
    return z.numpy().astype(np.float32).reshape(H, W)


def _reflectance(scene, camera, W: int, H: int, wavelength: float) -> np.ndarray:
    """(H, W) float32 monostatic ρ(λ)·T² of the surface through each pixel centre."""
    import drjit as dr
    import mitsuba as mi

    from .lidar.raycast import cast, monostatic_reflectance

    idx = dr.arange(mi.UInt32, W * H)
    px = (mi.Float(idx % W) + 0.5) / W
    py = (mi.Float(idx // W) + 0.5) / H
    ray, _ = camera.sample_ray(0.0, 0.5, mi.Point2f(px, py), mi.Point2f(0.5))
    wl = mi.Float(float(wavelength))
    beams = cast(scene, mi.Ray3f(ray.o, dr.normalize(ray.d)), wl)
    rho, _, _ = monostatic_reflectance(beams, wl)
    out = (rho * beams.two_way_transmittance).numpy().astype(np.float32).reshape(H, W)
    return np.where(np.isfinite(out), np.maximum(out, 0.0), 0.0).astype(np.float32)


def _surface_reflectance(scene, camera, W: int, H: int, wavelengths) -> np.ndarray:
    """(H, W, n) float32 diffuse reflectance of the surface through each pixel centre, 0 on the sky.

    The BSDF's ``eval_diffuse_reflectance`` at each of the ``n`` wavelengths (nm): the albedo of
    a diffuse surface, the pigment layer of a plastic, 0 for a smooth metal or glass. Unlike
    :func:`_reflectance` it does not depend on the viewing direction: it is the surface's own
    reflectance. Values clipped to [0, 1]; non-finite ones (a material without data at a
    wavelength) are 0. The surface is the one the LiDAR's return model sees through glass
    (:func:`~nidar_mi.lidar.raycast.cast`).
    """
    import drjit as dr
    import mitsuba as mi

    from .lidar.raycast import cast

    idx = dr.arange(mi.UInt32, W * H)
    px = (mi.Float(idx % W) + 0.5) / W
    py = (mi.Float(idx // W) + 0.5) / H
    ray, _ = camera.sample_ray(0.0, 0.5, mi.Point2f(px, py), mi.Point2f(0.5))
    beams = cast(scene, mi.Ray3f(ray.o, dr.normalize(ray.d)), mi.Float(550.0))
    si, hit = beams.si, beams.hit
    bsdf = si.bsdf(beams.ray)
    dr.eval(si, hit, bsdf)
    # a spectral variant carries 4 wavelengths per lane: 4 at a time, the wavelengths as data
    # (opaque), so one kernel serves every group
    lanes = 4
    wl = np.asarray(wavelengths, np.float64)
    padded = np.concatenate((wl, np.full(-len(wl) % lanes, wl[-1])))
    out = np.zeros((W * H, len(padded)), np.float32)
    for k in range(0, len(padded), lanes):
        group = [dr.opaque(mi.Float, float(x)) for x in padded[k : k + lanes]]
        si.wavelengths = mi.UnpolarizedSpectrum(*group)
        rho = bsdf.eval_diffuse_reflectance(si, hit)
        values = [dr.select(hit, rho[j], 0.0) for j in range(lanes)]
        dr.eval(*values)  # one kernel for the group
        for j, v in enumerate(values):
            v = v.numpy()
            out[:, k + j] = np.where(np.isfinite(v), np.clip(v, 0.0, 1.0), 0.0)
    return out[:, : len(wl)].reshape(H, W, len(wl))


def _albedo(scene, camera, W: int, H: int, wavelength: float) -> tuple[np.ndarray, np.ndarray]:
    """The surfaces' own colour and reflectance at λ (:func:`_surface_reflectance`).

    Returns:
        ((H, W, 3) float32 linear sRGB under D65 of the diffuse reflectance, unclipped
        (:func:`~nidar_mi.materials.visible_albedo.srgb_weights`); (H, W) float32 diffuse
        reflectance at ``wavelength``).
    """
    from .materials.visible_albedo import ALBEDO_WAVELENGTHS_NM, srgb_weights

    rho = _surface_reflectance(scene, camera, W, H, [*ALBEDO_WAVELENGTHS_NM, wavelength])
    rgb = rho[..., :-1].astype(np.float64) @ srgb_weights()
    return rgb.astype(np.float32), rho[..., -1]


#: Twins of cameras (the NIR bands; the RGB image in weather), by variant, lens, film, band,
#: spp and medium (a few at most): a sequence moves its twin with the camera instead of loading
#: a new sensor (and its kernels) every frame.
_TWINS: dict = {}
_TWINS_MAX = 8


def _lens(camera) -> dict:
    """The camera's lens as a ``mi.load_dict`` entry (pose aside)."""
    import mitsuba as mi

    params = mi.traverse(camera)
    if camera.class_name() == "ThinLensCamera":
        lens = {
            "type": "thinlens",
            "aperture_radius": float(params["aperture_radius"][0]),
            "focus_distance": float(params["focus_distance"][0]),
        }
    else:
        lens = {
            "type": "perspective",
            "principal_point_offset_x": float(params["principal_point_offset_x"][0]),
            "principal_point_offset_y": float(params["principal_point_offset_y"][0]),
        }
    return lens | {
        "fov": float(params["x_fov"][0]),
        "fov_axis": "x",
        "near_clip": float(params["near_clip"]),
        "far_clip": float(params["far_clip"]),
    }


def _twin(camera, film: dict, band: float | None, spp: int, medium=None):
    """A twin of the camera with another ``film`` (``band``: what sets it apart in the cache)
    and, in weather, inside ``medium``, at the camera's current pose."""
    import drjit as dr
    import mitsuba as mi

    lens = _lens(camera)
    W, H = (int(v) for v in camera.film().size())
    key = (mi.variant(), tuple(lens.items()), W, H, film["type"], band, int(spp), id(medium))
    twin = _TWINS.get(key)
    if twin is None:
        extra = {} if medium is None else {"medium": medium}
        spec = {"film": film, "sampler": {"type": "independent", "sample_count": spp}}
        twin = (mi.load_dict(lens | spec | extra), medium)  # the medium lives as long as the twin
        if len(_TWINS) >= _TWINS_MAX:
            _TWINS.pop(next(iter(_TWINS)))
        _TWINS[key] = twin
    T = mi.AffineTransform4f(transform_matrix(camera.world_transform()).astype(np.float32))
    dr.make_opaque(T)  # the pose is data: a moved camera reuses the render kernels
    params = mi.traverse(twin[0])
    params["to_world"] = T
    params.update()
    return twin[0]


def _nir_camera(camera, wavelength: float, spp: int, medium=None):
    """The camera's NIR twin (module docstring) at the camera's current pose."""
    W, H = (int(v) for v in camera.film().size())
    pts, _ = nir_response(wavelength)
    film = {"type": "specfilm", "width": W, "height": H, "nir": {"type": "spectrum", "value": pts}}
    return _twin(camera, film, float(wavelength), spp, medium)


#: Peak memory of a render per pixel (RGB and NIR films, depth, the images written), bytes, and
#: per sample (sampler state): Mitsuba traces the image in one fused kernel, so memory grows with
#: the pixels and barely with the samples (measured: docs/BENCHMARKS.md, "Memory").
PIXEL_BYTES = 160
SAMPLE_BYTES = 2


def render_memory(width: int, height: int, spp: int) -> int:
    """Estimated peak memory of one camera render written to disk, bytes."""
    return width * height * (PIXEL_BYTES + SAMPLE_BYTES * spp)


def check_render_memory(camera, spp: int, limit: int | None = None) -> None:
    """Refuse a render whose estimate exceeds ``limit`` (None: the default scan limit).

    Raises:
        NidarError: one line with the estimate, the limit and how to raise it.
    """
    from .errors import NidarError
    from .io.sizes import format_size
    from .lidar.memory import default_limit

    W, H = (int(v) for v in camera.film().size())
    limit = default_limit() if limit is None else int(limit)
    need = render_memory(W, H, spp)
    if need > limit:
        raise NidarError(
            f"camera '{camera.id()}': the render needs about {format_size(need)} ({W} x {H} "
            f"pixels, {spp} spp), more than the limit of {format_size(limit)}; lower the "
            "resolution or raise the limit with `max_memory` (or NIDAR_MAX_MEMORY)"
        )


_warned: set[str] = set()

#: Samples (pixels × spp) traced per pass on the CPU (about 0.3 s on 2 cores for the street
#: scene) and on a GPU.
PASS_SAMPLES_CPU = 2**21
PASS_SAMPLES_GPU = 2**25


def pass_samples() -> int:
    """Samples (pixels × spp) one render pass may trace in the active variant."""
    import mitsuba as mi

    return PASS_SAMPLES_GPU if mi.variant().startswith("cuda") else PASS_SAMPLES_CPU


def render_passes(pixels: int, spp: int, seed: int, budget: int) -> list[tuple[int, int]]:
    """The ``(spp, seed)`` of each pass of a render of ``pixels`` × ``spp`` samples.

    One pass with ``seed`` when the render fits ``budget`` samples; else passes of
    ``max(1, budget // pixels)`` samples per pixel (the last one takes the rest), pass ``i``
    seeded ``(seed + i · 0x9E3779B9) mod 2³²``.
    """
    per = max(1, budget // max(pixels, 1))
    if spp <= per:
        return [(spp, seed)]
    counts = [per] * (spp // per) + ([spp % per] if spp % per else [])
    return [(n, (seed + i * 0x9E3779B9) % 2**32) for i, n in enumerate(counts)]


def _render(scene, sensor, integrator, spp: int, seed: int, what: str) -> np.ndarray:
    """The developed image of ``sensor``, traced in passes (:func:`render_passes`); returning
    to Python between passes lets a pending signal (Ctrl-C, SIGTERM) stop the render."""
    import mitsuba as mi

    W, H = (int(v) for v in sensor.film().size())
    passes = render_passes(W * H, spp, seed, pass_samples())
    total = None  # one pass: its image; several: the spp-weighted sum so far, float64
    try:
        for n, s in passes:
            img = np.array(
                mi.render(scene, sensor=sensor, integrator=integrator, spp=n, seed=s),
                dtype=np.float32,
            )
            if len(passes) == 1:
                return img
            total = img * np.float64(n) if total is None else total + img * np.float64(n)
    except RuntimeError as e:  # Mitsuba's own message, e.g. an invalid film
        stop = _interruption(e)
        if stop is not None:  # Ctrl-C or SIGTERM that arrived inside Dr.Jit's custom operation
            raise stop from None
        first = next((ln.strip() for ln in str(e).splitlines() if ln.strip()), type(e).__name__)
        raise NidarError(f"{what}: Mitsuba could not render it ({first})") from None
    return (total / spp).astype(np.float32)


def _interruption(exc: BaseException | None) -> KeyboardInterrupt | None:
    """The :class:`KeyboardInterrupt` (Ctrl-C, or SIGTERM's ``Terminated``) that ``exc`` wraps.

    A signal handler that raises while Python code of a ``drjit.custom`` operation runs (Mitsuba's
    ``mi.render`` is one) has its exception chained under Dr.Jit's ``RuntimeError``; the render
    must stop as interrupted, not report a failed render. None when the chain holds none.
    """
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def _warn_rgb_emitters(loaded) -> None:
    """Warn once per scene and emitter whose radiance is RGB or a float (nothing past 830 nm)."""
    for name in loaded.rgb_only_emitters():
        key = f"{loaded.path}:{name}"
        if key not in _warned:
            _warned.add(key)
            warnings.warn(
                f"emitter '{name}' has an RGB/float radiance: it carries no meaningful energy "
                "past 830 nm, so the NIR image misses its light (use a spectrum)",
                RuntimeWarning,
                stacklevel=3,
            )


def _zero_non_finite(camera_id: str, images) -> None:
    """Set the non-finite values of ``(name, image)`` pairs to 0 in place, with a warning each."""
    for name, img in images:
        if not np.all(np.isfinite(img)):
            bad = int((~np.isfinite(img)).sum())
            warnings.warn(
                f"camera '{camera_id}': {bad} non-finite {name} values set to 0 "
                "(a material without data at these wavelengths?)",
                RuntimeWarning,
                stacklevel=3,
            )
            img[~np.isfinite(img)] = 0.0


def render_camera(
    loaded,
    camera,
    *,
    wavelength: float,
    spp: int = 16,
    seed: int = 0,
    other_wavelengths=(),
    nir: bool = True,
    albedo: bool = True,
) -> CameraRender:
    """Render RGB, NIR band, depth, reflectance at λ and albedo of one camera of a loaded scene.

    Args:
        loaded: a :class:`nidar_mi.scene.LoadedScene`.
        camera: one of ``loaded.cameras``.
        wavelength: NIR band centre in nm (the LiDAR's).
        spp: samples per pixel of both renders.
        seed: sampler seed, in [0, 2**32).
        other_wavelengths: further NIR band centres in nm (``CameraRender.other_nir``).
        nir: render the NIR bands (False: ``nir`` is all zeros; NIDAR needs only RGB).
        albedo: also give the surfaces' albedo colour and their reflectance at λ (the true maps
            that training frames carry; False: both None).

    In the scene's weather (:attr:`nidar_mi.scene.LoadedScene.weather`, its LiDARs'), the RGB
    and NIR images are rendered through its medium (:mod:`nidar_mi.weather.camera_medium`); depth,
    reflectance and albedo stay the surfaces' own.
    """
    scene = loaded.scene
    _warn_rgb_emitters(loaded)
    timings = {}
    bands = list(dict.fromkeys([float(wavelength), *map(float, other_wavelengths)]))
    request = (bands if nir else [], spp, seed)
    rgb, bands = _radiance(loaded, camera, request, loaded.weather, timings)
    nir = bands.pop(float(wavelength)) if nir else np.zeros(rgb.shape[:2], dtype=np.float32)
    t0 = time.perf_counter()
    K, T_world_cam, (W, H) = camera_calibration(camera)
    depth = _depth(scene, camera, W, H, T_world_cam)
    timings["depth"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    reflectance = _reflectance(scene, camera, W, H, wavelength)
    timings["reflectance"] = time.perf_counter() - t0
    colour = surface = None
    if albedo:
        t0 = time.perf_counter()
        colour, surface = _albedo(scene, camera, W, H, wavelength)
        timings["albedo"] = time.perf_counter() - t0
    images = [("rgb", rgb), ("nir", nir)] + [(f"nir {wl:g} nm", b) for wl, b in bands.items()]
    _zero_non_finite(camera.id(), images)
    return CameraRender(
        name=camera.id(),
        rgb=rgb,
        nir=nir,
        depth=depth,
        K=K,
        T_world_cam=T_world_cam,
        wavelength=float(wavelength),
        timings=timings,
        other_nir=bands,
        reflectance=reflectance,
        albedo=colour,
        surface_reflectance=surface,
    )


def _radiance(loaded, camera, request, weather, timings: dict):
    """The RGB image and the NIR band images (band nm -> (H, W) float32) of one camera; in
    ``weather``, through its medium (the scene's weather twin, the camera's twins in it).

    Args:
        request: ``(bands, spp, seed)``, the bands in nm (none: no NIR image).
    """
    import mitsuba as mi

    bands, spp, seed = request
    scene, medium, rgb_camera = loaded.scene, None, camera
    integrator = scene.integrator() or mi.load_dict(
        {"type": "path", "max_depth": DEFAULT_MAX_DEPTH}
    )
    if weather is not None and not weather.clear:
        scene, medium, integrator = _weather_scene(loaded, weather, bands)
        W, H = (int(v) for v in camera.film().size())
        rgb_camera = _twin(camera, {"type": "hdrfilm", "width": W, "height": H}, None, spp, medium)
    what = f"camera '{camera.id()}'"
    t0 = time.perf_counter()
    rgb = _render(scene, rgb_camera, integrator, spp, seed, what)[..., :3]
    timings["rgb"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    images = {}
    for wl in bands:
        _, integral = nir_response(wl)
        img = _render(scene, _nir_camera(camera, wl, spp, medium), integrator, spp, seed, what)
        images[wl] = (img[..., 0] / integral).astype(np.float32)
    timings["nir"] = time.perf_counter() - t0
    return rgb, images


#: Weather twins of scenes (a few at most), by scene, weather and bands.
_WEATHER_SCENES: dict = {}


def _weather_scene(loaded, weather, bands):
    """The scene's weather twin (:func:`nidar_mi.weather.camera_medium.weather_scene`), cached: a
    sequence renders every frame in the same one."""
    from .weather.camera_medium import weather_scene

    key = (id(loaded.scene), weather, tuple(bands))
    if key not in _WEATHER_SCENES:
        if len(_WEATHER_SCENES) >= 4:
            _WEATHER_SCENES.pop(next(iter(_WEATHER_SCENES)))
        eyes = [transform_matrix(c.world_transform())[:3, 3] for c in loaded.cameras]
        _WEATHER_SCENES[key] = (weather_scene(loaded.scene, weather, bands, eyes), loaded.scene)
    return _WEATHER_SCENES[key][0]
