"""Scene XML of generated layouts: byte stability, structure, light spectra, shape poses."""

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from nidar_mi.illumination import sky_radiance, sun_irradiance
from nidar_mi.scenegen.generate import generate_scene
from nidar_mi.scenegen.primitives import Block, Layout, Panel, Patch, Rig, Sky, Sun
from nidar_mi.scenegen.xml import DEFAULT_COLS, scene_xml

RIG = Rig("hdl64e", (0.0, 0.0, 1.8), 0.0, (0.3, 0.0, 1.7), 0.0, -2.0, 80.0)


def _spectrum(text: str) -> tuple[np.ndarray, np.ndarray]:
    pairs = [p.split(":") for p in text.split(",")]
    return np.array([float(a) for a, _ in pairs]), np.array([float(b) for _, b in pairs])


def test_same_seed_byte_identical_xml():
    _, a = generate_scene(5, 2)
    _, b = generate_scene(5, 2)
    assert a.encode() == b.encode()


def test_different_seeds_different_xml():
    texts = {generate_scene(s, k)[1] for s in (0, 1) for k in range(3)}
    assert len(texts) == 6


def test_structure_refs_and_defaults():
    layout, text = generate_scene(3, 0)
    root = ET.fromstring(text)
    defaults = {d.get("name"): d.get("value") for d in root.findall("default")}
    assert defaults == {
        "spp": "16",
        "width": "480",
        "height": "270",
        "cols": str(DEFAULT_COLS[layout.rig.lidar_preset]),
    }
    bsdfs = {b.get("id"): b for b in root.findall("bsdf")}
    assert all(b.get("type") == "nidar_material" for b in bsdfs.values())
    assert {b.find("string").get("value") for b in bsdfs.values()} == set(layout.materials())
    shapes = root.findall("shape")
    assert [s.get("id") for s in shapes] == [s.id for s in layout.shapes]
    assert all(s.find("ref").get("id") in bsdfs for s in shapes)
    sensors = {s.get("id"): s.get("type") for s in root.findall("sensor")}
    assert sensors == {"lidar_top": "lidar", "cam_front": "perspective"}


def test_sun_and_sky_carry_the_astm_spectra_scaled():
    layout = Layout("urban", (), Sun(40.0, 120.0, 0.8), Sky(1.3), RIG)
    root = ET.fromstring(scene_xml(layout))
    emitters = {e.get("id"): e for e in root.findall("emitter")}
    wl, sun = _spectrum(emitters["sun"].find("spectrum").get("value"))
    ref_wl, ref = sun_irradiance(step=20.0, scale=0.8)
    np.testing.assert_array_equal(wl, ref_wl)
    np.testing.assert_allclose(sun, ref, rtol=1e-3)
    assert wl.max() >= 1600 and sun[np.argmin(abs(wl - 900))] > 0.3  # NIR is there
    _, sky = _spectrum(emitters["sky"].find("spectrum").get("value"))
    np.testing.assert_allclose(sky, sky_radiance(step=20.0, scale=1.3)[1], rtol=1e-3)
    v = emitters["sun"].find("vector")
    d = np.array([float(v.get(c)) for c in "xyz"])
    el, az = math.radians(40.0), math.radians(120.0)
    expected = -np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    np.testing.assert_allclose(d, expected, atol=1e-6)


def test_shape_poses_in_mitsuba(variant, tmp_path):
    """A Panel's normal points to its heading with the documented extents; a yawed Block and a
    Patch cover the hand-computed boxes (distinct materials: Mitsuba merges meshes sharing one)."""
    import mitsuba as mi

    from nidar_mi.scene import load_scene

    shapes = (
        Panel("panel", "concrete", (2.0, 3.0, 1.5), (0.5, 0.25), 90.0),
        Block("block", "brick_red", (10.0, 0.0, 1.0), (2.0, 1.0, 1.0), 90.0),
        Patch("patch", "grass", (-5.0, 4.0, 0.01), (3.0, 1.0), 0.0),
    )
    layout = Layout("urban", shapes, Sun(45.0, 0.0, 1.0), Sky(1.0), RIG)
    path = tmp_path / "s.xml"
    path.write_text(scene_xml(layout))
    loaded = load_scene(str(path), variant=variant)
    by_id = {s.id(): s for s in loaded.scene.shapes()}
    lo, hi = by_id["panel"].bbox().min, by_id["panel"].bbox().max
    # heading 90: the panel spans x in [1.5, 2.5] (half width 0.5), z in [1.25, 1.75]
    np.testing.assert_allclose([lo.x, lo.z, hi.x, hi.z], [1.5, 1.25, 2.5, 1.75], atol=1e-5)
    np.testing.assert_allclose([lo.y, hi.y], [3.0, 3.0], atol=1e-5)
    ray = mi.Ray3f(mi.Point3f(2.0, 10.0, 1.5), mi.Vector3f(0.0, -1.0, 0.0))
    si = loaded.scene.ray_intersect(ray)
    assert si.shape == by_id["panel"]
    n = np.array([si.n.x[0], si.n.y[0], si.n.z[0]])
    np.testing.assert_allclose(n, [0.0, 1.0, 0.0], atol=1e-5)  # the normal faces +y
    b = by_id["block"].bbox()
    np.testing.assert_allclose([b.min.x, b.min.y, b.max.x, b.max.y], [9, -2, 11, 2], atol=1e-5)
    p = by_id["patch"].bbox()
    np.testing.assert_allclose([p.min.x, p.min.y, p.max.x, p.max.y], [-8, 3, -2, 5], atol=1e-5)


@pytest.mark.parametrize("k", range(3))
def test_camera_lookat_matches_the_rig(k):
    layout, text = generate_scene(11, k)
    la = ET.fromstring(text).find("sensor[@id='cam_front']/transform/lookat")
    o = np.array([float(v) for v in la.get("origin").split(",")])
    t = np.array([float(v) for v in la.get("target").split(",")])
    np.testing.assert_allclose(o, layout.rig.camera_position)
    np.testing.assert_allclose((t - o) / 10.0, layout.rig.camera_direction, atol=1e-6)
