"""Glass pass-through, NaN-producing metal presets, RGB-only warnings, kernel reuse."""

import gc
import warnings

import numpy as np
import pytest

N_GLASS = 1.5


def _fresnel_unpolarised(cos_i, n):
    """Fresnel reflectance of a smooth interface from air into index n (Hecht, Optics, eq. 4.42)."""
    sin_t = np.sqrt(1 - cos_i**2) / n
    cos_t = np.sqrt(1 - sin_t**2)
    rs = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    rp = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    return 0.5 * (rs**2 + rp**2)


def _glass_scene(glass_type):
    return f"""
    <sensor type="lidar" id="lidar">
        <string name="elevation_angles" value="4, 2, 0, -2, -4"/>
        <integer name="horizontal_resolution" value="360"/>
        <float name="range_max" value="50"/>
        <string name="intensity_mode" value="compensated"/>
    </sensor>
    <bsdf type="{glass_type}" id="glass"><float name="int_ior" value="{N_GLASS}"/></bsdf>
    <bsdf type="diffuse" id="wall"><spectrum name="reflectance" value="360:0.6, 1700:0.6"/></bsdf>
    <shape type="rectangle" id="pane"><transform name="to_world"><scale value="1.5"/>
        <rotate y="1" angle="-90"/><translate x="3"/></transform><ref id="glass"/></shape>
    <shape type="rectangle" id="backwall"><transform name="to_world"><scale value="2"/>
        <rotate y="1" angle="-90"/><translate x="6"/></transform><ref id="wall"/></shape>
    """


@pytest.mark.parametrize("glass_type", ["thindielectric", "dielectric"])
def test_glass_passes_with_two_way_fresnel(variant, write_scene, glass_type):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    L = load_scene(write_scene(_glass_scene(glass_type)))
    r = scan(L.scene, L.lidars[0])
    p = r.points()
    names = list(p["material_names"])
    assert "glass" not in {names[m] for m in p["material"]}, "glass itself returns nothing"
    through = p["material"] == names.index("wall")
    d = p["xyz"][through] / p["range"][through, None]
    behind = np.abs(6.0 * d[:, 1] / d[:, 0]) < 1.5  # beams through the 3 m x 3 m pane
    behind &= np.abs(6.0 * d[:, 2] / d[:, 0]) < 1.5
    assert behind.sum() > 20
    cos_i = d[behind, 0]
    R = _fresnel_unpolarised(cos_i, N_GLASS)
    # thin pane: two interfaces with inter-reflections, T = (1 - R) / (1 + R); one interface: 1 - R
    T = (1 - R) / (1 + R) if glass_type == "thindielectric" else 1 - R
    expected = 0.6 * p["cos_incidence"][through][behind] * T**2
    np.testing.assert_allclose(p["intensity"][through][behind], expected, rtol=1e-3)
    # range: the path length to the wall along the beam (6 m / cos)
    np.testing.assert_allclose(p["range"][through][behind], 6.0 / cos_i, rtol=1e-4)


