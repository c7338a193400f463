"""``python -m nidar_mi.render`` end to end: every file and its schema, determinism, bad input."""

import json
import os
import subprocess
import sys

import laspy
import numpy as np
import pytest

from nidar_mi.io.ownership import RECORD

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STREET = os.path.join(REPO, "scenes", "street.xml")
SMALL = ["-D", "width=48", "-D", "height=27", "-D", "cols=256", "--spp", "2"]


def run_cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "nidar_mi.render", *args],
        capture_output=True,
        text=True,
        cwd=cwd or REPO,
        timeout=600,
    )


@pytest.fixture(scope="module")
def street_out(tmp_path_factory):
    out = tmp_path_factory.mktemp("render") / "street"
    r = run_cli(STREET, "-o", str(out), "--seed", "3", "-q", *SMALL)
    assert r.returncode == 0, r.stderr
    return out


def test_every_file_is_written(street_out):
    expected = {
        "manifest.json",
        "lidar_top/points.npz",
        "lidar_top/points.ply",
        "lidar_top/points.las",
        "lidar_top/points.bin",
        "lidar_top/range_image.exr",
        "lidar_top/range.png",
        "lidar_top/intensity.png",
        "cam_front/rgb.png",
        "cam_front/rgb.exr",
        "cam_front/nir.png",
        "cam_front/nir.exr",
        "cam_front/depth.exr",
        "cam_front/reflectance.exr",
        "cam_front/albedo.exr",
        "cam_front/surface_reflectance.exr",
        "cam_front/calib.json",
    }
    found = {str(p.relative_to(street_out)) for p in street_out.rglob("*") if p.is_file()}
    assert found == expected | {RECORD}
    assert not [p for p in street_out.parent.iterdir() if ".partial-" in p.name]


def test_points_schema_and_formats_agree(street_out):
    from nidar_mi.io.kitti import read_kitti_bin
    from nidar_mi.io.las import read_las
    from nidar_mi.io.points import read_npz, read_ply

    p = read_npz(street_out / "lidar_top/points.npz")
    n = len(p["range"])
    assert n > 1000
    schema = {
        "xyz": (np.float32, (n, 3)),
        "xyz_world": (np.float32, (n, 3)),
        "range": (np.float32, (n,)),
        "intensity": (np.float32, (n,)),
        "reflectance": (np.float32, (n,)),
        "cos_incidence": (np.float32, (n,)),
        "ring": (np.uint16, (n,)),
        "column": (np.uint32, (n,)),
        "material": (np.int32, (n,)),
    }
    for key, (dtype, shape) in schema.items():
        assert p[key].dtype == dtype and p[key].shape == shape, key
    names = list(p["material_names"])
    assert {"asphalt", "brick_red", "vegetation", "car_paint_red"} <= set(names)
    assert np.all((p["material"] >= 0) & (p["material"] < len(names)))
    assert np.all(np.isfinite(p["intensity"])) and np.all(p["intensity"] >= 0)
    # the range runs from the beam's origin (the per-laser table's, 0.1-0.2 m off the axis)
    from nidar_mi.lidar.config import LidarConfig

    cfg = LidarConfig.from_mapping("l", {"preset": "hdl64e", "horizontal_resolution": 256})
    direction, origin = cfg.pattern.beams()
    beam = p["ring"].astype(np.int64) * 256 + p["column"]
    np.testing.assert_allclose(np.linalg.norm(p["xyz"] - origin[beam], axis=1), p["range"], 1e-5)
    np.testing.assert_allclose(
        p["xyz"] - origin[beam], direction[beam] * p["range"][:, None], 0, 2e-5
    )
    # the rig is at z = 1.73 m: world = lidar frame + translation
    np.testing.assert_allclose(p["xyz_world"], p["xyz"] + [0, 0, 1.73], atol=1e-4)

    # fixed per-sensor encodings: full scale = g · 1 m⁻² (raw mode, gain 1) = 1
    xyz, inten = read_kitti_bin(street_out / "lidar_top/points.bin")
    np.testing.assert_array_equal(xyz, p["xyz"])
    np.testing.assert_array_equal(inten, np.clip(p["intensity"], 0.0, 1.0))
    assert (p["intensity"] > 1.0).any()  # close, bright returns saturate in the [0, 1] encoding
    ply = read_ply(street_out / "lidar_top/points.ply")
    np.testing.assert_array_equal(ply["xyz"], p["xyz"])
    np.testing.assert_array_equal(ply["reflectance"], p["reflectance"])
    las = read_las(street_out / "lidar_top/points.las")
    np.testing.assert_allclose(las["xyz"], p["xyz"], atol=1e-4)
    counts = np.asarray(laspy.read(street_out / "lidar_top/points.las").intensity)
    want = np.round(np.clip(p["intensity"].astype(np.float64), 0, 1) * 65535)
    np.testing.assert_array_equal(counts, want)
    np.testing.assert_allclose(las["intensity"], np.minimum(p["intensity"], 1.0), atol=0.51 / 65535)


