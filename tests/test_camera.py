"""Camera renders: NIR band normalisation, Lambertian radiance, depth, intrinsics, RGB-emitter
warning, reflectance and albedo maps."""

import warnings

import numpy as np
import pytest

CAM = """
<sensor type="perspective" id="cam">
    <float name="fov" value="60"/>
    <transform name="to_world"><lookat origin="0,0,1" target="{tx},0,{tz}" up="0,0,1"/></transform>
    <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
    <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="16"/></film>
</sensor>
<sensor type="lidar" id="lidar"><string name="elevation_angles" value="0"/>
    <integer name="horizontal_resolution" value="8"/><float name="wavelength" value="{wl}"/></sensor>
"""


def _render(write_scene, body, wl=905.0, spp=4, tx=5, tz=1, albedo=True):
    from nidar_mi.camera import render_camera
    from nidar_mi.scene import load_scene

    L = load_scene(write_scene(CAM.format(wl=wl, tx=tx, tz=tz) + body))
    return render_camera(L, L.cameras[0], wavelength=wl, spp=spp, seed=1, albedo=albedo)


@pytest.mark.parametrize("wl", [905.0, 1550.0])
def test_uniform_sky_of_radiance_one_reads_one(variant, write_scene, wl):
    sky = '<emitter type="constant"><spectrum name="radiance" value="300:1, 1700:1"/></emitter>'
    r = _render(write_scene, sky, wl=wl)
    np.testing.assert_allclose(r.nir, 1.0, rtol=1e-5)
    assert (r.depth == 0).all()


def test_lambertian_ground_under_uniform_sky(variant, write_scene):
    """An infinite Lambertian plane under a uniform sky of radiance L reflects ρ(λ)·L."""
    body = """
    <emitter type="constant"><spectrum name="radiance" value="300:2, 1700:2"/></emitter>
    <shape type="rectangle"><transform name="to_world"><scale value="1000"/></transform>
        <bsdf type="diffuse"><spectrum name="reflectance" value="400:0.2, 1600:0.8"/></bsdf></shape>
    """
    r = _render(write_scene, body, wl=905.0, spp=256, tx=3, tz=0)
    ground = r.depth > 0
    assert ground.sum() > 100
    # ρ(905) = 0.2 + 0.6 * 505/1200 = 0.4525; radiance 2 * 0.4525
    assert r.nir[ground].mean() == pytest.approx(2 * 0.4525, rel=0.02)