def _register_nan_bsdf():
    """A BSDF whose every evaluation is NaN, as Mitsuba's metal presets give past their tables."""
    import drjit as dr
    import mitsuba as mi

    class NaNBSDF(mi.BSDF):
        def __init__(self, props):
            super().__init__(props)
            self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]

        def sample(self, ctx, si, sample1, sample2, active=True):
            return dr.zeros(mi.BSDFSample3f), mi.Spectrum(dr.nan)

        def eval(self, ctx, si, wo, active=True):
            return mi.Spectrum(dr.nan)

        def pdf(self, ctx, si, wo, active=True):
            return mi.Float(0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return mi.Spectrum(dr.nan), mi.Float(0.0)

        def traverse(self, callback):
            pass

        def to_string(self):
            return "NaNBSDF[]"

    mi.register_bsdf("test_nan_bsdf", lambda props: NaNBSDF(props))


def test_nan_reflectance_is_dropped_with_one_warning(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    _register_nan_bsdf()
    body = """
    <sensor type="lidar" id="lidar"><string name="elevation_angles" value="1, 0, -1"/>
        <integer name="horizontal_resolution" value="90"/></sensor>
    <shape type="sphere" id="ball"><point name="center" x="4" y="0" z="0"/>
        <bsdf type="test_nan_bsdf" id="nan_metal"/></shape>
    <shape type="sphere" id="ball2"><point name="center" x="-4" y="0" z="0"/>
        <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.5, 1700:0.5"/></bsdf></shape>
    """
    L = load_scene(write_scene(body))
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        r = scan(L.scene, L.lidars[0])
    msgs = [str(x.message) for x in w if "nan_metal" in str(x.message)]
    assert len(msgs) == 1 and "no finite reflectance" in msgs[0]
    nan_idx = r.material_names.index("nan_metal")
    assert (r.hit & (r.material == nan_idx)).sum() > 0
    assert not (r.valid & (r.material == nan_idx)).any()
    assert (r.valid & (r.material == r.material_names.index("grey"))).sum() > 0
    assert np.isfinite(r.reflectance).all() and np.isfinite(r.intensity).all()


def _conductor_dome(material: str, wavelength: float, alpha: float = 0.3) -> str:
    """A LiDAR at the centre of a rough-conductor dome: every beam at normal incidence."""
    return f"""
    <sensor type="lidar" id="lidar">
        <string name="elevation_angles" value="20, 10, 0, -10, -20"/>
        <integer name="horizontal_resolution" value="180"/>
        <float name="wavelength" value="{wavelength}"/></sensor>
    <bsdf type="roughconductor" id="metal">{material}<float name="alpha" value="{alpha}"/></bsdf>
    <shape type="sphere" id="dome"><float name="radius" value="10"/><ref id="metal"/>
        <boolean name="flip_normals" value="true"/></shape>
    """


def test_rough_conductor_monostatic_reflectance_exceeds_one(variant, write_scene):
    """ρ = π·f_r(ω, ω) is Lambertian-equivalent: a rough conductor at normal incidence gives
    F(0)·D(0)·G·π/4 = F(0) / (4 α²) (Beckmann or GGX, D(0) = 1/(π α²), G = 1), above 1 for
    α < √F / 2. F(0) = ((n-1)² + k²) / ((n+1)² + k²) for a conductor of index n + ik."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    n, k, alpha = 0.2, 5.0, 0.3
    eta = f'<spectrum name="eta" value="{n}"/><spectrum name="k" value="{k}"/>'
    L = load_scene(write_scene(_conductor_dome(eta, 905, alpha)))
    r = scan(L.scene, L.lidars[0])
    f0 = ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)
    assert r.valid.all()
    np.testing.assert_allclose(r.reflectance, f0 / (4 * alpha**2), rtol=1e-4)
    assert r.reflectance.min() > 2.5


def test_a_conductor_preset_past_its_table_loses_every_return(variant, write_scene):
    """Mitsuba's gold ("Au") has no data past ~886 nm: a warning, and no return at all (not
    the few beams whose evaluation happened to be finite)."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    gold = '<string name="material" value="Au"/>'
    for wavelength, kept in ((850, True), (905, False)):
        L = load_scene(write_scene(_conductor_dome(gold, wavelength)))
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            r = scan(L.scene, L.lidars[0])
        msgs = [str(x.message) for x in w if "no finite reflectance" in str(x.message)]
        assert r.hit.all()
        if kept:
            assert r.valid.all() and not msgs
        else:
            assert len(msgs) == 1 and "'metal'" in msgs[0] and "returns are dropped" in msgs[0]
            assert not r.valid.any() and not r.intensity.any() and not r.range.any()


def test_rgb_material_warns(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    body = """
    <sensor type="lidar" id="lidar"><string name="elevation_angles" value="0"/>
        <integer name="horizontal_resolution" value="36"/></sensor>
    <shape type="sphere" id="ball"><point name="center" x="4" y="0" z="0"/>
        <bsdf type="diffuse" id="painted_rgb"><rgb name="reflectance" value="0.1, 0.5, 0.2"/></bsdf></shape>
    """
    L = load_scene(write_scene(body))
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        scan(L.scene, L.lidars[0])
    assert any("painted_rgb" in str(x.message) and "RGB-only" in str(x.message) for x in w)


def test_new_pose_and_seed_reuse_kernels(variant, write_scene):
    """Poses and seeds are opaque: scanning another frame launches the same kernels."""
    import drjit as dr

    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    body = """
    <sensor type="lidar" id="lidar"><string name="preset" value="vlp16"/>
        <integer name="horizontal_resolution" value="180"/><float name="noise_range_std" value="0.01"/></sensor>
    <shape type="sphere" id="ball"><point name="center" x="4" y="0" z="0"/>
        <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.5, 1700:0.5"/></bsdf></shape>
    """
    L = load_scene(write_scene(body))
    # Objects of earlier tests freed mid-test would change the set of BSDF instances (and so
    # the dispatch kernels): collect them first and hold the collector still.
    gc.collect()
    gc.disable()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for _ in range(2):  # the first scans of a scene also build one-time state
            scan(L.scene, L.lidars[0], seed=99, to_world=np.eye(4))
        hashes = []
        for i in range(3):
            T = np.eye(4)
            T[:3, 3] = [0.1 * i, -0.05 * i, 0.02 * i]
            dr.kernel_history()  # clear
            scan(L.scene, L.lidars[0], seed=i + 1, to_world=T)
            hashes.append(sorted(k["hash"] for k in dr.kernel_history() if "hash" in k))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        gc.enable()
    assert hashes[0] and hashes[1] == hashes[2] == hashes[0]
