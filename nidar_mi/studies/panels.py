"""Panel scenes: library-material panels around a LiDAR, scanned through the real ``lidar`` plugin.

See :mod:`nidar_mi.studies` for the experiments built on them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..errors import NidarError
from ..lidar.config import INTENSITY_MODES
from ..materials import get_material

__all__ = [
    "LIDAR_HEIGHT_M",
    "REFERENCE_DISTANCE_M",
    "PanelLayout",
    "PanelScene",
    "PanelScan",
    "panel_layout",
    "panel_scene_xml",
    "load_panel_scene",
    "scan_panels",
]

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
    from ..illumination import sky_radiance, spectrum_string, sun_irradiance

    sun = spectrum_string(*sun_irradiance())
    sky = spectrum_string(*sky_radiance())
    return (
        '<emitter type="directional" id="sun"><vector name="direction" x="0.6" y="0.2" '
        f'z="-0.77"/><spectrum name="irradiance" value="{sun}"/></emitter>\n'
        f'<emitter type="constant" id="sky"><spectrum name="radiance" value="{sky}"/></emitter>'
    )


@dataclass(frozen=True)
class PanelScene:
    """What a panel scene holds besides its materials (:func:`panel_scene_xml`).

    Attributes:
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
    """

    distance_m: float | Sequence[float] = 10.0
    incidence_deg: float | Sequence[float] = 0.0
    wavelength_nm: float = 905.0
    intensity_mode: str = "raw"
    alpha_per_m: float = 0.0
    gain: float = 1.0
    detection_threshold: float = 0.0
    panel_size_m: float = 1.0
    cols: int = 3600
    spread_deg: float = 360.0
    overrides: Mapping[str, float] | None = None
    backdrop: str | None = None
    backdrop_distance_m: float | None = None
    camera_size: tuple[int, int] | None = None
    camera_fov_deg: float = 70.0


def panel_scene_xml(materials: str | Sequence[str], **options) -> str:
    """Mitsuba scene XML of a panel scene (see the module docstring).

    Args:
        materials: one library material for every panel, or one per panel.
        **options: the fields of :class:`PanelScene`.

    Returns:
        Scene XML for :func:`nidar_mi.scene.load_scene` (``nidar_material`` not yet expanded).

    Raises:
        NidarError: bad layout values, an unknown material, or a material count that does not
            match the panels.
    """
    o = PanelScene(**options)
    layout = panel_layout(
        o.distance_m,
        o.incidence_deg,
        panel_size_m=o.panel_size_m,
        cols=o.cols,
        spread_deg=o.spread_deg,
        count=None if isinstance(materials, str) else len(materials),
    )
    if o.intensity_mode not in INTENSITY_MODES:
        raise NidarError(f"intensity_mode must be one of {', '.join(INTENSITY_MODES)}")
    names = _panel_materials(materials, layout.distances_m.size, o.backdrop)
    far = float(layout.distances_m.max())
    r_back = 1.5 * far if o.backdrop_distance_m is None else float(o.backdrop_distance_m)
    if o.backdrop is not None and not r_back > far + o.panel_size_m:
        raise NidarError(f"the backdrop ({r_back:g} m) must lie behind the farthest panel")
    range_max = (r_back if o.backdrop is not None else far) * 1.5 + 1.0
    lines = [
        '<?xml version="1.0" encoding="utf-8"?>',
        '<scene version="3.0.0">',
        '<integrator type="path"><integer name="max_depth" value="4"/></integrator>',
        *_lidar_xml(
            layout.cols,
            wavelength_nm=o.wavelength_nm,
            intensity_mode=o.intensity_mode,
            alpha_per_m=o.alpha_per_m,
            gain=o.gain,
            detection_threshold=o.detection_threshold,
            range_max=range_max,
        ),
    ]
    if o.camera_size is not None:
        lines += [*_camera_xml(o.camera_size, o.camera_fov_deg), _emitters_xml()]
    lines += [_material_xml(name, name, o.overrides) for name in sorted(set(names))]
    lines += _panels_xml(names, layout)
    if o.backdrop is not None:
        lines.append(_backdrop_xml(o.backdrop, r_back))
    lines.append("</scene>")
    return "\n".join(lines) + "\n"


def _panel_materials(materials: str | Sequence[str], n: int, backdrop: str | None) -> list[str]:
    """The material of each of the ``n`` panels; every name (and the backdrop's) must exist."""
    names = [materials] * n if isinstance(materials, str) else [str(m) for m in materials]
    for name in {*names, *([backdrop] if backdrop is not None else [])}:
        get_material(name)  # an unknown name fails here, with suggestions
    return names


def _lidar_xml(
    cols: int,
    *,
    wavelength_nm: float,
    intensity_mode: str,
    alpha_per_m: float,
    gain: float,
    detection_threshold: float,
    range_max: float,
) -> list[str]:
    """The ``lidar`` sensor: one horizontal ring of ``cols`` columns at :data:`LIDAR_HEIGHT_M`."""
    return [
        '<sensor type="lidar" id="lidar">',
        '  <string name="elevation_angles" value="0"/>',
        f'  <integer name="horizontal_resolution" value="{cols}"/>',
        f'  <float name="wavelength" value="{_f(wavelength_nm)}"/>',
        f'  <string name="intensity_mode" value="{intensity_mode}"/>',
        f'  <float name="atmospheric_extinction" value="{_f(alpha_per_m)}"/>',
        f'  <float name="gain" value="{_f(gain)}"/>',
        f'  <float name="detection_threshold" value="{_f(detection_threshold)}"/>',
        '  <float name="range_min" value="0"/>',
        f'  <float name="range_max" value="{_f(range_max)}"/>',
        f'  <transform name="to_world"><translate z="{_f(LIDAR_HEIGHT_M)}"/></transform>',
        "</sensor>",
    ]


def _camera_xml(size: tuple[int, int], fov_deg: float) -> list[str]:
    """A perspective camera at the LiDAR looking along +x; ``size`` is (width, height)."""
    w, h = (int(v) for v in size)
    z = _f(LIDAR_HEIGHT_M)
    return [
        '<sensor type="perspective" id="camera">',
        f'  <float name="fov" value="{_f(fov_deg)}"/>',
        '  <string name="fov_axis" value="x"/>',
        f'  <transform name="to_world"><lookat origin="0, 0, {z}" '
        f'target="1, 0, {z}" up="0, 0, 1"/></transform>',
        '  <sampler type="independent"><integer name="sample_count" value="4"/></sampler>',
        f'  <film type="hdrfilm"><integer name="width" value="{w}"/>'
        f'<integer name="height" value="{h}"/></film>',
        "</sensor>",
    ]


def _panels_xml(names: Sequence[str], layout: PanelLayout) -> list[str]:
    """One rectangle per panel: faces the LiDAR, turned by its incidence angle about z."""
    h, half = LIDAR_HEIGHT_M, 0.5 * layout.panel_size_m
    lines = []
    for i, (name, d, th, az) in enumerate(
        zip(names, layout.distances_m, layout.incidences_deg, layout.azimuths_deg)
    ):
        a = math.radians(az)
        lines.append(
            f'<shape type="rectangle" id="panel_{i:03d}"><transform name="to_world">'
            f'<scale value="{_f(half)}"/><rotate y="1" angle="-90"/>'
            f'<rotate z="1" angle="{_f(th)}"/><rotate z="1" angle="{_f(az)}"/>'
            f'<translate x="{_f(d * math.cos(a))}" y="{_f(d * math.sin(a))}" z="{_f(h)}"/>'
            f'</transform><ref id="{name}"/></shape>'
        )
    return lines


def _backdrop_xml(material: str, radius_m: float) -> str:
    """A two-sided sphere of ``material`` around the LiDAR."""
    return (
        f'<shape type="sphere" id="backdrop"><point name="center" x="0" y="0" '
        f'z="{_f(LIDAR_HEIGHT_M)}"/><float name="radius" value="{_f(radius_m)}"/>'
        f'<bsdf type="twosided" id="backdrop_{material}">'
        f"{_material_xml(None, material, None)}</bsdf></shape>"
    )


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
        variant: the active Mitsuba variant expected (None: whichever is active).
        rgb_twin: load the RGB-only twin (every material replaced by its sRGB appearance).
        **kwargs: the keyword arguments of :func:`panel_scene_xml`.

    Returns:
        (:class:`nidar_mi.scene.LoadedScene`, :class:`PanelLayout`).
    """
    from ..scene import load_scene_text

    layout_keys = ("distance_m", "incidence_deg", "panel_size_m", "cols", "spread_deg")
    count = None if isinstance(materials, str) else len(materials)
    layout = panel_layout(**{k: kwargs[k] for k in layout_keys if k in kwargs}, count=count)
    xml = panel_scene_xml(materials, **kwargs)
    loaded = load_scene_text(xml, "panels.xml", variant=variant, rgb_twin=rgb_twin)
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
    from ..lidar.scan import scan

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