def test_range_image_and_camera_outputs(street_out):
    from nidar_mi.io.images import read_exr, read_png
    from nidar_mi.io.points import read_npz

    p = read_npz(street_out / "lidar_top/points.npz")
    img = read_exr(street_out / "lidar_top/range_image.exr")
    assert img["range"].shape == (64, 256)
    valid = img["valid"] > 0.5
    assert valid.sum() == len(p["range"])
    np.testing.assert_array_equal(img["range"][p["ring"], p["column"]], p["range"])
    np.testing.assert_array_equal(img["intensity"][p["ring"], p["column"]], p["intensity"])

    rgb = read_png(street_out / "cam_front/rgb.png")
    assert rgb.shape == (27, 48, 3) and rgb.dtype == np.uint8
    nir = read_exr(street_out / "cam_front/nir.exr")
    depth = read_exr(street_out / "cam_front/depth.exr")
    (nir_img,) = nir.values()
    (z,) = depth.values()
    assert nir_img.shape == z.shape == (27, 48)
    assert np.isfinite(nir_img).all() and nir_img.max() > 0
    calib = json.loads((street_out / "cam_front/calib.json").read_text())
    K = np.array(calib["K"])
    # 80 deg horizontal fov over 48 px: fx = 24 / tan(40 deg)
    assert K[0, 0] == pytest.approx(24 / np.tan(np.deg2rad(40)), rel=1e-4)
    assert K[0, 2] == pytest.approx(23.5, abs=1e-3) and K[1, 2] == pytest.approx(13.0, abs=1e-3)
    # LiDAR points seen by the camera project onto pixels whose depth matches their z
    T = np.array(calib["T_cam_lidar"]["lidar_top"])
    pc = p["xyz"].astype(np.float64) @ T[:3, :3].T + T[:3, 3]
    front = pc[:, 2] > 1.0
    uv = pc[front, :2] / pc[front, 2:3] @ K[:2, :2].T + K[:2, 2]
    inside = (uv[:, 0] > 0) & (uv[:, 0] < 47) & (uv[:, 1] > 0) & (uv[:, 1] < 26)
    px = np.round(uv[inside]).astype(int)
    zc = pc[front][inside, 2]
    zr = z[px[:, 1], px[:, 0]]
    agree = np.abs(zr - zc) < 0.05 * zc + 0.1
    assert inside.sum() > 100 and agree.mean() > 0.8


def test_manifest(street_out, variant):
    m = json.loads((street_out / "manifest.json").read_text())
    assert m["variant"] == variant and m["seed"] == 3
    lid = m["lidars"]["lidar_top"]
    assert lid["parameters"]["preset"] == "hdl64e" and lid["parameters"]["rings"] == 64
    assert lid["parameters"]["horizontal_resolution"] == 256
    assert lid["rays"] == 64 * 256 and 0 < lid["returns"] <= lid["hits"] <= lid["rays"]
    assert {"raycast", "bsdf", "detect", "readback"} <= set(lid["timings_s"])
    assert set(m["versions"]) >= {"nidar_mi", "mitsuba", "drjit"}
    assert m["versions"]["mitsuba"] == "3.9.1"


def test_same_seed_same_files_other_seed_other_noise(street_out, tmp_path):
    from nidar_mi.io.points import read_npz

    a = tmp_path / "a"
    b = tmp_path / "b"
    for out, seed in ((a, "3"), (b, "4")):
        r = run_cli(STREET, "-o", str(out), "--seed", seed, "-q", "--no-cameras", *SMALL)
        assert r.returncode == 0, r.stderr
    for f in ("points.bin", "points.ply"):
        assert (a / "lidar_top" / f).read_bytes() == (street_out / "lidar_top" / f).read_bytes()
    pa, pb = read_npz(a / "lidar_top/points.npz"), read_npz(b / "lidar_top/points.npz")
    assert len(pa["range"]) != len(pb["range"]) or not np.array_equal(pa["range"], pb["range"])


BAD_XML = '<scene version="3.0.0"><shape type="sphere"'
NO_LIDAR = '<scene version="3.0.0"><shape type="sphere"/></scene>'
BAD_PARAM = '<scene version="3.0.0"><sensor type="lidar" id="l"><float name="dropout" value="2"/></sensor></scene>'


