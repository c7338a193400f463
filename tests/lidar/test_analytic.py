"""The scan against the closed-form return model on Lambertian panels (noise off).

Geometry and intensities are computed here independently of the package: beam directions from
the azimuth/elevation definition, ray-rectangle intersections in NumPy, ρ(λ) by linear
interpolation of the panels' literal spectra.
"""

import numpy as np
import pytest

RAMP = [(400.0, 0.2), (1600.0, 0.8)]  # ρ(905) = 0.4525, ρ(1550) = 0.775
FLAT = [(360.0, 0.35), (1700.0, 0.35)]
ALPHA = 0.02  # 1/m
ELEV = [6.0, 3.0, 1.0, -1.0, -3.0, -6.0]
COLS = 720


def _panels():
    """(id, material, centre, yaw of the normal away from the sensor in deg, half size)."""
    return [
        ("p_near", "ramp", (4.0, 0.0, 0.0), 0.0, 0.3),
        ("p_tilt", "ramp", (7.0, 3.0, 0.0), 35.0, 0.45),
        ("p_far", "flat", (-12.0, 1.0, 0.3), 160.0, 0.9),
        ("p_side", "flat", (0.5, -9.0, -0.2), -100.0, 1.1),
    ]


def _rotation(yaw_deg):
    """Rectangle frame: Mitsuba rectangle (xy-plane, normal +z) turned by rotate y -90 (normal -x)
    then rotate z yaw: returns (u, v, n) world axes."""
    y = np.deg2rad(yaw_deg)
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    Ry = np.array([[0, 0, -1], [0, 1, 0], [1, 0, 0]])  # rotate y by -90 deg
    R = Rz @ Ry
    return R[:, 0], R[:, 1], R[:, 2]


def _scene_xml(wavelength, mode):
    def spec(s):
        return ", ".join(f"{w:g}:{v:g}" for w, v in s)

    body = f"""
    <sensor type="lidar" id="lidar">
        <string name="elevation_angles" value="{",".join(map(str, ELEV))}"/>
        <integer name="horizontal_resolution" value="{COLS}"/>
        <float name="wavelength" value="{wavelength}"/>
        <float name="gain" value="2.5"/>
        <float name="range_min" value="0.1"/>
        <float name="range_max" value="50"/>
        <float name="atmospheric_extinction" value="{ALPHA}"/>
        <string name="intensity_mode" value="{mode}"/>
    </sensor>
    <bsdf type="diffuse" id="ramp"><spectrum name="reflectance" value="{spec(RAMP)}"/></bsdf>
    <bsdf type="diffuse" id="flat"><spectrum name="reflectance" value="{spec(FLAT)}"/></bsdf>
    """
    for pid, mat, c, yaw, h in _panels():
        body += f"""
    <shape type="rectangle" id="{pid}"><transform name="to_world"><scale value="{h}"/>
        <rotate y="1" angle="-90"/><rotate z="1" angle="{yaw}"/>
        <translate x="{c[0]}" y="{c[1]}" z="{c[2]}"/></transform><ref id="{mat}"/></shape>"""
    return body


