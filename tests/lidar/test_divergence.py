"""Beam divergence and multiple returns against closed forms.

One beam along +x (``horizontal_resolution`` 1, ``fov_h`` 1 centred, elevation 0). A panel at
10 m covers the side ``y > y_e`` of the footprint, a wall at 20 m the rest: the beam splits its
energy between them by the fraction of the Gaussian footprint the panel covers,
:func:`nidar_mi.lidar.footprint.footprint_fraction` (an integral of the profile, independent of
the sub-ray pattern). Tolerances: the sub-ray sum is a midpoint quadrature of that integral,
within 0.04 of it at quality 8 (169 sub-rays) and 0.027 at 12 for any edge position and
orientation (``tests/lidar/test_footprint.py``); against the discrete sum of the
sub-ray weights that hit the panel (recomputed here from the sub-ray geometry) float32 rounding
only (1e-5 relative).
"""

import numpy as np
import pytest

RHO = 0.5
DIV_MRAD = 10.0  # full angle: θ_w = 5 mrad, a footprint of 5 cm radius at 10 m


def _scene(edge_y, *, quality, mode="dual", extra=""):
    return f"""
    <sensor type="lidar" id="lidar">
        <string name="elevation_angles" value="0"/>
        <integer name="horizontal_resolution" value="1"/>
        <float name="fov_h" value="1"/>
        <boolean name="fov_h_centred" value="true"/>
        <float name="beam_divergence" value="{DIV_MRAD}"/>
        <integer name="beam_sample_quality" value="{quality}"/>
        <string name="return_mode" value="{mode}"/>
        <float name="range_max" value="100"/>
        {extra}
    </sensor>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:{RHO}, 1700:{RHO}"/></bsdf>
    <bsdf type="diffuse" id="grey2"><spectrum name="reflectance" value="360:{RHO}, 900:{RHO}, 1700:{RHO}"/></bsdf>
    <shape type="rectangle" id="panel"><transform name="to_world">
        <scale x="1" y="1"/><rotate y="1" angle="-90"/><translate x="10" y="{edge_y + 1.0}"/>
        </transform><ref id="grey"/></shape>
    <shape type="rectangle" id="wall"><transform name="to_world"><scale value="5"/>
        <rotate y="1" angle="-90"/><translate x="20"/></transform><ref id="grey2"/></shape>
    """


def _one_beam(write_scene, edge_y, quality, mode="dual"):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    L = load_scene(write_scene(_scene(edge_y, quality=quality, mode=mode)))
    return scan(L.scene, L.lidars[0])


def _discrete_fraction(edge_y, quality):
    """Σ w·cos³δ over the sub-rays crossing x = 10 m at y > edge_y (δ from +x: the range is
    10/cos δ and the incidence cosine cos δ), and the same over the others (the wall)."""
    import mitsuba as mi

    from nidar_mi.lidar.footprint import subray_offsets

    off, w = subray_offsets(quality)
    s, t = mi.coordinate_system(mi.ScalarVector3f(1.0, 0.0, 0.0))
    theta = DIV_MRAD * 5e-4
    s, t = np.array(s).ravel(), np.array(t).ravel()
    d = np.array([1.0, 0, 0]) + np.tan(off[:, :1] * theta) * s + np.tan(off[:, 1:] * theta) * t
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    on_panel = 10.0 * d[:, 1] / d[:, 0] > edge_y
    c3 = w * d[:, 0] ** 3
    return float(c3[on_panel].sum()), float(c3[~on_panel].sum())


@pytest.mark.parametrize("edge", [-0.55, 0.0, 0.4])
def test_edge_splits_energy_by_footprint_fraction(variant, write_scene, edge):
    from nidar_mi.lidar.footprint import footprint_fraction

    theta_w = DIV_MRAD * 5e-4
    edge_y = edge * 10.0 * theta_w + 1e-4  # off the sub-rays lying exactly on a ring axis
    F = footprint_fraction(-edge)  # the panel covers y > edge_y
    for quality, tol in ((8, 0.04), (12, 0.027)):
        r = _one_beam(write_scene, edge_y, quality)
        front, back = r.intensity[0, 0], r.further[0].intensity[0, 0]
        if 0.6 * RHO / 100.0 * F < RHO / 400.0 * (1 - F):  # the wall is the strongest
            front, back = back, front
        assert r.valid[0, 0] and r.further[0].valid[0, 0], "dual mode reports both echoes"
        F_front = front / (RHO / 100.0)
        F_back = back / (RHO / 400.0)
        discrete_front, discrete_back = _discrete_fraction(edge_y, quality)
        assert F_front == pytest.approx(discrete_front, rel=1e-5)
        assert F_back == pytest.approx(discrete_back, rel=1e-5)
        assert abs(F_front - F) < tol, (quality, F_front, F)


