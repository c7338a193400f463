"""``assign`` on awkward input: non-finite points, images of every PNG colour type, the
renderer's own calibration file, and the input's per-point columns carried to the outputs."""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np
import pytest

from nidar_mi.io.images import write_png
from nidar_mi.io.las import read_las
from nidar_mi.io.points import read_npz, read_ply, write_ply
from nidar_mi.nidar.pipeline import shipped_weights_dir

pytestmark = pytest.mark.skipif(
    not (shipped_weights_dir() / "irnet.safetensors").is_file(), reason="no shipped weights"
)


def _png16(path, rgb16: np.ndarray) -> None:
    """A 16-bit RGB PNG (colour type 2, bit depth 16), which Pillow cannot write."""
    h, w, _ = rgb16.shape
    rows = b"".join(b"\x00" + rgb16[y].astype(">u2").tobytes() for y in range(h))

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    ihdr = struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0)
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows))
    path.write_bytes(data + chunk(b"IEND", b""))


def _outputs(out) -> dict:
    return {
        "npz": read_npz(out / "points.npz"),
        "ply": read_ply(out / "points.ply"),
        "las": read_las(out / "points.las"),
    }


# ------------------------------------------------------------------------ 9: NaN and infinity


def test_non_finite_points_are_dropped_with_a_count(tmp_path, call, assign_inputs):
    cloud = read_ply(assign_inputs[1])
    n = len(cloud["xyz"])
    xyz = cloud["xyz"].copy()
    xyz[3, 0] = np.nan
    xyz[7, 2] = np.inf
    xyz[11, 1] = -np.inf
    intensity = cloud["intensity"].copy()
    intensity[20] = np.nan
    path = tmp_path / "holes.ply"
    write_ply(path, {"xyz": xyz, "intensity": intensity})
    argv = ["--points", path, *assign_inputs[2:], "-o", tmp_path / "out"]
    status, out, err = call("assign", argv)
    assert status == 0, err
    lines = err.strip().splitlines()  # then the unknown sensor's warning
    assert lines[0] == f"warning: {path}: dropped 4 of {n} points with NaN or infinite values"
    assert lines[1].startswith("warning: unknown sensor") and len(lines) == 2
    assert out.startswith("profile: generic-compensated (")  # the profile used, on stdout
    keep = np.ones(n, bool)
    keep[[3, 7, 11, 20]] = False
    for fmt, p in _outputs(tmp_path / "out").items():
        assert len(p["xyz"]) == n - 4, fmt
        np.testing.assert_array_equal(p["xyz"], xyz[keep], err_msg=fmt) if fmt != "las" else None
        for key, value in p.items():
            if np.asarray(value).dtype.kind == "f":
                assert np.isfinite(value).all(), (fmt, key)


def test_a_cloud_without_finite_points_is_refused(tmp_path, call, one_error_line, assign_inputs):
    path = tmp_path / "nan.ply"
    write_ply(path, {"xyz": np.full((5, 3), np.nan, np.float32)})
    status, _, err = call("assign", ["--points", path, *assign_inputs[2:], "-o", tmp_path / "o"])
    one_error_line(status, err, "none of its 5 points")
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------------ 10: image types


