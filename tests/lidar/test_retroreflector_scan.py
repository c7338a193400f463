"""Retroreflective sheeting through the LiDAR: far stronger than a white Lambertian panel."""

import numpy as np
import pytest


def test_retroreflector_outshines_white_panel(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.materials.vmf import monostatic_gain
    from nidar_mi.scene import load_scene

    body = """
    <sensor type="lidar" id="lidar"><string name="elevation_angles" value="1, 0, -1"/>
        <integer name="horizontal_resolution" value="720"/><string name="intensity_mode" value="compensated"/></sensor>
    <bsdf type="retroreflector" id="sheeting">
        <spectrum name="reflectance" value="360:0.8, 1700:0.8"/><float name="lobe_width" value="2"/></bsdf>
    <bsdf type="diffuse" id="white"><spectrum name="reflectance" value="360:0.95, 1700:0.95"/></bsdf>
    <shape type="rectangle" id="sign"><transform name="to_world"><scale value="0.5"/><rotate y="1" angle="-90"/>
        <translate x="10" y="1"/></transform><ref id="sheeting"/></shape>
    <shape type="rectangle" id="panel"><transform name="to_world"><scale value="0.5"/><rotate y="1" angle="-90"/>
        <translate x="10" y="-1"/></transform><ref id="white"/></shape>
    """
    L = load_scene(write_scene(body))
    r = scan(L.scene, L.lidars[0])
    p = r.points()
    names = list(p["material_names"])
    retro = p["material"] == names.index("sheeting")
    white = p["material"] == names.index("white")
    assert retro.sum() > 5 and white.sum() > 5
    # Lambertian: ρ·cosθ; sheeting: ρ·gain·cosθ, the monostatic gain of the documented lobe
    np.testing.assert_allclose(p["reflectance"][white], 0.95, rtol=1e-5)
    np.testing.assert_allclose(p["reflectance"][retro], 0.8 * monostatic_gain(2.0), rtol=1e-3)
    ratio = np.median(p["intensity"][retro]) / np.median(p["intensity"][white])
    assert ratio > 100
    assert ratio == pytest.approx(0.8 * monostatic_gain(2.0) / 0.95, rel=0.02)