def test_dual_reports_strongest_and_last_with_their_ranges(variant, write_scene):
    r = _one_beam(write_scene, 0.0, 5)
    strongest, last = r.first, r.further[0]
    assert strongest.range[0, 0] == pytest.approx(10.0, abs=1e-3)
    assert last.range[0, 0] == pytest.approx(20.0, abs=1e-3)
    assert r.shape_names[strongest.shape_index[0, 0]] == "panel"
    assert r.shape_names[last.shape_index[0, 0]] == "wall"
    p = r.points()
    assert list(p["return_index"]) == [0, 1]
    np.testing.assert_allclose(p["xyz"][:, 0], [10.0, 20.0], atol=1e-3)


@pytest.mark.parametrize("mode, expected_m", [("first", 10.0), ("last", 20.0), ("strongest", 10.0)])
def test_single_return_modes(variant, write_scene, mode, expected_m):
    r = _one_beam(write_scene, 0.0, 5, mode)
    assert not r.further
    assert r.valid[0, 0] and r.range[0, 0] == pytest.approx(expected_m, abs=1e-3)


def test_dual_with_the_strongest_last_reports_the_second_strongest(variant, write_scene):
    # the panel covers a sliver: the wall echo is the strongest and also the last
    theta_w = DIV_MRAD * 5e-4
    r = _one_beam(write_scene, 0.85 * 10.0 * theta_w, 8)
    assert r.range[0, 0] == pytest.approx(20.0, abs=1e-3)
    assert r.further[0].valid[0, 0]
    assert r.further[0].range[0, 0] == pytest.approx(10.0, abs=1e-3)


def test_glass_pane_gives_its_own_echo(variant, write_scene):
    """A pane at normal incidence returns g·R/(2 θ_w² d²) (R = ((n-1)/(n+1))²), the wall behind
    it g·ρ·T²/d² with T = 1 - R: dual mode reports both (n = 1.5 / 1.000277, Mitsuba's air)."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    body = (
        _scene(-5.0, quality=3)
        .replace(
            '<shape type="rectangle" id="panel">',
            '<bsdf type="dielectric" id="glass"><float name="int_ior" value="1.5"/></bsdf>'
            '<shape type="rectangle" id="pane"><transform name="to_world"><scale value="2"/>'
            '<rotate y="1" angle="-90"/><translate x="5"/></transform><ref id="glass"/></shape>'
            '<shape type="rectangle" id="panel">',
        )
        .replace('translate x="10" y="-4.0"', 'translate x="10" y="-40"')
    )
    L = load_scene(write_scene(body))
    r = scan(L.scene, L.lidars[0])
    eta = 1.5 / 1.000277  # Mitsuba's default exterior: air
    R = ((eta - 1.0) / (eta + 1.0)) ** 2
    theta_w = DIV_MRAD * 5e-4
    glass, wall = r.first, r.further[0]
    assert r.shape_names[glass.shape_index[0, 0]] == "pane"
    assert glass.range[0, 0] == pytest.approx(5.0, abs=1e-3)
    assert glass.reflectance[0, 0] == pytest.approx(R, rel=1e-4)
    assert glass.intensity[0, 0] == pytest.approx(R / (2 * theta_w**2) / 25.0, rel=1e-3)
    assert wall.range[0, 0] == pytest.approx(20.0, abs=1e-3)
    assert wall.intensity[0, 0] == pytest.approx(RHO * (1 - R) ** 2 / 400.0, rel=1e-3)


def test_ideal_beam_is_the_single_ray_scan(variant, write_scene):
    """Without divergence every single-return mode is the one-ray scan (nothing to split), and
    ``dual`` (which would silently be single) is refused in one line naming the fix."""
    from nidar_mi.errors import NidarError
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    base = _scene(0.0, quality=3).replace(f'value="{DIV_MRAD}"', 'value="0"')
    out = []
    for mode in ("strongest", "first", "last"):
        L = load_scene(write_scene(base.replace('value="dual"', f'value="{mode}"')))
        out.append(scan(L.scene, L.lidars[0]))
    assert not any(r.further for r in out)
    assert out[0].range[0, 0] == out[1].range[0, 0] == out[2].range[0, 0]
    with pytest.raises(NidarError, match=r"'return_mode' 'dual' needs beam_divergence > 0"):
        load_scene(write_scene(base))


def test_echo_receiver_draws_are_per_beam_and_standard_normal():
    """The receiver noise of diverging beams: one standard normal per (beam, echo slot), the
    same whatever block the beam is cast in, another for another seed."""
    from nidar_mi.lidar.scan import _echo_normals

    whole = _echo_normals(3, 0, (100_000, 4))
    np.testing.assert_array_equal(_echo_normals(3, 500, (10, 4)), whole[500:510])
    np.testing.assert_array_equal(_echo_normals(3, 500, (10, 2)), whole[500:510, :2])
    assert abs(whole.mean()) < 0.01 and abs(whole.std() - 1.0) < 0.01
    assert abs(np.corrcoef(whole[:, 0], whole[:, 1])[0, 1]) < 0.01
    assert not np.array_equal(_echo_normals(4, 0, (10, 4)), whole[:10])