def test_every_png_colour_type_gives_the_rgb_result(tmp_path, call, assign_inputs):
    from nidar_mi.io.images import read_png

    rgb = read_png(assign_inputs[-1])
    grey = np.round(rgb.mean(axis=2)).astype(np.uint8)
    variants = {
        "rgba.png": lambda p: write_png(p, np.dstack([rgb, np.full(rgb.shape[:2], 7, np.uint8)])),
        "rgb16.png": lambda p: _png16(p, rgb.astype(np.uint16) * 257),
        "grey.png": lambda p: write_png(p, grey),
        "grey_as_rgb.png": lambda p: write_png(p, np.dstack([grey] * 3)),
        "grey16.png": lambda p: (
            __import__("PIL.Image").Image.fromarray(grey.astype(np.uint16) * 257).save(p)
        ),
    }
    results = {}
    for name, write in {"rgb.png": lambda p: write_png(p, rgb), **variants}.items():
        write(tmp_path / name)
        argv = [*assign_inputs[:4], "--image", tmp_path / name, "-o", tmp_path / name[:-4]]
        status, _, err = call("assign", argv + ["--formats", "npz"])
        assert status == 0, err
        assert ("greyscale" in err) == (name in ("grey.png", "grey16.png")), (name, err)
        results[name] = read_npz(tmp_path / name[:-4] / "points.npz")["intensity_nidar"]
    np.testing.assert_array_equal(results["rgba.png"], results["rgb.png"])
    np.testing.assert_array_equal(results["rgb16.png"], results["rgb.png"])
    np.testing.assert_array_equal(results["grey.png"], results["grey_as_rgb.png"])
    np.testing.assert_array_equal(results["grey16.png"], results["grey_as_rgb.png"])
    # the colours reach the network: its dense head differs between the colour and grey image
    # (the profile's steps may map both R maps of these few points to the same intensities)
    dense = {}
    for name in ("rgb.png", "grey.png"):
        argv = [*assign_inputs[:4], "--image", tmp_path / name, "-o", tmp_path / f"d_{name[:-4]}"]
        assert call("assign", argv + ["--formats", "npz", "--branch", "I_hat"])[0] == 0
        dense[name] = read_npz(tmp_path / f"d_{name[:-4]}" / "points.npz")["intensity_nidar"]
    assert not np.array_equal(dense["grey.png"], dense["rgb.png"])


def test_an_image_of_the_wrong_size_names_both_sizes(tmp_path, call, one_error_line, assign_inputs):
    write_png(tmp_path / "wide.png", np.zeros((24, 40, 3), np.uint8))
    argv = [*assign_inputs[:4], "--image", tmp_path / "wide.png", "-o", tmp_path / "o"]
    status, _, err = call("assign", argv)
    one_error_line(status, err, "image 40x24 does not match camera 'front' 32x24")


# ------------------------------------------------------------------------ 15: render files


def test_the_renderers_own_files_and_columns(tmp_path, call, tiny_scene, variant):
    render = tmp_path / "render"
    status, _, err = call("render", [tiny_scene, "-o", render, "-q", "--spp", "1"])
    assert status == 0, err
    argv = ["--points", render / "lidar/points.npz", "--calib", render / "cam/calib.json"]
    argv += ["--image", render / "cam/rgb.png", "-o", tmp_path / "out"]
    status, out, err = call("assign", argv)
    assert status == 0, err
    # the simulator's own cloud: its own profile, no warning of an unknown sensor
    assert "profile: sim-905 (" in out and "unknown sensor" not in err
    src = read_npz(render / "lidar/points.npz")
    outs = _outputs(tmp_path / "out")
    for fmt, p in outs.items():
        for key in ("ring", "column", "material", "reflectance", "range", "cos_incidence"):
            np.testing.assert_array_equal(p[key], src[key], err_msg=f"{fmt} {key}")
        assert list(p["material_names"]) == list(src["material_names"]), fmt
        assert p["nidar_observed"].any() and p["intensity_nidar"].dtype == np.float32


# --------------------------------------------------------------- --kitti: the newcomer's path


@pytest.fixture()
def fresh_user(tmp_path, monkeypatch):
    """A user without NIDAR_MI_DATA, in a folder with no ``../shared/data``, with an empty
    cache of their own."""
    monkeypatch.delenv("NIDAR_MI_DATA", raising=False)
    monkeypatch.setenv("NIDAR_MI_CACHE", str(tmp_path / "cache"))
    home = tmp_path / "home" / "work"
    home.mkdir(parents=True)
    monkeypatch.chdir(home)
    return tmp_path


