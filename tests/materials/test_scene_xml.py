"""Tests of the scene-XML loader pass and RGB-only twins."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.materials import expand_scene_xml, linear_rgb, reflectance
from nidar_mi.materials.spectra import Spectrum
from nidar_mi.materials.srgb import spectrum_to_linear_srgb

SCENE = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="16"/></sampler>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
  </sensor>
  <emitter type="constant"><spectrum name="radiance" value="400:1.0, 700:1.0"/></emitter>
  <!-- library material referenced by id -->
  <bsdf type="nidar_material" id="road"><string name="name" value="asphalt_old"/></bsdf>
  <shape type="rectangle" id="ground"><ref id="road"/></shape>
  <shape type="sphere" id="car">
    <float name="radius" value="0.6"/>
    <bsdf type="twosided">
      <bsdf type="nidar_material"><string name="name" value="car_paint_red"/>
        <float name="roughness" value="0.3"/></bsdf>
    </bsdf>
  </shape>
  <shape type="sphere" id="ball">
    <point name="center" x="1.2" y="1.2" z="0"/><float name="radius" value="0.3"/>
    <bsdf type="diffuse"><spectrum name="reflectance" value="400:0.1, 550:0.5, 700:0.2"/></bsdf>
  </shape>
  <shape type="sphere" id="flat">
    <point name="center" x="-1.2" y="1.2" z="0"/><float name="radius" value="0.3"/>
    <bsdf type="diffuse"><spectrum name="reflectance" value="0.4"/></bsdf>
  </shape>
</scene>"""


def _bsdfs(xml: str) -> list[ET.Element]:
    return list(ET.fromstring(xml).iter("bsdf"))


def test_expansion_keeps_ids_and_nesting():
    out = expand_scene_xml(SCENE)
    assert "nidar_material" not in out
    root = ET.fromstring(out)
    road = root.find("bsdf[@id='road']")
    assert road is not None and road.get("type") == "roughdiffuse"
    assert road.find("float[@name='sigma']").get("value") == "35.1"
    spec = road.find("spectrum[@name='reflectance']")
    s = Spectrum.parse_xml_value(spec.get("value"))
    assert s.wavelengths_nm[0] == 360.0 and s.wavelengths_nm[-1] == 1700.0
    np.testing.assert_allclose(s(905.0), reflectance("asphalt_old", 905.0), rtol=1e-5)
    inner = root.find("shape[@id='car']/bsdf[@type='twosided']/bsdf")
    assert inner.get("type") == "roughplastic"
    assert inner.find("float[@name='alpha']").get("value") == "0.3"
    # literal spectra elsewhere are untouched without rgb_twin
    assert root.find("shape[@id='ball']/bsdf/spectrum").get("value") == "400:0.1, 550:0.5, 700:0.2"


def test_rgb_twin_converts_every_reflectance_but_not_emitters():
    out = expand_scene_xml(SCENE, rgb_twin=True)
    root = ET.fromstring(out)
    road = root.find("bsdf[@id='road']/rgb[@name='reflectance']")
    np.testing.assert_allclose(
        [float(v) for v in road.get("value").split(",")], linear_rgb("asphalt_old"), rtol=1e-6
    )
    ball = root.find("shape[@id='ball']/bsdf/rgb[@name='reflectance']")
    want = spectrum_to_linear_srgb(Spectrum([400.0, 550.0, 700.0], [0.1, 0.5, 0.2]))
    np.testing.assert_allclose([float(v) for v in ball.get("value").split(",")], want, rtol=1e-6)
    # a uniform spectrum is the same grey in both renderings and is kept
    assert root.find("shape[@id='flat']/bsdf/spectrum").get("value") == "0.4"
    # emitters keep their spectra
    assert root.find("emitter/spectrum").get("value") == "400:1.0, 700:1.0"
    assert not any(b.find("spectrum[@name='diffuse_reflectance']") is not None for b in _bsdfs(out))


@pytest.mark.parametrize(
    "body, match",
    [
        ('<bsdf type="nidar_material"/>', "lacks"),
        (
            '<bsdf type="nidar_material"><string name="name" value="unobtainium"/></bsdf>',
            "unknown material",
        ),
        ('<bsdf type="nidar_material"><string name="name" value="$mat"/></bsdf>', "literal"),
        (
            '<bsdf type="nidar_material"><string name="name" value="grass"/>'
            '<rgb name="reflectance" value="0.5"/></bsdf>',
            "unexpected",
        ),
        (
            '<bsdf type="nidar_material"><string name="name" value="grass"/>'
            '<float name="roughness" value="0.2"/></bsdf>',
            "cannot be set",
        ),
        ("<bsdf type=", "does not parse"),
    ],
)
def test_bad_material_elements_are_user_errors(body, match):
    with pytest.raises(NidarError, match=match):
        expand_scene_xml(f'<scene version="3.0.0">{body}</scene>')


