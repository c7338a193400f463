"""The scan on the device: one kernel per block, look-ups on the device, draws left out at σ 0."""

import numpy as np

_BODY = """
<sensor type="lidar" id="lidar"><string name="preset" value="vlp16"/>
    <integer name="horizontal_resolution" value="180"/>
    <float name="noise_intensity_std" value="{noise_i}"/>
    <float name="noise_range_std" value="{noise_r}"/>
    <float name="dropout" value="0.1"/></sensor>
<shape type="sphere" id="ball"><point name="center" x="4" y="0" z="0"/>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.5, 1700:0.5"/></bsdf></shape>
<shape type="rectangle" id="floor"><transform name="to_world"><scale value="20"/>
    <translate z="-1.5"/></transform>
    <bsdf type="diffuse" id="dark"><spectrum name="reflectance" value="360:0.1, 1700:0.1"/></bsdf></shape>
"""


def _load(write_scene, noise_i=0.01, noise_r=0.02):
    from nidar_mi.scene import load_scene

    return load_scene(write_scene(_BODY.format(noise_i=noise_i, noise_r=noise_r)))


def test_ideal_scan_is_one_kernel_over_the_beams(variant, write_scene):
    """Pattern, pose, draws, detection and look-ups run in one kernel of one lane per beam."""
    import drjit as dr

    from nidar_mi.lidar.scan import scan

    L = _load(write_scene)
    scan(L.scene, L.lidars[0])
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        res = scan(L.scene, L.lidars[0])
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    beams = res.valid.size
    assert [k["size"] for k in history if k["size"] >= beams] == [beams]
    assert 0.3 < res.valid.mean() < 1.0


def test_material_and_shape_indices_looked_up_on_the_device(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.lidar.scene_tables import material_table, scene_tables, shape_table

    L = _load(write_scene)
    tables = scene_tables(L.scene)
    assert scene_tables(L.scene) is tables  # cached per scene
    assert tables.material_names == material_table(L.scene)[0] == ["dark", "grey"]
    assert tables.shape_names == shape_table(L.scene)[0]
    res = scan(L.scene, L.lidars[0])
    ball, floor = tables.shape_names.index("ball"), tables.shape_names.index("floor")
    assert set(np.unique(res.shape_index)) == {-1, ball, floor}
    np.testing.assert_array_equal(res.material[res.shape_index == ball], 1)
    np.testing.assert_array_equal(res.material[res.shape_index == floor], 0)
    np.testing.assert_array_equal(res.material[~res.hit], -1)


def test_draws_left_out_at_zero_sigma_keep_the_others(variant, write_scene):
    """Without range noise the range draw is left out of the kernel; the stream advances as
    before, so dropout and intensity noise draw the same values."""
    from nidar_mi.lidar.scan import scan

    noisy = _load(write_scene)
    exact = _load(write_scene, noise_r=0.0)
    a = scan(noisy.scene, noisy.lidars[0], seed=4)
    b = scan(exact.scene, exact.lidars[0], seed=4)
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_array_equal(a.intensity, b.intensity)
    assert np.abs(a.range - b.range)[a.valid].max() > 0.01
    c = scan(exact.scene, exact.lidars[0], seed=5)
    assert not np.array_equal(b.valid, c.valid)