def _expected(wavelength, mode):
    el = np.deg2rad(np.array(ELEV))[:, None]
    az = np.deg2rad((np.arange(COLS) + 0.5) * 360.0 / COLS)[None, :]
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el) + 0 * az], -1)
    best_t = np.full(d.shape[:2], np.inf)
    rho = np.zeros(d.shape[:2])
    cos = np.zeros(d.shape[:2])
    margin = np.full(d.shape[:2], np.inf)
    for _, mat, c, yaw, h in _panels():
        u, v, n = _rotation(yaw)
        c = np.asarray(c)
        dn = d @ n
        t = (c @ n) / np.where(np.abs(dn) > 1e-12, dn, np.nan)
        p = d * t[..., None] - c
        pu, pv = p @ u, p @ v
        inside = (t > 0) & (np.abs(pu) <= h) & (np.abs(pv) <= h)
        near_u = np.where(np.abs(pv) <= h + 1e-3, np.abs(np.abs(pu) - h), np.inf)
        near_v = np.where(np.abs(pu) <= h + 1e-3, np.abs(np.abs(pv) - h), np.inf)
        margin = np.minimum(margin, np.where(t > 0, np.minimum(near_u, near_v), np.inf))
        closer = inside & (t < best_t)
        wl, vals = zip(*(RAMP if mat == "ramp" else FLAT))
        best_t = np.where(closer, t, best_t)
        rho = np.where(closer, np.interp(wavelength, wl, vals), rho)
        cos = np.where(closer, np.abs(dn), cos)
    hit = np.isfinite(best_t)
    dist = np.where(hit, best_t, 1.0)
    I = 2.5 * rho * cos * np.exp(-2 * ALPHA * dist)
    if mode == "raw":
        I = I / dist**2
    return hit, best_t, I, margin


@pytest.mark.parametrize("wavelength", [905.0, 1550.0])
@pytest.mark.parametrize("mode", ["raw", "compensated"])
def test_panels_match_return_model(variant, write_scene, wavelength, mode):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    hit, t, I, margin = _expected(wavelength, mode)
    assert margin.min() > 1e-4, "test geometry: no beam may graze a panel edge"
    assert 200 < hit.sum() < hit.size  # every panel is seen, not every beam hits

    loaded = load_scene(write_scene(_scene_xml(wavelength, mode)))
    r = scan(loaded.scene, loaded.lidars[0])
    assert r.valid.sum() == hit.sum()
    np.testing.assert_array_equal(r.valid, hit)
    np.testing.assert_allclose(r.range[hit], t[hit], rtol=1e-4)
    np.testing.assert_allclose(r.intensity[hit], I[hit], rtol=1e-4)
    # ρ at λ: the literal spectra interpolated linearly
    expected_rho = {905.0: (0.4525, 0.35), 1550.0: (0.775, 0.35)}[wavelength]
    names = r.material_names
    ramp = r.material == names.index("ramp")
    flat = r.material == names.index("flat")
    np.testing.assert_allclose(r.reflectance[ramp & hit], expected_rho[0], rtol=1e-5)
    np.testing.assert_allclose(r.reflectance[flat & hit], expected_rho[1], rtol=1e-5)
    pts = r.points()
    np.testing.assert_allclose(np.linalg.norm(pts["xyz"], axis=1), pts["range"], rtol=1e-5)
    assert np.isfinite(pts["intensity"]).all()


def test_detection_threshold_and_range_limits(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    hit, t, I, _ = _expected(905.0, "raw")
    vals = np.unique(I[hit])
    k = int(
        np.argmax(np.diff(vals) / vals[1:] > 1e-3 * (np.arange(vals.size - 1) >= vals.size // 2))
    )
    thr = float(0.5 * (vals[k] + vals[k + 1]))  # between two returns, far from either (float32)
    xml = _scene_xml(905.0, "raw").replace(
        '<float name="range_max" value="50"/>',
        f'<float name="range_max" value="10"/><float name="detection_threshold" value="{thr}"/>',
    )
    r = scan(*(lambda L: (L.scene, L.lidars[0]))(load_scene(write_scene(xml))))
    expected = hit & (I >= thr) & (t <= 10.0)
    np.testing.assert_array_equal(r.valid, expected)


def test_pose_moves_points_not_frame(variant, write_scene):
    """A translated sensor sees the same world points; xyz stays in the LiDAR frame."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    loaded = load_scene(write_scene(_scene_xml(905.0, "raw")))
    T = np.eye(4)
    T[:3, 3] = [0.2, -0.1, 0.05]
    r = scan(loaded.scene, loaded.lidars[0], to_world=T)
    p = r.points()
    np.testing.assert_allclose(p["xyz_world"], p["xyz"] + T[:3, 3], atol=1e-5)
