"""``render`` outputs that the contract and the readers rely on: a folder replaced whole, fixed
intensity encodings per sensor, previews that read like the camera, the range image masked by
``valid``, the seed recorded, one NIR band per LiDAR wavelength, thin-lens cameras, options that
only apply with ``--intensity nidar``, and one warning line for the RGB twin."""

from __future__ import annotations

import json
import subprocess
import sys

import laspy
import numpy as np
import pytest

from nidar_mi.io.images import read_exr, read_png
from nidar_mi.io.kitti import read_kitti_bin
from nidar_mi.io.ownership import RECORD
from nidar_mi.io.points import read_npz
from nidar_mi.io.range_preview import preview_columns

SKY = "360:0.5, 1700:1.5"  # linear in λ: the band average at λ is its value at λ


def _sky(wl: float) -> float:
    return 0.5 + (wl - 360.0) / 1340.0


def _scene(tmp_path, *, lidar_extra="", second_lidar=False, camera="perspective", name="s.xml"):
    """A LiDAR at the origin, a camera looking along +x, a grey wall on the left (y = +5 m)
    and a sky whose radiance is linear in λ."""
    second = (
        """<sensor type="lidar" id="b_lidar"><string name="elevation_angles" value="0"/>
            <integer name="horizontal_resolution" value="36"/>
            <float name="wavelength" value="1550"/></sensor>"""
        if second_lidar
        else ""
    )
    lens = (
        '<float name="aperture_radius" value="0.01"/><float name="focus_distance" value="8"/>'
        if camera == "thinlens"
        else ""
    )
    xml = f"""<?xml version="1.0"?>
<scene version="3.0.0">
    <sensor type="lidar" id="a_lidar">
        <string name="elevation_angles" value="10, 0, -10"/>
        <integer name="horizontal_resolution" value="72"/>
        {lidar_extra}
    </sensor>
    {second}
    <sensor type="{camera}" id="cam">
        <float name="fov" value="90"/>{lens}
        <transform name="to_world"><lookat origin="0, 0, 0" target="1, 0, 0" up="0, 0, 1"/></transform>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/></film>
    </sensor>
    <emitter type="constant"><spectrum name="radiance" value="{SKY}"/></emitter>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.3, 1700:0.6"/></bsdf>
    <shape type="cube" id="wall"><ref id="grey"/>
        <transform name="to_world"><scale x="10" y="0.1" z="4"/><translate y="5"/></transform>
    </shape>
</scene>
"""
    path = tmp_path / name
    path.write_text(xml)
    return path


def _render(call, scene, out, *extra):
    status, _, err = call("render", [scene, "-o", out, "-q", "--spp", "2", *extra])
    assert status == 0, err
    return json.loads((out / "manifest.json").read_text())


# ------------------------------------------------------------------------ 6: replaced whole


def test_a_rerender_replaces_the_folder_whole(tmp_path, call, variant):
    scene, out = _scene(tmp_path), tmp_path / "out"
    _render(call, scene, out, "--formats", "npz,ply,las")
    m = _render(call, scene, out, "--formats", "npz", "--no-cameras")
    found = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert found == sorted([*m["files"], RECORD])  # no stale points.ply, no camera folder
    assert not (out / "cam").exists() and not (out / "a_lidar" / "points.ply").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_foreign_file_is_never_removed(tmp_path, call, one_error_line, snapshot, variant):
    scene, out = _scene(tmp_path), tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    before = snapshot(out)
    for extra in ([], ["--overwrite"]):
        status, _, err = call("render", [scene, "-o", out, "-q", "--spp", "1", *extra])
        one_error_line(status, err, "holds 1 file(s) that 'render' did not write (notes.txt)")
        assert snapshot(out) == before


