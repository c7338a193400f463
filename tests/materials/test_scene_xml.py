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