def test_a_lone_material_element_expands():
    out = expand_scene_xml(
        '<bsdf type="nidar_material" id="x"><string name="name" value="iron"/></bsdf>'
    )
    el = ET.fromstring(out)
    assert el.get("type") == "roughconductor" and el.get("id") == "x"


def test_rgb_twin_scene_loads_and_renders_like_the_spectral_one(variant):
    import mitsuba as mi

    images = []
    for twin in (False, True):
        scene = mi.load_string(expand_scene_xml(SCENE, rgb_twin=twin))
        images.append(np.array(mi.render(scene, seed=1)))
    spectral, rgb = images
    assert spectral.shape == rgb.shape == (16, 16, 3)
    assert np.all(np.isfinite(spectral)) and np.all(np.isfinite(rgb))
    assert spectral.mean() > 0.05
    # in the visible, the twin looks the same (same seed; spectral noise differs a little)
    np.testing.assert_allclose(rgb.mean(axis=(0, 1)), spectral.mean(axis=(0, 1)), atol=0.02)


def test_expanded_xml_evaluates_like_the_library(variant):
    import drjit as dr
    import mitsuba as mi

    xml = (
        '<scene version="3.0.0"><shape type="rectangle">'
        '<bsdf type="nidar_material"><string name="name" value="grass"/></bsdf>'
        "</shape></scene>"
    )
    bsdf = mi.load_string(expand_scene_xml(xml)).shapes()[0].bsdf()
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.wi = mi.Vector3f(0.0, 0.0, 1.0)
    wls = [550.0, 905.0, 1400.0, 1550.0]
    si.wavelengths = mi.UnpolarizedSpectrum(wls)
    rho = np.array(bsdf.eval(mi.BSDFContext(), si, si.wi)).ravel() * np.pi
    np.testing.assert_allclose(rho, reflectance("grass", wls), rtol=1e-5)


_OWN = "360:0.05, 500:0.1, 600:0.4, 905:0.7, 1700:0.3"


def test_a_material_takes_another_reflectance_and_keeps_its_kind():
    """``<spectrum name="reflectance">`` in a ``nidar_material`` replaces the spectrum only: the
    road keeps its rough-diffuse facets and surge, the paint its clear coat; the RGB twin is the
    sRGB of the new spectrum."""
    body = (
        '<bsdf type="nidar_material" id="{id}"><string name="name" value="{name}"/>'
        f'<spectrum name="reflectance" value="{_OWN}"/></bsdf>'
    )
    scene = body.format(id="road", name="asphalt_old") + body.format(id="car", name="car_paint_red")
    out = ET.fromstring(expand_scene_xml(f'<scene version="3.0.0">{scene}</scene>'))
    road, car = out.find("bsdf[@id='road']"), out.find("bsdf[@id='car']")
    assert road.get("type") == "roughdiffuse" and road.find("float[@name='sigma']") is not None
    assert car.get("type") == "roughplastic" and car.find("float[@name='alpha']") is not None
    for el, name in ((road, "reflectance"), (car, "diffuse_reflectance")):
        s = Spectrum.parse_xml_value(el.find(f"spectrum[@name='{name}']").get("value"))
        np.testing.assert_allclose(s([500.0, 905.0, 1700.0]), [0.1, 0.7, 0.3], rtol=1e-6)
    twin = ET.fromstring(expand_scene_xml(f'<scene version="3.0.0">{scene}</scene>', rgb_twin=True))
    rgb = twin.find("bsdf[@id='road']/rgb[@name='reflectance']").get("value")
    expected = spectrum_to_linear_srgb(Spectrum.parse_xml_value(_OWN))
    np.testing.assert_allclose([float(v) for v in rgb.split(",")], expected, rtol=1e-6)
    assert not np.allclose(expected, linear_rgb("asphalt_old"), atol=0.01)


@pytest.mark.parametrize(
    "name, value, match",
    [
        ("iron", _OWN, "takes no reflectance"),
        ("concrete", "360:0.1, 905:1.2, 1700:0.3", r"in \[0, 1\]"),
        ("concrete", "400:0.1, 1700:0.3", "must span 360-1700 nm"),
        ("concrete", "400-0.1", "bad reflectance"),
    ],
)
def test_a_bad_reflectance_is_a_user_error(name, value, match):
    body = (
        f'<bsdf type="nidar_material"><string name="name" value="{name}"/>'
        f'<spectrum name="reflectance" value="{value}"/></bsdf>'
    )
    with pytest.raises(NidarError, match=match):
        expand_scene_xml(f'<scene version="3.0.0">{body}</scene>')
