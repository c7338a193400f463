"""Mitsuba scene XML of a generated :class:`~.primitives.Layout`.

The text is a pure function of the layout (fixed number formatting, shapes in layout order), so
the same layout always gives byte-identical XML. Materials are ``nidar_material`` BSDFs named
``mat_<library name>``; the sun is a ``directional`` emitter with the ASTM G-173 direct spectrum
(:func:`nidar_mi.illumination.sun_irradiance`), the sky a ``constant`` emitter with the diffuse
spectrum (:func:`nidar_mi.illumination.sky_radiance`), both scaled by the layout's factors.

Every shape carries its semantic ``label`` and, for multi-part objects, an ``instance``
(:func:`nidar_mi.scenegen.labels.shape_label`; the declaration is read by
:func:`nidar_mi.labels.strip_labels`).

Like ``scenes/street.xml`` the scene declares ``<default>`` parameters ``spp``, ``width``,
``height`` (camera film) and ``cols`` (LiDAR columns per scan), so ``render -D`` can shrink it.
"""

from __future__ import annotations

from ..illumination import sky_radiance, spectrum_string, sun_irradiance
from .labels import shape_label
from .primitives import Block, Cylinder, Layout, Panel, Patch, Rig, Sphere

__all__ = ["scene_xml", "DEFAULT_COLS", "SPECTRUM_STEP_NM"]

#: Columns per scan by preset (the sensors' usual 10 Hz resolution).
DEFAULT_COLS = {"hdl64e": 2048, "vlp16": 1800}
#: Bin width of the sun and sky spectra, nm (as in scenes/street.xml).
SPECTRUM_STEP_NM = 20.0


def _f(v: float) -> str:
    return format(float(v) + 0.0, ".10g")


def _xyz(name: str, v) -> str:
    return f'<{name} x="{_f(v[0])}" y="{_f(v[1])}" z="{_f(v[2])}"/>'


def _point(name: str, v) -> str:
    return f'<point name="{name}" x="{_f(v[0])}" y="{_f(v[1])}" z="{_f(v[2])}"/>'


def _transform(*ops: str) -> str:
    return '<transform name="to_world">' + "".join(ops) + "</transform>"


def _shape(s) -> str:
    ref = f'<ref id="mat_{s.material}"/>'
    if isinstance(s, Patch):
        body = _transform(
            f'<scale x="{_f(s.half_size[0])}" y="{_f(s.half_size[1])}"/>',
            f'<rotate z="1" angle="{_f(s.yaw_deg)}"/>' if s.yaw_deg else "",
            _xyz("translate", s.center),
        )
        kind = "rectangle"
    elif isinstance(s, Panel):
        # rectangle normal +z -> +x (rotate about y by 90), then to the heading; the scaled x
        # half extent becomes the vertical one.
        body = _transform(
            f'<scale x="{_f(s.half_size[1])}" y="{_f(s.half_size[0])}"/>',
            '<rotate y="1" angle="90"/>',
            f'<rotate z="1" angle="{_f(s.heading_deg)}"/>',
            _xyz("translate", s.center),
        )
        kind = "rectangle"
    elif isinstance(s, Block):
        body = _transform(
            _xyz("scale", s.half_size),
            f'<rotate z="1" angle="{_f(s.yaw_deg)}"/>' if s.yaw_deg else "",
            _xyz("translate", s.center),
        )
        kind = "cube"
    elif isinstance(s, Cylinder):
        body = (
            f'<float name="radius" value="{_f(s.radius)}"/>{_point("p0", s.p0)}{_point("p1", s.p1)}'
        )
        kind = "cylinder"
    elif isinstance(s, Sphere):
        body = f'{_point("center", s.center)}<float name="radius" value="{_f(s.radius)}"/>'
        kind = "sphere"
    else:  # pragma: no cover
        raise TypeError(f"unknown shape record {type(s).__name__}")
    tags = ""
    if (label := shape_label(s)) is not None:
        cls, instance = label
        tags = f' label="{cls}"' + (f' instance="{instance}"' if instance else "")
    return f'    <shape type="{kind}" id="{s.id}"{tags}>{body}{ref}</shape>'


def _threshold(preset: str) -> list[str]:
    """The detection threshold line: none where the preset has a calibrated default
    (:mod:`nidar_mi.lidar.link_budget`), else 5e-5."""
    from ..lidar.pattern import PRESETS

    if PRESETS[preset].detection_threshold > 0:
        return []
    return ['        <float name="detection_threshold" value="0.00005"/>']


