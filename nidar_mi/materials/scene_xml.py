"""The scene-XML loader pass: ``<bsdf type="nidar_material">`` -> Mitsuba XML, and RGB-only twins.

A scene names library materials as::

    <bsdf type="nidar_material" id="road">
        <string name="name" value="asphalt_old"/>
        <float name="roughness" value="0.3"/>      <!-- optional overrides, see mitsuba_dict -->
        <spectrum name="reflectance" value="360:0.1, ..., 1700:0.4"/>  <!-- optional -->
    </bsdf>

The optional ``reflectance`` spectrum (wavelength:value pairs in nm covering 360-1700 nm, values
in [0, 1]) replaces the material's own, keeping its kind and other parameters
(:func:`nidar_mi.materials.bsdf_dict`); the generated scenes of ``scenegen --spectra earthlib``
use it.

:func:`expand_scene_xml` replaces each such element (at any depth, e.g. inside ``twosided``)
by the BSDF of :func:`nidar_mi.materials.bsdf_dict`, keeping its ``id`` and any other attribute.
The scene loader calls it before ``mi.load_string``.

With ``rgb_twin=True`` the whole scene becomes its RGB-only twin: library materials get their
RGB twin BSDF, and in every other ``<bsdf>`` each literal spectrum child named like a
reflectance (``reflectance``, ``diffuse_reflectance``, ``specular_reflectance``,
``specular_transmittance``) with a ``value="wl:v, ..."`` list becomes an ``<rgb>`` of its linear
sRGB appearance. Uniform spectra (``value="0.5"``) are already grey in both, spectra from files,
conductor presets and ``eta``/``k`` are left as they are (name metals through ``nidar_material``
to twin them). Emitters, sensors and media are never touched.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from ..errors import NidarError
from .mitsuba_dict import bsdf_dict
from .spectra import Spectrum
from .srgb import spectrum_to_linear_srgb

__all__ = ["NIDAR_MATERIAL_TYPE", "TWIN_SPECTRUM_NAMES", "expand_scene_xml", "dict_to_element"]

NIDAR_MATERIAL_TYPE = "nidar_material"
#: Names of BSDF spectrum parameters converted to RGB in an RGB-only twin.
TWIN_SPECTRUM_NAMES = frozenset(
    {"reflectance", "diffuse_reflectance", "specular_reflectance", "specular_transmittance"}
)
_TEXTURE_TAGS = {"rgb": "rgb", "irregular": "spectrum"}


def _fmt(v: float) -> str:
    return f"{float(v):.9g}"


def dict_to_element(d: dict, tag: str = "bsdf", name: str | None = None) -> ET.Element:
    """Mitsuba XML element of a plugin dict as :func:`bsdf_dict` builds it.

    Handles float, bool, str values and ``irregular`` / ``rgb`` nested dicts.
    """
    attrs = {"type": d["type"]}
    if name is not None:
        attrs = {"type": d["type"], "name": name}
    el = ET.Element(tag, attrs)
    for key, value in d.items():
        if key == "type":
            continue
        if isinstance(value, bool):
            ET.SubElement(el, "boolean", {"name": key, "value": str(value).lower()})
        elif isinstance(value, (int, float)):
            ET.SubElement(el, "float", {"name": key, "value": _fmt(value)})
        elif isinstance(value, str):
            ET.SubElement(el, "string", {"name": key, "value": value})
        elif isinstance(value, dict) and value.get("type") == "irregular":
            wl = value["wavelengths"].split(",")
            vals = value["values"].split(",")
            pairs = ", ".join(f"{a.strip()}:{b.strip()}" for a, b in zip(wl, vals))
            ET.SubElement(el, "spectrum", {"name": key, "value": pairs})
        elif isinstance(value, dict) and value.get("type") == "rgb":
            ET.SubElement(
                el, "rgb", {"name": key, "value": ", ".join(_fmt(c) for c in value["value"])}
            )
        else:
            raise TypeError(f"cannot write parameter '{key}' = {value!r} as XML")
    return el


def _material_element(el: ET.Element, rgb_twin: bool) -> ET.Element:
    """The expanded BSDF element for one ``nidar_material`` element."""
    name = None
    overrides: dict[str, float] = {}
    reflectance = None
    for child in el:
        if not isinstance(child.tag, str):  # comment
            continue
        key, value = child.get("name"), child.get("value")
        if child.tag == "string" and key == "name":
            name = value
        elif child.tag in ("float", "integer") and key is not None and value is not None:
            if value.startswith("$"):
                raise NidarError(f"nidar_material parameter '{key}' must be a literal, got {value}")
            overrides[key] = float(value)
        elif child.tag == "spectrum" and key == "reflectance" and value is not None:
            try:
                reflectance = Spectrum.parse_xml_value(value)
            except ValueError as e:
                raise NidarError(f"nidar_material{_where(el)}: bad reflectance: {e}") from None
        else:
            raise NidarError(
                f"nidar_material: unexpected <{child.tag} name={key!r}>; it takes "
                '<string name="name">, numeric overrides and <spectrum name="reflectance">'
            )
    if not name:
        raise NidarError(f'nidar_material{_where(el)} lacks <string name="name" value="..."/>')
    if name.startswith("$"):
        raise NidarError(f"nidar_material name must be a literal material name, got {name}")
    new = dict_to_element(
        bsdf_dict(name, rgb_twin=rgb_twin, overrides=overrides, reflectance=reflectance)
    )
    for attr, value in el.attrib.items():
        if attr != "type":
            new.set(attr, value)
    new.tail = el.tail
    new.text = el.text
    return new


def _where(el: ET.Element) -> str:
    return f" (id '{el.get('id')}')" if el.get("id") else ""


def _twin_spectra(bsdf: ET.Element) -> None:
    """Replace literal reflectance spectra of a non-library BSDF element by RGB, in place."""
    for i, child in enumerate(list(bsdf)):
        if child.tag != "spectrum" or child.get("name") not in TWIN_SPECTRUM_NAMES:
            continue
        value = child.get("value")
        if value is None or ":" not in value:
            continue  # uniform value or spectrum file: left as is (see module docstring)
        try:
            spectrum = Spectrum.parse_xml_value(value)
        except ValueError as e:
            raise NidarError(f"bad spectrum '{child.get('name')}'{_where(bsdf)}: {e}") from None
        rgb = spectrum_to_linear_srgb(spectrum)
        new = ET.Element(
            "rgb", {"name": child.get("name"), "value": ", ".join(_fmt(c) for c in rgb)}
        )
        new.tail = child.tail
        bsdf[i] = new


def expand_scene_xml(xml_text: str, *, rgb_twin: bool = False) -> str:
    """Expand ``nidar_material`` BSDFs of a Mitsuba scene XML (and make an RGB twin if asked).

    Args:
        xml_text: Mitsuba scene XML.
        rgb_twin: also turn the scene into its RGB-only twin (see the module docstring).

    Returns:
        The scene XML, ready for ``mi.load_string``.

    Raises:
        NidarError: malformed XML, unknown material, bad override.
    """
    try:
        parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
        root = ET.fromstring(xml_text, parser=parser)
    except ET.ParseError as e:
        raise NidarError(f"scene XML does not parse: {e}") from None

    def visit(parent: ET.Element) -> None:
        for i, child in enumerate(list(parent)):
            if child.tag == "bsdf" and child.get("type") == NIDAR_MATERIAL_TYPE:
                parent[i] = _material_element(child, rgb_twin)
                continue
            if child.tag == "bsdf" and rgb_twin:
                _twin_spectra(child)
            if child.tag in ("emitter", "sensor", "medium"):
                continue
            visit(child)

    if root.tag == "bsdf" and root.get("type") == NIDAR_MATERIAL_TYPE:
        root = _material_element(root, rgb_twin)
    else:
        if root.tag == "bsdf" and rgb_twin:
            _twin_spectra(root)
        visit(root)
    return ET.tostring(root, encoding="unicode")
