"""Controlled LiDAR experiments: library-material panels scanned through the real ``lidar`` plugin.

A *panel scene* puts N square panels of library materials (``nidar_material``) around a LiDAR
at height :data:`LIDAR_HEIGHT_M`, every panel centre at that height and on the beam of one column
of a single horizontal ring (elevation 0), so the scan reads each panel at exactly the distance
and incidence angle asked for. A panel faces the LiDAR and is turned about its vertical axis by
its incidence angle. Noise, dropout and ray drop are off; the scene has no ground.

The scene is loaded with :func:`nidar_mi.scene.load_scene` and scanned with
:func:`nidar_mi.lidar.raycast.scan`, so what comes back is what the sensor reports: the return
model ``I = g · ρ(m, λ, θ) · a(d, θ)`` of :mod:`nidar_mi.lidar.return_model` applied to the BSDF
of the material evaluated monostatically at the laser wavelength.

* :func:`incidence_sweep`: intensity against incidence angle at a fixed distance.
* :func:`range_sweep`: intensity against distance (``1/d²`` and ``exp(-2αd)``).
* :func:`detection_range` / :func:`max_detection_range`: the range where ``g·ρ·cosθ·exp(-2αd)/d²``
  falls to a detection threshold (pure bisection, and the same with ρ measured by a scan).
* :func:`extinction_from_visibility`: α at a wavelength from the meteorological visibility
  (Kim, McArthur & Korevaar 2001).
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .errors import NidarError
from .lidar.config import INTENSITY_MODES
from .materials import get_material

__all__ = [
    "LIDAR_HEIGHT_M",
    "REFERENCE_DISTANCE_M",
    "PanelLayout",
    "PanelScan",
    "IncidenceSweep",
    "RangeSweep",
    "panel_layout",
    "panel_scene_xml",
    "load_panel_scene",
    "scan_panels",
    "incidence_sweep",
    "range_sweep",
    "detection_range",
    "max_detection_range",
    "extinction_from_visibility",
]

#: Height of the LiDAR and of every panel centre, m.
LIDAR_HEIGHT_M = 1.0
#: Distance at which :func:`max_detection_range` measures the monostatic reflectance, m.
REFERENCE_DISTANCE_M = 10.0


@dataclass(frozen=True)
class PanelLayout:
    """Where the panels of a panel scene stand. Arrays are (N,).

    Attributes:
        distances_m: distance from the LiDAR to each panel centre, m.
        incidences_deg: incidence angle of the centre beam on each panel, degrees.
        columns: the LiDAR column whose beam hits each panel centre.
        azimuths_deg: azimuth of each panel centre (counter-clockwise from +x), degrees.
        cols: columns of the scan (over 360 degrees).
        panel_size_m: side of each square panel, m.
    """

    distances_m: np.ndarray
    incidences_deg: np.ndarray
    columns: np.ndarray
    azimuths_deg: np.ndarray
    cols: int
    panel_size_m: float


class PanelScan(NamedTuple):
    """What the LiDAR reports at each panel centre. Arrays are (N,), in layout order.

    Attributes:
        layout: the panel layout.
        intensity: reported intensity (``raw``: 1/m²; ``compensated``: unitless); 0 if no return.
        reflectance: ρ = π × monostatic BSDF at λ (0 where nothing was hit).
        cos_incidence: cosine of the incidence angle on the shading normal.
        range_m: reported range, m (0 where no return).
        valid: a return was reported.
        material: the material (BSDF id) hit at each panel centre ('' where nothing was hit).
    """

    layout: PanelLayout
    intensity: np.ndarray
    reflectance: np.ndarray
    cos_incidence: np.ndarray
    range_m: np.ndarray
    valid: np.ndarray
    material: list


class IncidenceSweep(NamedTuple):
    """Result of :func:`incidence_sweep`. Arrays are (N,)."""

    angles_deg: np.ndarray
    intensity: np.ndarray
    reflectance: np.ndarray
    cos_incidence: np.ndarray


class RangeSweep(NamedTuple):
    """Result of :func:`range_sweep`. Arrays are (N,)."""

    distances_m: np.ndarray
    intensity: np.ndarray
    reflectance: np.ndarray
    range_m: np.ndarray
    valid: np.ndarray


def panel_layout(
    distance_m: float | Sequence[float] = 10.0,
    incidence_deg: float | Sequence[float] = 0.0,
    *,
    panel_size_m: float = 1.0,
    cols: int = 3600,
    spread_deg: float = 360.0,
    count: int | None = None,
) -> PanelLayout:
    """Place N panels on distinct LiDAR columns so that no panel shadows another's centre beam.

    ``distance_m`` and ``incidence_deg`` broadcast to N panels. Panel ``i`` stands on column
    ``round(i · cols · spread / 360 / N)`` (shifted so the panels are centred on +x when
    ``spread_deg`` < 360), at the azimuth of that column's beam.

    Args:
        distance_m: distance(s) to the panel centres, m, > ``panel_size_m``.
        incidence_deg: incidence angle(s), degrees, in [0, 90).
        panel_size_m: side of a square panel, m.
        cols: columns of the scan over 360 degrees.
        spread_deg: the azimuth range the panels share, degrees, in (0, 360].
        count: number of panels N when neither ``distance_m`` nor ``incidence_deg`` says it.

    Raises:
        NidarError: bad values, or panels too close in azimuth for their angular size.
    """
    arrays = [
        np.atleast_1d(np.asarray(distance_m, dtype=np.float64)),
        np.atleast_1d(np.asarray(incidence_deg, dtype=np.float64)),
    ]
    if count is not None:
        arrays.append(np.zeros(int(count)))
    try:
        d, th = np.broadcast_arrays(*arrays)[:2]
    except ValueError:
        raise NidarError(
            "distances, incidence angles and materials give different panel counts"
        ) from None
    d, th = d.astype(np.float64).ravel().copy(), th.astype(np.float64).ravel().copy()
    if not (panel_size_m > 0 and math.isfinite(panel_size_m)):
        raise NidarError(f"panel_size_m must be positive, got {panel_size_m}")
    if not 0.0 < spread_deg <= 360.0:
        raise NidarError(f"spread_deg must be in (0, 360], got {spread_deg}")
    if not np.all(np.isfinite(d)) or np.any(d <= panel_size_m):
        raise NidarError(f"every distance must exceed the panel size ({panel_size_m:g} m)")
    if not np.all(np.isfinite(th)) or np.any(th < 0.0) or np.any(th >= 90.0):
        raise NidarError("every incidence angle must be in [0, 90) degrees")
    n = d.size
    if n == 0:
        raise NidarError("a panel scene needs at least one panel")
    if int(cols) < 2 * n:
        raise NidarError(f"{n} panels need at least {2 * n} columns, got {cols}")
    cols = int(cols)
    span = cols * spread_deg / 360.0
    first = 0.0 if spread_deg >= 360.0 else -0.5 * span * (n - 1) / n
    columns = np.round(first + np.arange(n) * span / n).astype(np.int64) % cols
    az = (columns + 0.5) * (360.0 / cols)
    # angular half width of a panel seen from the LiDAR (its corner, conservatively)
    half = np.degrees(np.arctan2(0.5 * math.sqrt(2.0) * panel_size_m, d - 0.5 * panel_size_m))
    if n > 1:
        order = np.argsort(az)
        gaps = np.diff(np.concatenate([az[order], az[order[:1]] + 360.0]))
        need = half[order] + np.roll(half[order], -1)  # panel k and its neighbour k + 1
        pairs = n if spread_deg >= 360.0 else n - 1  # the wrap-around pair only on a full circle
        if np.any(gaps[:pairs] <= need[:pairs]):
            raise NidarError(
                f"{n} panels of {panel_size_m:g} m do not fit in {spread_deg:g} degrees of azimuth "
                "without shadowing each other: use fewer panels, smaller panels or larger distances"
            )
    return PanelLayout(
        distances_m=d,
        incidences_deg=th,
        columns=columns,
        azimuths_deg=az,
        cols=cols,
        panel_size_m=float(panel_size_m),
    )


def _f(v: float) -> str:
    return f"{float(v):.10g}"


def _material_xml(bsdf_id: str | None, name: str, overrides: Mapping[str, float] | None) -> str:
    extra = "".join(
        f'<float name="{k}" value="{_f(v)}"/>' for k, v in sorted((overrides or {}).items())
    )
    id_attr = f' id="{bsdf_id}"' if bsdf_id else ""
    return (
        f'<bsdf type="nidar_material"{id_attr}><string name="name" value="{name}"/>{extra}</bsdf>'
    )


def _emitters_xml() -> str:
    from .illumination import sky_radiance, spectrum_string, sun_irradiance

    sun = spectrum_string(*sun_irradiance())
    sky = spectrum_string(*sky_radiance())
    return (
        '<emitter type="directional" id="sun"><vector name="direction" x="0.6" y="0.2" '
        f'z="-0.77"/><spectrum name="irradiance" value="{sun}"/></emitter>\n'
        f'<emitter type="constant" id="sky"><spectrum name="radiance" value="{sky}"/></emitter>'
    )


def panel_scene_xml(
    materials: str | Sequence[str],
    *,
    distance_m: float | Sequence[float] = 10.0,
    incidence_deg: float | Sequence[float] = 0.0,
    wavelength_nm: float = 905.0,
    intensity_mode: str = "raw",
    alpha_per_m: float = 0.0,
    gain: float = 1.0,
    detection_threshold: float = 0.0,
    panel_size_m: float = 1.0,
    cols: int = 3600,
    spread_deg: float = 360.0,
    overrides: Mapping[str, float] | None = None,
    backdrop: str | None = None,
    backdrop_distance_m: float | None = None,
    camera_size: tuple[int, int] | None = None,
    camera_fov_deg: float = 70.0,
) -> str:
    """Mitsuba scene XML of a panel scene (see the module docstring).

    Args:
        materials: one library material for every panel, or one per panel.
        distance_m: distance(s) to the panel centres, m (broadcast with ``incidence_deg``).
        incidence_deg: incidence angle(s) of the centre beams, degrees.
        wavelength_nm: laser wavelength, nm.
        intensity_mode: ``raw`` (with 1/d²) or ``compensated``.
        alpha_per_m: atmospheric extinction α, 1/m.
        gain: LiDAR gain g.
        detection_threshold: returns with g·ρ·a below it are dropped.
        panel_size_m: side of a square panel, m.
        cols: columns of the single horizontal ring (360 degrees).
        spread_deg: azimuth range shared by the panels (centred on +x when below 360).
        overrides: material overrides (``roughness``, ...) applied to every panel material.
        backdrop: library material of a sphere around the LiDAR behind every panel (two-sided),
            or None for empty space.
        backdrop_distance_m: radius of that sphere, m (default: 1.5 × the farthest panel).
        camera_size: (width, height) of a perspective camera at the LiDAR looking along +x,
            with ASTM G-173 sun and sky, or None for a LiDAR-only scene.
        camera_fov_deg: horizontal field of view of that camera, degrees.

    Returns:
        Scene XML for :func:`nidar_mi.scene.load_scene` (``nidar_material`` not yet expanded).

    Raises:
        NidarError: bad layout values, an unknown material, or a material count that does not
            match the panels.
    """
    layout = panel_layout(
        distance_m,
        incidence_deg,
        panel_size_m=panel_size_m,
        cols=cols,
        spread_deg=spread_deg,
        count=None if isinstance(materials, str) else len(materials),
    )
    if intensity_mode not in INTENSITY_MODES:
        raise NidarError(f"intensity_mode must be one of {', '.join(INTENSITY_MODES)}")
    n = layout.distances_m.size
    names = [materials] * n if isinstance(materials, str) else [str(m) for m in materials]
    for name in {*names, *([backdrop] if backdrop is not None else [])}:
        get_material(name)  # an unknown name fails here, with suggestions
    far = float(layout.distances_m.max())
    r_back = 1.5 * far if backdrop_distance_m is None else float(backdrop_distance_m)
    if backdrop is not None and not r_back > far + panel_size_m:
        raise NidarError(f"the backdrop ({r_back:g} m) must lie behind the farthest panel")
    range_max = (r_back if backdrop is not None else far) * 1.5 + 1.0
    h = LIDAR_HEIGHT_M
    lines = [
        '<?xml version="1.0" encoding="utf-8"?>',
        '<scene version="3.0.0">',
        '<integrator type="path"><integer name="max_depth" value="4"/></integrator>',
        '<sensor type="lidar" id="lidar">',
        '  <string name="elevation_angles" value="0"/>',
        f'  <integer name="horizontal_resolution" value="{layout.cols}"/>',
        f'  <float name="wavelength" value="{_f(wavelength_nm)}"/>',
        f'  <string name="intensity_mode" value="{intensity_mode}"/>',
        f'  <float name="atmospheric_extinction" value="{_f(alpha_per_m)}"/>',
        f'  <float name="gain" value="{_f(gain)}"/>',
        f'  <float name="detection_threshold" value="{_f(detection_threshold)}"/>',
        '  <float name="range_min" value="0"/>',
        f'  <float name="range_max" value="{_f(range_max)}"/>',
        f'  <transform name="to_world"><translate z="{_f(h)}"/></transform>',
        "</sensor>",
    ]
    if camera_size is not None:
        w, hgt = (int(v) for v in camera_size)
        lines += [
            '<sensor type="perspective" id="camera">',
            f'  <float name="fov" value="{_f(camera_fov_deg)}"/>',
            '  <string name="fov_axis" value="x"/>',
            f'  <transform name="to_world"><lookat origin="0, 0, {_f(h)}" '
            f'target="1, 0, {_f(h)}" up="0, 0, 1"/></transform>',
            '  <sampler type="independent"><integer name="sample_count" value="4"/></sampler>',
            f'  <film type="hdrfilm"><integer name="width" value="{w}"/>'
            f'<integer name="height" value="{hgt}"/></film>',
            "</sensor>",
            _emitters_xml(),
        ]
    for name in sorted(set(names)):
        lines.append(_material_xml(name, name, overrides))
    for i, (name, d, th, az) in enumerate(
        zip(names, layout.distances_m, layout.incidences_deg, layout.azimuths_deg)
    ):
        a = math.radians(az)
        lines.append(
            f'<shape type="rectangle" id="panel_{i:03d}"><transform name="to_world">'
            f'<scale value="{_f(0.5 * panel_size_m)}"/><rotate y="1" angle="-90"/>'
            f'<rotate z="1" angle="{_f(th)}"/><rotate z="1" angle="{_f(az)}"/>'
            f'<translate x="{_f(d * math.cos(a))}" y="{_f(d * math.sin(a))}" z="{_f(h)}"/>'
            f'</transform><ref id="{name}"/></shape>'
        )
    if backdrop is not None:
        lines.append(
            f'<shape type="sphere" id="backdrop"><point name="center" x="0" y="0" z="{_f(h)}"/>'
            f'<float name="radius" value="{_f(r_back)}"/><bsdf type="twosided" id="backdrop_{backdrop}">'
            f"{_material_xml(None, backdrop, None)}</bsdf></shape>"
        )
    lines.append("</scene>")
    return "\n".join(lines) + "\n"


def load_panel_scene(
    materials: str | Sequence[str],
    *,
    variant: str | None = None,
    rgb_twin: bool = False,
    **kwargs,
):
    """Build and load a panel scene.

    Args:
        materials: as in :func:`panel_scene_xml`.
        variant: Mitsuba variant (None: the default of :func:`nidar_mi.backend.set_variant`).
        rgb_twin: load the RGB-only twin (every material replaced by its sRGB appearance).
        **kwargs: the keyword arguments of :func:`panel_scene_xml`.

    Returns:
        (:class:`nidar_mi.scene.LoadedScene`, :class:`PanelLayout`).
    """
    from .scene import load_scene

    layout_keys = ("distance_m", "incidence_deg", "panel_size_m", "cols", "spread_deg")
    count = None if isinstance(materials, str) else len(materials)
    layout = panel_layout(**{k: kwargs[k] for k in layout_keys if k in kwargs}, count=count)
    xml = panel_scene_xml(materials, **kwargs)
    with tempfile.TemporaryDirectory(prefix="nidar_panels_") as tmp:
        path = os.path.join(tmp, "panels.xml")
        with open(path, "w", encoding="utf-8") as f:
            f.write(xml)
        loaded = load_scene(path, variant=variant, rgb_twin=rgb_twin)
    return loaded, layout


def scan_panels(
    materials: str | Sequence[str],
    *,
    variant: str | None = None,
    rgb_twin: bool = False,
    **kwargs,
) -> PanelScan:
    """Scan a panel scene and read the return at every panel centre.

    Args:
        materials: as in :func:`panel_scene_xml`.
        variant: Mitsuba variant.
        rgb_twin: scan the RGB-only twin instead.
        **kwargs: the keyword arguments of :func:`panel_scene_xml`.

    Returns:
        The returns at the panel centres, in layout order.
    """
    from .lidar.raycast import scan

    loaded, layout = load_panel_scene(materials, variant=variant, rgb_twin=rgb_twin, **kwargs)
    result = scan(loaded.scene, loaded.lidars[0], seed=0)
    c = layout.columns
    mat = result.material[0, c]
    return PanelScan(
        layout=layout,
        intensity=result.intensity[0, c].astype(np.float64),
        reflectance=result.reflectance[0, c].astype(np.float64),
        cos_incidence=result.cos_incidence[0, c].astype(np.float64),
        range_m=result.range[0, c].astype(np.float64),
        valid=result.valid[0, c].copy(),
        material=[result.material_names[m] if m >= 0 else "" for m in mat],
    )


def incidence_sweep(
    material: str,
    angles_deg: Sequence[float],
    wavelength_nm: float = 905.0,
    *,
    distance_m: float = 10.0,
    intensity_mode: str = "compensated",
    variant: str | None = None,
    **kwargs,
) -> IncidenceSweep:
    """Intensity of one material against incidence angle, through the LiDAR.

    Every angle is one panel of the same scene at ``distance_m``; one scan reads them all.

    Args:
        material: library material name.
        angles_deg: (N,) incidence angles, degrees, in [0, 90).
        wavelength_nm: laser wavelength, nm.
        distance_m: panel distance, m.
        intensity_mode: ``compensated`` (default: I = g·ρ(θ)·cosθ) or ``raw`` (÷ d²).
        variant: Mitsuba variant.
        **kwargs: further keyword arguments of :func:`panel_scene_xml` (``gain``,
            ``overrides``, ``panel_size_m``, ...).

    Returns:
        (angles_deg, intensity, reflectance ρ(θ), cos_incidence), each (N,).
    """
    s = scan_panels(
        material,
        distance_m=distance_m,
        incidence_deg=np.asarray(angles_deg, dtype=np.float64),
        wavelength_nm=wavelength_nm,
        intensity_mode=intensity_mode,
        variant=variant,
        **kwargs,
    )
    return IncidenceSweep(s.layout.incidences_deg, s.intensity, s.reflectance, s.cos_incidence)


def range_sweep(
    material: str,
    distances_m: Sequence[float],
    alpha_per_m: float = 0.0,
    wavelength_nm: float = 905.0,
    *,
    incidence_deg: float = 0.0,
    variant: str | None = None,
    **kwargs,
) -> RangeSweep:
    """Raw intensity of one material against distance, through the LiDAR.

    Args:
        material: library material name.
        distances_m: (N,) panel distances, m.
        alpha_per_m: atmospheric extinction α, 1/m.
        wavelength_nm: laser wavelength, nm.
        incidence_deg: incidence angle on every panel, degrees.
        variant: Mitsuba variant.
        **kwargs: further keyword arguments of :func:`panel_scene_xml` (``gain``,
            ``detection_threshold``, ...).

    Returns:
        (distances_m, intensity in 1/m², reflectance, range_m, valid), each (N,).
    """
    s = scan_panels(
        material,
        distance_m=np.asarray(distances_m, dtype=np.float64),
        incidence_deg=incidence_deg,
        alpha_per_m=alpha_per_m,
        wavelength_nm=wavelength_nm,
        intensity_mode="raw",
        variant=variant,
        **kwargs,
    )
    return RangeSweep(s.layout.distances_m, s.intensity, s.reflectance, s.range_m, s.valid)


def detection_range(
    rho: float,
    threshold: float,
    *,
    gain: float = 1.0,
    alpha_per_m: float = 0.0,
    cos_incidence: float = 1.0,
    d_max_m: float = 1.0e6,
    rtol: float = 1.0e-12,
) -> float:
    """Largest range at which a return is still detected: ``g·ρ·cosθ·exp(-2αd)/d² = threshold``.

    The left side falls strictly with ``d``, so the root is unique; it is found by bisection on
    ``log`` of both sides. With ``α = 0`` it is ``sqrt(g·ρ·cosθ / threshold)``.

    Args:
        rho: monostatic reflectance ρ (π × BSDF) at the laser wavelength, > 0.
        threshold: detection threshold on ``g·ρ·a`` (raw units, 1/m²), > 0.
        gain: LiDAR gain g.
        alpha_per_m: atmospheric extinction α, 1/m, >= 0.
        cos_incidence: cosine of the incidence angle, in (0, 1].
        d_max_m: upper end of the search, m.
        rtol: relative tolerance on the range.

    Returns:
        The range in m (``d_max_m`` if the return is still above threshold there).
    """
    if not (rho > 0 and threshold > 0 and gain > 0 and 0 < cos_incidence <= 1):
        raise NidarError("detection_range needs rho, threshold, gain > 0 and cos in (0, 1]")
    if alpha_per_m < 0:
        raise NidarError(f"alpha_per_m must be >= 0, got {alpha_per_m}")
    log_k = math.log(gain * rho * cos_incidence / threshold)

    def excess(d: float) -> float:  # log(signal / threshold), strictly decreasing in d
        return log_k - 2.0 * alpha_per_m * d - 2.0 * math.log(d)

    if excess(d_max_m) >= 0.0:
        return float(d_max_m)
    lo, hi = 1.0e-9, float(d_max_m)
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        if excess(mid) >= 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def max_detection_range(
    material: str,
    threshold: float,
    *,
    wavelength_nm: float = 905.0,
    alpha_per_m: float = 0.0,
    gain: float = 1.0,
    incidence_deg: float = 0.0,
    variant: str | None = None,
    overrides: Mapping[str, float] | None = None,
) -> float:
    """Maximum detection range of a library material, with ρ·cosθ measured through the LiDAR.

    One ``compensated`` scan of a panel at :data:`REFERENCE_DISTANCE_M` without extinction
    gives ``g·ρ(θ)·cosθ``; :func:`detection_range` then solves the return model for the range.

    Args:
        material: library material name.
        threshold: detection threshold (raw units, 1/m²).
        wavelength_nm: laser wavelength, nm.
        alpha_per_m: atmospheric extinction α, 1/m.
        gain: LiDAR gain g.
        incidence_deg: incidence angle, degrees.
        variant: Mitsuba variant.
        overrides: material overrides.

    Returns:
        Range in m; 0 if the material returns nothing at this wavelength and angle.
    """
    s = scan_panels(
        material,
        distance_m=REFERENCE_DISTANCE_M,
        incidence_deg=incidence_deg,
        wavelength_nm=wavelength_nm,
        intensity_mode="compensated",
        overrides=overrides,
        variant=variant,
    )
    g_rho_cos = float(s.intensity[0])
    if not (s.valid[0] and g_rho_cos > 0.0):
        return 0.0
    return detection_range(g_rho_cos, threshold, gain=gain, alpha_per_m=alpha_per_m)


def extinction_from_visibility(visibility_km: float, wavelength_nm: float) -> float:
    """Atmospheric extinction α (1/m) from the meteorological visibility (Kim model).

    ``α = 3.91 / V · (λ / 550 nm)^(-q)`` (1/km), with ``q`` = 1.6 (V > 50 km), 1.3
    (6 < V <= 50), 0.16 V + 0.34 (1 < V <= 6), V − 0.5 (0.5 < V <= 1), 0 (V <= 0.5):
    I. I. Kim, B. McArthur, E. Korevaar, "Comparison of laser beam propagation at 785 nm and
    1550 nm in fog and haze for optical wireless communications", Proc. SPIE 4214 (2001).
    The 3.91 is Koschmieder's ``-ln(0.02)`` for a 2 % contrast threshold.

    Args:
        visibility_km: meteorological visibility V, km, > 0.
        wavelength_nm: wavelength λ, nm, > 0.

    Returns:
        α in 1/m (the one-way extinction coefficient of the return model).
    """
    v = float(visibility_km)
    if not (v > 0 and wavelength_nm > 0):
        raise NidarError("visibility_km and wavelength_nm must be positive")
    if v > 50.0:
        q = 1.6
    elif v > 6.0:
        q = 1.3
    elif v > 1.0:
        q = 0.16 * v + 0.34
    elif v > 0.5:
        q = v - 0.5
    else:
        q = 0.0
    return 3.91 / v * (wavelength_nm / 550.0) ** (-q) / 1000.0