def test_verbose_sequence_logs_one_line_per_frame(tmp_path, call, variant):
    """Long sequences used to log nothing per frame, even with ``-v``."""
    scene = _scene(tmp_path)
    traj = tmp_path / "t.tum"
    traj.write_text("".join(f"{t:.1f} {t:.1f} 0 0 0 0 0 1\n" for t in (0.0, 0.1, 0.2, 0.3, 0.4)))
    argv = [
        scene,
        "-o",
        tmp_path / "seq",
        "-v",
        "--spp",
        "1",
        "--trajectory",
        traj,
        "--frames",
        "3",
    ]
    status, _, err = call("render", argv)
    assert status == 0, err
    frames = [ln for ln in err.splitlines() if "nidar_mi.sequence: frame " in ln]
    assert [ln.split("frame ")[1].split()[0] for ln in frames] == ["1/3", "2/3", "3/3"]
    assert all(ln.startswith("DEBUG ") and " rendered in " in ln for ln in frames)


# ------------------------------------------------------------------------ 16: encodings, previews


def test_las_and_bin_intensity_scales_are_fixed_per_sensor(tmp_path, call, variant):
    """gain 2, compensated: full scale 2 whatever the frame holds; noise makes frames differ."""
    extra = (
        '<float name="gain" value="2"/><string name="intensity_mode" value="compensated"/>'
        '<float name="noise_intensity_std" value="1.0"/>'
    )
    scene = _scene(tmp_path, lidar_extra=extra)
    for seed in ("1", "2"):
        out = tmp_path / f"s{seed}"
        _render(call, scene, out, "--seed", seed, "--no-cameras")
        p = read_npz(out / "a_lidar/points.npz")
        assert p["intensity"].max() > 2.0 and len(p["intensity"]) > 20  # some saturate
        las = laspy.read(out / "a_lidar/points.las")
        want = np.round(np.clip(p["intensity"].astype(np.float64) / 2.0, 0, 1) * 65535)
        np.testing.assert_array_equal(np.asarray(las.intensity), want)
        _, unit = read_kitti_bin(out / "a_lidar/points.bin")
        np.testing.assert_array_equal(unit, np.clip(p["intensity"] / np.float32(2.0), 0, 1))
    out = tmp_path / "raw"
    _render(call, scene, out, "--seed", "1", "--no-cameras", "--bin-intensity", "raw")
    _, raw = read_kitti_bin(out / "a_lidar/points.bin")
    np.testing.assert_array_equal(raw, read_npz(out / "a_lidar/points.npz")["intensity"])


def test_range_image_reflectance_is_masked_by_valid(tmp_path, call, variant):
    scene = _scene(tmp_path, lidar_extra='<float name="dropout" value="0.5"/>')
    out = tmp_path / "out"
    _render(call, scene, out, "--no-cameras")
    img = read_exr(out / "a_lidar/range_image.exr")
    valid = img["valid"] > 0.5
    assert valid.sum() > 5 and (~valid).sum() > 5
    assert not img["reflectance"][~valid].any()
    rho_905 = 0.3 + 0.3 * (905 - 360) / 1340
    np.testing.assert_allclose(img["reflectance"][valid], rho_905, rtol=1e-4)


def test_preview_columns_read_like_the_camera():
    """Azimuth decreases left to right; on a 360° scan forward (0°) is in the middle."""
    cols = 8
    az = (np.arange(cols) + 0.5) * 360.0 / cols  # the scan order: counter-clockwise from +x
    order, shown = preview_columns(az)
    np.testing.assert_allclose(shown, [157.5, 112.5, 67.5, 22.5, -22.5, -67.5, -112.5, -157.5])
    assert list(order) == [3, 2, 1, 0, 7, 6, 5, 4]
    order, shown = preview_columns([20.0, 60.0, 100.0])  # a 120° scan: mirrored only
    assert list(order) == [2, 1, 0]