@pytest.mark.parametrize(
    "content, args, needle",
    [
        (None, [], "no such scene file"),
        (BAD_XML, [], "bad.xml"),
        (NO_LIDAR, [], "no lidar sensor"),
        (BAD_PARAM, [], "parameter 'dropout'"),
        (NO_LIDAR, ["--formats", "npz,xyz"], "--formats"),
        (NO_LIDAR, ["--spp", "0"], "--spp"),
        (NO_LIDAR, ["-D", "novalue"], "NAME=VALUE"),
    ],
)
def test_bad_input_one_line_no_output(tmp_path, content, args, needle):
    scene = tmp_path / "bad.xml"
    if content is not None:
        scene.write_text(content)
    out = tmp_path / "out"
    r = run_cli(str(scene), "-o", str(out), *args)
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir()] == (["bad.xml"] if content is not None else [])


def test_two_lidars_in_one_scene(tmp_path):
    """Several lidar sensors per scene: each gets its own folder, parameters and pose."""
    from nidar_mi.io.points import read_npz

    scene = tmp_path / "two.xml"
    scene.write_text(
        """<scene version="3.0.0">
        <sensor type="lidar" id="front"><string name="preset" value="vlp16"/>
            <integer name="horizontal_resolution" value="360"/>
            <transform name="to_world"><translate x="1" z="1.5"/></transform></sensor>
        <sensor type="lidar" id="rear"><string name="elevation_angles" value="0, -5"/>
            <integer name="horizontal_resolution" value="180"/><float name="wavelength" value="1550"/>
            <transform name="to_world"><rotate z="1" angle="180"/><translate x="-1" z="0.5"/></transform></sensor>
        <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.3, 1700:0.6"/></bsdf>
        <shape type="sphere" id="dome"><float name="radius" value="20"/><ref id="grey"/>
            <boolean name="flip_normals" value="true"/></shape>
    </scene>"""
    )
    out = tmp_path / "out"
    r = run_cli(str(scene), "-o", str(out), "-q", "--formats", "npz")
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "manifest.json").read_text())
    assert set(m["lidars"]) == {"front", "rear"} and m["cameras"] == {}
    assert m["lidars"]["front"]["rays"] == 16 * 360 and m["lidars"]["rear"]["rays"] == 2 * 180
    assert m["lidars"]["rear"]["parameters"]["wavelength"] == 1550.0
    front = read_npz(out / "front/points.npz")
    rear = read_npz(out / "rear/points.npz")
    # every beam hits the dome of radius 20 around the origin: world points lie on it
    for p, n in ((front, 16 * 360), (rear, 2 * 180)):
        assert len(p["range"]) == n
        np.testing.assert_allclose(np.linalg.norm(p["xyz_world"], axis=1), 20.0, rtol=1e-4)
    # ρ at each sensor's wavelength (linear spectrum 0.3 at 360 nm .. 0.6 at 1700 nm)
    np.testing.assert_allclose(front["reflectance"], 0.3 + 0.3 * (905 - 360) / 1340, rtol=1e-4)
    np.testing.assert_allclose(rear["reflectance"], 0.3 + 0.3 * (1550 - 360) / 1340, rtol=1e-4)


def test_pcd_laz_formats_and_semantic_labels(tmp_path):
    """``--formats npz,pcd,las,laz`` writes the same points: the PCD file holds the npz's, the
    LAZ file (lazrs) the LAS file's; the street's labels follow its shapes (every asphalt return
    is road, every brick return building, every car-paint return car)."""
    from nidar_mi.io.las import read_las
    from nidar_mi.io.pcd import read_pcd
    from nidar_mi.io.points import read_npz

    out = tmp_path / "street"
    formats = ["--formats", "npz,pcd,las,laz"]
    r = run_cli(STREET, "-o", str(out), "-q", "--no-cameras", *formats, *SMALL)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (out / "lidar_top").glob("points.*")) == [
        "points.las",
        "points.laz",
        "points.npz",
        "points.pcd",
    ]
    npz = read_npz(out / "lidar_top/points.npz")
    pcd = read_pcd(out / "lidar_top/points.pcd")
    assert sorted(pcd) == sorted(npz)
    for key, value in npz.items():
        np.testing.assert_array_equal(pcd[key], value, err_msg=key)
    las, laz = read_las(out / "lidar_top/points.las"), read_las(out / "lidar_top/points.laz")
    assert sorted(laz) == sorted(las) and len(laz["xyz"]) == len(npz["xyz"]) > 1000
    for key, value in las.items():
        np.testing.assert_array_equal(laz[key], value, err_msg=key)
    assert laspy.read(out / "lidar_top/points.laz").header.are_points_compressed
    names = list(npz["material_names"])
    material = np.array(names)[npz["material"]]
    for mat, label in (("asphalt", 40), ("brick_red", 50), ("car_paint_red", 10)):
        assert (material == mat).sum() > 0, mat
        assert np.all(npz["label"][material == mat] == label), mat
    car = npz["instance_names"][npz["instance"][npz["label"] == 10]]
    assert set(car) == {"car"}  # body, cabin and wheels are one instance
    assert np.all(npz["instance"] > 0)