def test_assign_kitti_needs_only_its_flags_and_never_fits_on_its_frame(
    fresh_user, call, monkeypatch
):
    """``assign --kitti DIR --frame F`` used to need NIDAR_MI_DATA, then fit kitti-hdl64e on
    every frame it found, F among them (a leak into the result). It fits on the other frames of
    DIR, once per set of frames."""
    from nidar_mi.datasets import profile_fitting
    from tests.helpers.synthetic_kitti import make_kitti

    kitti = make_kitti(fresh_user / "kitti", frames=4, cols=90)
    fitted = []
    fit = profile_fitting.fit_scan_profile

    def spy(model, scans, **kw):
        fitted.append(sorted(s.name for s in scans))
        return fit(model, scans, **kw)

    monkeypatch.setattr(profile_fitting, "fit_scan_profile", spy)
    argv = ["--kitti", kitti, "--frame", "000002", "--formats", "npz"]
    status, out, err = call("assign", [*argv, "-o", fresh_user / "a"])
    assert status == 0, err
    assert fitted == [["000000", "000001", "000003"]]
    assert "fitting the kitti-hdl64e profile on 3 other frames" in err and "(not on 000002" in err
    (cached,) = (fresh_user / "cache" / "profiles").glob("kitti-hdl64e-*.json")
    assert json.loads(cached.read_text())["provenance"]["frames"] == ["000000", "000001", "000003"]
    status, _, err = call("assign", [*argv, "-o", fresh_user / "b"])  # the cached profile
    assert status == 0 and "fitting" not in err and len(fitted) == 1, err
    a, b = (read_npz(fresh_user / d / "points.npz") for d in "ab")
    np.testing.assert_array_equal(a["intensity_nidar"], b["intensity_nidar"])
    status, _, err = call("assign", ["--kitti", kitti, "--frame", "000000", "-o", fresh_user / "c"])
    assert status == 0 and fitted[-1] == ["000001", "000002", "000003"], err


def test_the_frames_of_a_long_drive_are_chosen_once(tmp_path):
    """Ten frames evenly spread over the folder; the assigned frame's neighbour replaces it, so
    that most frames of a drive share one profile."""
    from nidar_mi.datasets.sensor_profiles import KITTI_ASSIGN_FRAMES, _assign_frames

    ids = [f"{i:06d}" for i in range(78)]
    base = _assign_frames(ids, "000005")
    assert len(base) == KITTI_ASSIGN_FRAMES and "000005" not in base
    assert _assign_frames(ids, "000040") == base  # not among the ten: the same ten
    swapped = _assign_frames(ids, base[3])
    assert base[3] not in swapped and len(set(swapped) - set(base)) == 1
    assert _assign_frames(ids[:4], "000001") == ["000000", "000002", "000003"]


def test_assign_kitti_with_a_greyscale_image(tmp_path, call):
    """Used to fail after the model had loaded; ``--points`` takes a grey image as R = G = B with
    a warning, and so does ``--kitti``."""
    from PIL import Image

    from tests.helpers.synthetic_kitti import make_kitti

    kitti = make_kitti(tmp_path / "kitti", frames=1, cols=90)
    png = kitti / "image_2" / "000000.png"
    Image.open(png).convert("L").save(png)
    argv = ["--kitti", kitti, "--frame", "000000", "--profile", "generic-compensated"]
    status, _, err = call("assign", [*argv, "-o", tmp_path / "out", "--formats", "npz"])
    assert status == 0, err
    assert (
        f"warning: {png} is a greyscale image (L): NIDAR, trained on colour images, sees it" in err
    )
    assert read_npz(tmp_path / "out" / "points.npz")["nidar_observed"].any()


def test_assign_kitti_with_a_resized_image(tmp_path, call, one_error_line):
    """A half-size image used to give 1.8 % of the points observed (16 % normally), status 0."""
    from PIL import Image

    from tests.helpers.synthetic_kitti import make_kitti

    kitti = make_kitti(tmp_path / "kitti", frames=1, cols=90)
    png = kitti / "image_2" / "000000.png"
    Image.open(png).resize((621, 188)).save(png)
    argv = ["--kitti", kitti, "--frame", "000000", "--profile", "generic-compensated"]
    status, _, err = call("assign", [*argv, "-o", tmp_path / "out"])
    one_error_line(status, err, "is 621x188 but calib P2's principal point (600, 180) is far from")
    assert not (tmp_path / "out").exists()