def _rig(rig: Rig) -> list[str]:
    d = rig.camera_direction
    o = rig.camera_position
    target = tuple(o[i] + 10.0 * d[i] for i in range(3))
    lidar_ops = f'<rotate z="1" angle="{_f(rig.lidar_yaw_deg)}"/>' + _xyz(
        "translate", rig.lidar_position
    )
    return [
        '    <sensor type="lidar" id="lidar_top">',
        f'        <string name="preset" value="{rig.lidar_preset}"/>',
        '        <integer name="horizontal_resolution" value="$cols"/>',
        '        <float name="wavelength" value="905"/>',
        '        <float name="range_max" value="120"/>',
        '        <string name="intensity_mode" value="raw"/>',
        '        <float name="noise_intensity_std" value="0.0002"/>',
        '        <float name="noise_range_std" value="0.01"/>',
        *_threshold(rig.lidar_preset),
        '        <float name="dropout" value="0.01"/>',
        '        <integer name="seed" value="0"/>',
        f'        <transform name="to_world">{lidar_ops}</transform>',
        "    </sensor>",
        '    <sensor type="perspective" id="cam_front">',
        f'        <float name="fov" value="{_f(rig.camera_fov_deg)}"/>',
        '        <string name="fov_axis" value="x"/>',
        '        <transform name="to_world">',
        f'            <lookat origin="{", ".join(_f(v) for v in o)}" '
        f'target="{", ".join(_f(round(v, 6)) for v in target)}" up="0, 0, 1"/>',
        "        </transform>",
        '        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>',
        '        <film type="hdrfilm">',
        '            <integer name="width" value="$width"/>',
        '            <integer name="height" value="$height"/>',
        "        </film>",
        "    </sensor>",
    ]


def _light(layout: Layout) -> list[str]:
    d = layout.sun.direction
    sun = spectrum_string(*sun_irradiance(step=SPECTRUM_STEP_NM, scale=layout.sun.scale))
    sky = spectrum_string(*sky_radiance(step=SPECTRUM_STEP_NM, scale=layout.sky.scale))
    return [
        '    <emitter type="directional" id="sun">',
        f'        <vector name="direction" x="{_f(round(d[0], 6))}" y="{_f(round(d[1], 6))}" '
        f'z="{_f(round(d[2], 6))}"/>',
        f'        <spectrum name="irradiance" value="{sun}"/>',
        "    </emitter>",
        '    <emitter type="constant" id="sky">',
        f'        <spectrum name="radiance" value="{sky}"/>',
        "    </emitter>",
    ]


def scene_xml(
    layout: Layout, *, name: str = "scene", description: str = "", spectra: dict | None = None
) -> str:
    """The scene file of ``layout``.

    Args:
        layout: the layout to write.
        name: scene name for the header comment.
        description: extra header line (e.g. the seeds it was drawn from).
        spectra: material name -> :class:`~nidar_mi.scenegen.spectral_regimes.SurfaceSpectrum` for the
            materials that take another spectrum (:func:`~nidar_mi.scenegen.spectral_regimes.draw_spectra`),
            written as the ``reflectance`` of their ``nidar_material`` with its source.

    Returns:
        The XML text (UTF-8, ``\\n`` line ends, trailing newline).
    """
    rig, sun = layout.rig, layout.sun
    header = [
        '<?xml version="1.0" encoding="utf-8"?>',
        "<!--",
        f"  {name}: a generated {layout.kind} scene (nidar_mi.scenegen, docs/SCENES.md).",
    ]
    if description:
        header.append(f"  {description}")
    header += [
        f"  Rig: {rig.lidar_preset} LiDAR at {rig.lidar_position} m, yaw {rig.lidar_yaw_deg} deg;"
        f" camera at {rig.camera_position} m, yaw {rig.camera_yaw_deg} deg,"
        f" pitch {rig.camera_pitch_deg} deg, horizontal fov {rig.camera_fov_deg} deg.",
        f"  Sun: elevation {sun.elevation_deg} deg, azimuth {sun.azimuth_deg} deg,"
        f" ASTM G-173 direct x {sun.scale}; sky: ASTM G-173 diffuse x {layout.sky.scale}.",
        "-->",
    ]
    lines = header + [
        '<scene version="3.0.0">',
        '    <default name="spp" value="16"/>',
        '    <default name="width" value="480"/>',
        '    <default name="height" value="270"/>',
        f'    <default name="cols" value="{DEFAULT_COLS[rig.lidar_preset]}"/>',
        "",
        '    <integrator type="path"><integer name="max_depth" value="5"/></integrator>',
        "",
        *_rig(rig),
        "",
        *_light(layout),
        "",
    ]
    spectra = spectra or {}
    for m in layout.materials():
        head = f'    <bsdf type="nidar_material" id="mat_{m}"><string name="name" value="{m}"/>'
        if m not in spectra:
            lines.append(head + "</bsdf>")
            continue
        source, spectrum = spectra[m]
        lines += [
            f"    <!-- mat_{m}: the spectrum of {source} -->",
            head,
            f'        <spectrum name="reflectance" value="{spectrum.xml_value()}"/></bsdf>',
        ]
    lines.append("")
    lines += [_shape(s) for s in layout.shapes]
    lines.append("</scene>")
    return "\n".join(lines) + "\n"