def test_depth_and_intrinsics(variant, write_scene):
    body = """
    <shape type="rectangle"><transform name="to_world"><scale value="20"/><rotate y="1" angle="-90"/>
        <translate x="4"/></transform><bsdf type="diffuse"/></shape>
    """
    r = _render(write_scene, body)
    # a wall 4 m ahead, facing the camera: z-depth 4 everywhere
    np.testing.assert_allclose(r.depth, 4.0, rtol=1e-5)
    fx = 12.0 / np.tan(np.deg2rad(30.0))  # 60 deg over 24 px
    np.testing.assert_allclose(r.K, [[fx, 0, 11.5], [0, fx, 7.5], [0, 0, 1]], rtol=1e-4, atol=1e-3)
    # OpenCV axes: camera x right = world -y, y down = world -z, z forward = world +x
    np.testing.assert_allclose(
        r.T_world_cam[:3, :3], [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-6
    )
    np.testing.assert_allclose(r.T_world_cam[:3, 3], [0, 0, 1], atol=1e-6)


def test_rgb_emitter_warns(variant, write_scene):
    body = '<emitter type="constant" id="rgb_sky"><rgb name="radiance" value="1, 1, 1"/></emitter>'
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        r = _render(write_scene, body)
    assert any("rgb_sky" in str(x.message) and "830 nm" in str(x.message) for x in w)
    assert r.nir.max() < 1e-3  # D65-shaped radiance: nothing at 905 nm


def test_reflectance_image_is_rho_at_the_laser_wavelength(variant, write_scene):
    """ρ(λ) of a Lambertian plane per pixel, 0 on the sky; the same as the LiDAR's monostatic ρ."""
    body = """
    <emitter type="constant"><spectrum name="radiance" value="300:2, 1700:2"/></emitter>
    <shape type="rectangle"><transform name="to_world"><scale value="1000"/></transform>
        <bsdf type="diffuse"><spectrum name="reflectance" value="400:0.2, 1600:0.8"/></bsdf></shape>
    """
    for wl, rho in ((905.0, 0.2 + 0.6 * 505 / 1200), (1550.0, 0.2 + 0.6 * 1150 / 1200)):
        r = _render(write_scene, body, wl=wl, tx=3, tz=0)
        ground = r.depth > 0
        assert r.reflectance.shape == r.depth.shape and r.reflectance.dtype == np.float32
        np.testing.assert_allclose(r.reflectance[ground], rho, rtol=1e-5)
        assert (r.reflectance[~ground] == 0).all() and (~ground).sum() > 20


def test_reflectance_behind_glass_carries_the_two_way_transmittance(variant, write_scene):
    """A thin glass pane (n = 1.5) before a white wall: ρ·T², T = 1 - 2R/(1+R), R = 0.04 at normal
    incidence (Fresnel), for the pixels that look through it near its normal."""
    body = """
    <shape type="rectangle"><transform name="to_world"><scale value="20"/><rotate y="1" angle="-90"/>
        <translate x="4"/></transform><bsdf type="diffuse"><spectrum name="reflectance" value="0.5"/>
        </bsdf></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="20"/><rotate y="1" angle="-90"/>
        <translate x="2"/></transform><bsdf type="thindielectric"><float name="int_ior" value="1.5"/>
        <float name="ext_ior" value="1.0"/></bsdf></shape>
    """
    r = _render(write_scene, body, tx=5, tz=1)
    centre = r.reflectance[7:9, 11:13]
    R = 0.04
    T = 1 - 2 * R / (1 + R)  # thin slab, multiple reflections
    np.testing.assert_allclose(centre, 0.5 * T**2, rtol=2e-3)  # rays within 2.5 deg of normal


def test_albedo_is_the_colour_of_the_surface_spectrum(variant, write_scene):
    """The albedo colour of a Lambertian plane is the D65 linear sRGB of its spectrum
    (colour-science's integration, :func:`spectrum_to_linear_srgb`), its surface reflectance ρ(λ)
    whatever the viewing angle; a rough plastic's albedo is its pigment layer, not its gloss."""
    from nidar_mi.materials.spectra import Spectrum
    from nidar_mi.materials.srgb import spectrum_to_linear_srgb

    spectrum = "400:0.1, 500:0.2, 550:0.6, 650:0.3, 905:0.5, 1600:0.8"
    body = f"""
    <emitter type="constant"><spectrum name="radiance" value="300:2, 1700:2"/></emitter>
    <shape type="rectangle"><transform name="to_world"><scale value="1000"/></transform>
        <bsdf type="diffuse"><spectrum name="reflectance" value="{spectrum}"/></bsdf></shape>
    """
    wl, values = zip(*[map(float, p.split(":")) for p in spectrum.split(", ")])
    expected = spectrum_to_linear_srgb(Spectrum(np.array(wl), np.array(values)))
    r = _render(write_scene, body, wl=905.0, tx=3, tz=0)
    ground = r.depth > 0
    assert r.albedo.shape == (*r.depth.shape, 3) and r.albedo.dtype == np.float32
    np.testing.assert_allclose(
        r.albedo[ground], np.broadcast_to(expected, (ground.sum(), 3)), atol=2e-3
    )
    np.testing.assert_allclose(r.surface_reflectance[ground], 0.5, rtol=1e-5)
    assert (r.albedo[~ground] == 0).all() and (r.surface_reflectance[~ground] == 0).all()

    plastic = """
    <emitter type="constant"><spectrum name="radiance" value="300:2, 1700:2"/></emitter>
    <shape type="rectangle"><transform name="to_world"><scale value="20"/><rotate y="1" angle="-90"/>
        <translate x="4"/></transform><bsdf type="roughplastic"><float name="alpha" value="0.1"/>
        <spectrum name="diffuse_reflectance" value="0.3"/></bsdf></shape>
    """
    r = _render(write_scene, plastic, tx=5, tz=1)
    np.testing.assert_allclose(r.surface_reflectance, 0.3, rtol=1e-5)
    assert r.reflectance[7:9, 11:13].min() > 1.0  # monostatically the gloss dominates
    np.testing.assert_allclose(r.albedo, 0.3, atol=2e-3)


def test_albedo_can_be_left_out(variant, write_scene):
    r = _render(write_scene, '<shape type="sphere"><bsdf type="diffuse"/></shape>', albedo=False)
    assert r.albedo is None and r.surface_reflectance is None


@pytest.mark.parametrize("stop", [KeyboardInterrupt, "terminated"])
def test_a_signal_inside_a_custom_operation_stops_the_render(
    variant, write_scene, monkeypatch, stop
):
    """Ctrl-C or SIGTERM raised while Mitsuba runs Python inside ``drjit.custom`` reaches the
    caller as the interruption (exit 130/143), not as "Mitsuba could not render it" (exit 2)."""
    import drjit as dr
    import mitsuba as mi

    from nidar_mi.cli._common import Terminated

    exc = Terminated if stop == "terminated" else KeyboardInterrupt

    class Interrupted(dr.CustomOp):
        def eval(self, x):
            raise exc()

    def render(*args, **kwargs):
        return dr.custom(Interrupted, mi.Float(1.0))

    monkeypatch.setattr(mi, "render", render)
    with pytest.raises(exc):
        _render(write_scene, '<shape type="sphere"><bsdf type="diffuse"/></shape>', albedo=False)


def test_a_library_material_with_another_spectrum_has_that_albedo(variant, write_scene):
    """A ``nidar_material`` given another reflectance (``scenegen --spectra earthlib``) renders
    with it: its surface reflectance at λ is that spectrum's value, its albedo that spectrum's
    sRGB colour, for a rough-diffuse road surface as for a Lambertian one."""
    from nidar_mi.materials.spectra import Spectrum
    from nidar_mi.materials.srgb import spectrum_to_linear_srgb

    spectrum = "360:0.05, 450:0.08, 550:0.3, 650:0.2, 905:0.62, 1700:0.4"
    body = f"""
    <emitter type="constant"><spectrum name="radiance" value="300:2, 1700:2"/></emitter>
    <shape type="rectangle"><transform name="to_world"><scale value="1000"/></transform>
        <bsdf type="nidar_material"><string name="name" value="concrete"/>
        <spectrum name="reflectance" value="{spectrum}"/></bsdf></shape>
    """
    r = _render(write_scene, body, wl=905.0, tx=3, tz=0)
    ground = r.depth > 0
    np.testing.assert_allclose(r.surface_reflectance[ground], 0.62, rtol=1e-5)
    expected = spectrum_to_linear_srgb(Spectrum.parse_xml_value(spectrum))
    np.testing.assert_allclose(
        r.albedo[ground], np.broadcast_to(expected, (ground.sum(), 3)), atol=2e-3
    )