def test_preview_shows_a_wall_on_the_left_left_of_centre(tmp_path, call, variant):
    out = tmp_path / "out"
    _render(call, _scene(tmp_path), out, "--no-cameras")
    png = read_png(out / "a_lidar/range.png")[..., :3].astype(int)
    # the image area: coloured pixels are returns (not black, not the white page)
    colourful = (png.max(axis=2) - png.min(axis=2)) > 40
    ys, xs = np.nonzero(colourful[: png.shape[0] // 3])  # above the colour bar
    assert xs.size > 0
    centre = png.shape[1] / 2
    assert np.all(xs < centre), "the wall at +y (left) must be left of the preview's centre"
    assert png.shape[0] > 3 * 8 + 100  # the rings, the azimuth axis and the colour bar


# ------------------------------------------------------------------------ 17: seed, NIR, lenses


def test_manifest_records_the_seeds_used(tmp_path, call, variant):
    m = _render(call, _scene(tmp_path), tmp_path / "a", "--no-cameras")
    assert (m["seed"], m["seed_source"]) == (0, "default")
    assert m["lidars"]["a_lidar"]["parameters"]["seed"] == 0
    m = _render(call, _scene(tmp_path), tmp_path / "b", "--no-cameras", "--seed", "7")
    assert (m["seed"], m["seed_source"]) == (7, "--seed")
    assert m["lidars"]["a_lidar"]["parameters"]["seed"] == 7


@pytest.mark.parametrize("camera", ["perspective", "thinlens"])
def test_one_nir_band_per_lidar_wavelength(tmp_path, call, camera, variant):
    out = tmp_path / "out"
    m = _render(call, _scene(tmp_path, second_lidar=True, camera=camera), out)
    assert m["nir_wavelengths_nm"] == [905.0, 1550.0]  # the first LiDAR by id first
    calib = json.loads((out / "cam/calib.json").read_text())
    assert calib["nir_images"] == {"905": "nir.exr", "1550": "nir_1550nm.exr"}
    assert {"cam/nir_1550nm.exr", "cam/nir_1550nm.png", "cam/rgb.png"} <= set(m["files"])
    # the top-right pixels see only the sky: the band average of a radiance linear in λ
    for name, wl in (("nir.exr", 905.0), ("nir_1550nm.exr", 1550.0)):
        (band,) = read_exr(out / "cam" / name).values()
        np.testing.assert_allclose(band[:3, -3:], _sky(wl), rtol=2e-3)


def test_a_non_camera_sensor_is_named_in_a_warning(tmp_path, call, variant):
    scene = _scene(tmp_path)
    text = scene.read_text().replace(
        "<emitter",
        '<sensor type="radiancemeter" id="meter"><film type="hdrfilm">'
        '<integer name="width" value="1"/><integer name="height" value="1"/></film></sensor>'
        "\n    <emitter",
        1,
    )
    scene.write_text(text)
    status, _, err = call("render", [scene, "-o", tmp_path / "out", "-q", "--spp", "1"])
    assert status == 0
    assert err.count("\n") == 1 and "'meter' (RadianceMeter) not rendered" in err


@pytest.mark.parametrize(
    "extra, needle",
    [
        (["--weights", "w"], "--weights is used only with --intensity nidar"),
        (["--nidar-branch", "I_hat"], "--nidar-branch is used only with --intensity nidar"),
    ],
)
def test_nidar_options_need_nidar_intensity(tmp_path, call, one_error_line, extra, needle):
    status, _, err = call("render", [_scene(tmp_path), "-o", tmp_path / "out", *extra])
    one_error_line(status, err, needle)
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------ 14: RGB twin


def test_rgb_twin_warns_once_per_lidar(tmp_path):
    """In a fresh process (the warning is given once per material and process)."""
    r = subprocess.run(
        [sys.executable, "-m", "nidar_mi.render", "scenes/street.xml", "--rgb-twin", "-q"]
        + ["-o", str(tmp_path / "out"), "--spp", "1", "--no-cameras", "-D", "cols=256"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=str(__import__("pathlib").Path(__file__).resolve().parents[2]),
    )
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert (
        lines[0].startswith("warning: lidar 'lidar_top': ") and "materials are RGB-only" in lines[0]
    )
    assert "asphalt" in lines[0] and "vegetation" in lines[0]
