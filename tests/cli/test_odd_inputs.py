"""Odd inputs an adversarial user tried, each refused before any work with one ``error:`` line
(status 2, no traceback, nothing written): sensor poses that are not poses, option combinations
that cannot act, unbounded frames, rates and images, special files, outputs that cannot be
replaced, a disk that fills up."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from tests.cli.conftest import TINY_SCENE
from tests.helpers.synthetic_kitti import make_kitti

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LIDAR_POSE = '<transform name="to_world"><translate z="1"/></transform>'


def _scene(tmp_path, text: str, name: str = "odd.xml") -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _quick_render(call, scene, out, *extra):
    return call("render", [scene, "-o", out, "-q", "--spp", "1", "--no-cameras", *extra])


# ------------------------------------------------------------------------------ sensor poses

#: LiDAR poses that are no rotation and translation, with the words that name the problem.
#: A scale of 2 used to put the road at z = -1.81 m; 0 gave no return and status 0; a mirror was
#: accepted; NaN failed only after the scan, at the manifest.
BAD_POSES = {
    "scale 2": ('<scale value="2"/><translate z="1"/>', "scales by 2"),
    "scale 0": ('<scale value="0"/>', "collapses space (scale 0)"),
    "mirror": ('<scale x="-1"/><translate z="1"/>', "mirrors (det -1)"),
    "nan": ('<matrix value="nan 0 0 0 0 1 0 0 0 0 1 1 0 0 0 1"/>', "holds NaN or infinite values"),
    "shear": ('<matrix value="1 0.5 0 0 0 1 0 0 0 0 1 1 0 0 0 1"/>', "shears or scales unevenly"),
}


@pytest.mark.parametrize("case", list(BAD_POSES))
def test_a_lidar_pose_must_be_rigid(case, tmp_path, call, one_error_line, variant):
    transform, words = BAD_POSES[case]
    scene = _scene(
        tmp_path,
        TINY_SCENE.replace(LIDAR_POSE, f'<transform name="to_world">{transform}</transform>'),
    )
    status, _, err = _quick_render(call, scene, tmp_path / "out")
    one_error_line(status, err, f"lidar 'lidar': to_world {words}")
    assert "tolerance 0.0001" in err and not (tmp_path / "out").exists()


def test_a_rotated_lidar_pose_is_a_pose(tmp_path, call, variant):
    """A rotation written to 6 digits is inside the tolerance."""
    rotated = '<rotate z="1" angle="33.3"/><rotate x="1" angle="2.5"/><translate z="1"/>'
    scene = _scene(
        tmp_path,
        TINY_SCENE.replace(LIDAR_POSE, f'<transform name="to_world">{rotated}</transform>'),
    )
    assert _quick_render(call, scene, tmp_path / "out")[0] == 0


# ------------------------------------------------------------- options that cannot act


def test_empty_define_on_the_command_line(tmp_path, call, one_error_line, tiny_scene):
    status, _, err = _quick_render(call, tiny_scene, tmp_path / "out", "-D", "cols=")
    one_error_line(status, err, "-D cols= has no value")


def test_dual_returns_need_a_beam_divergence(tmp_path, call, one_error_line, variant):
    dual = '<string name="return_mode" value="dual"/>'
    scene = _scene(tmp_path, TINY_SCENE.replace(LIDAR_POSE, LIDAR_POSE + dual))
    status, _, err = _quick_render(call, scene, tmp_path / "out")
    one_error_line(status, err, "parameter 'return_mode' 'dual' needs beam_divergence > 0")
    beam = '<float name="beam_divergence" value="3"/>'
    scene = _scene(tmp_path, TINY_SCENE.replace(LIDAR_POSE, LIDAR_POSE + dual + beam), "ok.xml")
    assert _quick_render(call, scene, tmp_path / "out")[0] == 0


def test_a_profile_of_another_branch_is_refused_by_render(
    tmp_path, call, one_error_line, tiny_scene
):
    """``render --intensity nidar --profile p.json --nidar-branch I_hat`` with a profile fitted on
    R used to saturate at 1.0; ``assign`` refuses the same."""
    from nidar_mi.datasets.sensor_profiles import generic_profile

    profile = tmp_path / "p.json"
    profile.write_text(json.dumps(generic_profile("generic-compensated").to_dict()))
    argv = [tiny_scene, "-o", tmp_path / "out", "-q", "--intensity", "nidar"]
    status, _, err = call("render", [*argv, "--profile", profile, "--nidar-branch", "I_hat"])
    one_error_line(
        status, err, "--nidar-branch I_hat: profile generic-compensated maps the R branch"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("scale", ["nan", "-1", "0", "inf"])
def test_calibrate_intensity_scale_must_be_positive(
    scale, tmp_path, call, one_error_line, synthetic_data
):
    out = tmp_path / "p.json"
    status, _, err = call("calibrate", [synthetic_data, "-o", out, "--intensity-scale", scale])
    one_error_line(status, err, "--intensity-scale must be a finite number > 0")
    assert not out.exists()


def test_bin_intensity_without_a_bin_file(tmp_path, call, one_error_line, tiny_scene):
    argv = ["--bin-intensity", "raw", "--formats", "npz"]
    status, _, err = _quick_render(call, tiny_scene, tmp_path / "out", *argv)
    one_error_line(status, err, "--bin-intensity applies to the .bin points")


# ------------------------------------------------------------------- bounds, checked at once

#: Commands that used to run for minutes (or leave an empty OUT) before failing or not at all.
UNBOUNDED = {
    "scenegen frames": (
        "scenegen",
        ["--count", "1", "--kind", "city", "--frames", "100000000"],
        "--frames must lie in [2, 10000]",
    ),
    "scenegen rate": (
        "scenegen",
        ["--count", "1", "--kind", "city", "--frames", "20", "--rate", "0.0001"],
        "longer than 10 km",
    ),
    "drive frames": ("drive", ["--frames", "100000000"], "--frames must lie in [2, 10000]"),
    "drive speed": ("drive", ["--speed", "nan"], "--speed must lie in (0, 70] m/s"),
}


@pytest.mark.parametrize("case", list(UNBOUNDED))
def test_drives_are_bounded_before_any_work(case, tmp_path, call, one_error_line):
    command, argv, words = UNBOUNDED[case]
    out = tmp_path / "out"
    t0 = time.perf_counter()
    status, _, err = call(command, [*argv, "-o", out, "-q"])
    one_error_line(status, err, words)
    assert time.perf_counter() - t0 < 30 and not out.exists()


def _png_header(path, width: int, height: int) -> None:
    """A PNG that declares ``width`` x ``height`` pixels (and holds none)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b""))
        + chunk(b"IEND", b"")
    )


@pytest.mark.parametrize("side", [60000, 12000])
def test_a_decompression_bomb_is_refused(side, tmp_path, call, one_error_line):
    """A 60000 x 60000 PNG header used to end in a traceback (also with ``--skip-bad``); one of
    12000 x 10000 passed Pillow's hard limit with a warning only."""
    bomb = tmp_path / "bomb.png"
    _png_header(bomb, side, 10000 if side == 12000 else side)
    status, _, err = call("pseudo_nir", [bomb, "-o", tmp_path / "out", "-q"])
    one_error_line(status, err, f"{bomb}: an image of")
    assert "more than the 89,478,485 an image may have" in err and not (tmp_path / "out").exists()


def test_a_decompression_bomb_is_skipped(tmp_path, call, assign_inputs):
    bomb = tmp_path / "bomb.png"
    _png_header(bomb, 60000, 60000)
    out = tmp_path / "out"
    status, _, err = call("pseudo_nir", [bomb, assign_inputs[5], "-o", out, "-q", "--skip-bad"])
    assert status == 0, err
    assert [ln for ln in err.splitlines() if ln.startswith("warning: skipped")] == [
        f"warning: skipped {bomb}: an image of 3,600,000,000 pixels, more than the 89,478,485 an "
        "image may have (a decompression bomb?)"
    ]
    assert json.loads((out / "index.json").read_text())["images"][0]["input"].endswith("cam.png")


@pytest.mark.parametrize("value", ["banana", "-5G", "0", "nan"])
def test_a_bad_memory_setting_is_refused(
    value, tmp_path, call, one_error_line, tiny_scene, monkeypatch
):
    monkeypatch.setenv("NIDAR_MAX_MEMORY", value)
    status, _, err = _quick_render(call, tiny_scene, tmp_path / "out")
    one_error_line(status, err, "NIDAR_MAX_MEMORY: not a")
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------- special files


def _cli(args, timeout=120, **kw):
    return subprocess.run(
        [sys.executable, "-m", "nidar_mi.render", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=timeout,
        **kw,
    )


def test_a_fifo_as_the_scene_does_not_hang(tmp_path):
    fifo = tmp_path / "scene.xml"
    os.mkfifo(fifo)
    r = _cli([fifo, "-o", tmp_path / "out", "-q"], timeout=120)  # it used to wait for ever
    assert (
        r.returncode == 2
        and r.stderr.strip() == f"error: {fifo}: a named pipe (FIFO), not a scene file"
    )


def test_dev_zero_as_the_scene_says_what_it_is(tmp_path, call, one_error_line):
    status, _, err = _quick_render(call, "/dev/zero", tmp_path / "out")
    one_error_line(status, err, "/dev/zero: a character device, not a scene file")


def test_a_symlink_loop_as_the_scene(tmp_path, call, one_error_line):
    loop = tmp_path / "loop.xml"
    loop.symlink_to(loop)
    status, _, err = _quick_render(call, loop, tmp_path / "out")
    one_error_line(status, err, "is a symbolic link loop")


@pytest.mark.parametrize("kind", ["loop", "dangling"])
def test_an_output_link_that_leads_nowhere(kind, tmp_path, call, one_error_line, tiny_scene):
    out = tmp_path / "out"
    out.symlink_to(out if kind == "loop" else tmp_path / "nowhere")
    status, _, err = _quick_render(call, tiny_scene, out)
    words = "is a symbolic link loop" if kind == "loop" else "which does not exist"
    one_error_line(status, err, words)
    assert out.is_symlink() and not (tmp_path / "nowhere").exists()


def test_a_mount_point_as_the_output_is_refused_before_work(
    tmp_path, call, one_error_line, tiny_scene, monkeypatch
):
    """A mount point cannot be renamed over: it used to fail only at the end."""
    from nidar_mi.io import atomic

    mount = tmp_path / "mnt"
    mount.mkdir()
    real = os.path.ismount
    monkeypatch.setattr(atomic.os.path, "ismount", lambda p: os.fspath(p) == str(mount) or real(p))
    monkeypatch.setattr("nidar_mi.simulate.RenderSession.open", pytest.fail)
    status, _, err = _quick_render(call, tiny_scene, mount)
    one_error_line(status, err, "it is a mount point, which cannot be replaced whole")


@pytest.mark.parametrize(
    "command, argv",
    [
        ("render", ["SCENE", "-o", ""]),
        ("assign", ["--kitti", "K", "--frame", "000000", "-o", ""]),
        ("pseudo_nir", ["IMG", "-o", ""]),
        ("scenegen", ["--count", "1", "-o", ""]),
        ("dataset", ["--scenes", "S", "-o", ""]),
        ("evaluate", ["--photos", "S", "-o", ""]),
        ("calibrate", ["S", "-o", ""]),
        ("drive", ["-o", ""]),
        ("train", ["S", ""]),
        ("materials", ["--plot", "grass", "-o", ""]),
        ("weather", ["IN", "--fog", "100", "-o", ""]),
    ],
)
def test_an_empty_output_path_is_an_error(
    command, argv, tmp_path, call, one_error_line, monkeypatch
):
    """``-o ""`` used to mean the default output."""
    monkeypatch.chdir(tmp_path)
    status, _, err = call(command, argv)
    one_error_line(status, err, "an empty path; name the output")
    assert list(tmp_path.iterdir()) == []


_DISK_FULL = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))
from nidar_mi.cli.render import main
sys.exit(main(sys.argv[1:]))
"""


def test_a_full_disk_while_an_exr_is_written(tmp_path, tiny_scene):
    """Writing past the file-size limit fails like a full disk (EFBIG for ENOSPC): OpenEXR's
    error used to end in a traceback."""
    out = tmp_path / "out"
    argv = [tiny_scene, "-o", out, "-q", "--spp", "1", "-D", "width=400", "-D", "height=300"]
    r = subprocess.run(
        [sys.executable, "-c", _DISK_FULL, *map(str, argv)],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=600,
        env=dict(os.environ, NIDAR_VARIANT="llvm_ad_spectral"),
    )
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert lines[0].startswith("error: cannot write ") and ".exr: " in lines[0]
    assert "File too large" in lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scenes"]  # nothing half-written


# --------------------------------------------------------------------- folders of many inputs


def test_a_bad_scene_is_found_before_any_render(
    tmp_path, call, one_error_line, monkeypatch, variant
):
    """``dataset`` with one bad XML among good ones used to render the others first."""
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    for name in ("a", "b", "d"):
        (scenes / f"{name}.xml").write_text(TINY_SCENE)
    (scenes / "c.xml").write_text(TINY_SCENE.replace("</scene>", "<shape>"))
    monkeypatch.setattr("nidar_mi.simulate.render_scene", pytest.fail)
    status, _, err = call("dataset", ["--scenes", scenes, "-o", tmp_path / "data", "-q"])
    one_error_line(status, err, f"{scenes / 'c.xml'}: scene XML does not parse")
    assert not (tmp_path / "data").exists()


def test_a_bad_kitti_folder_leaves_nothing(tmp_path, call, one_error_line):
    """``dataset --kitti`` on a bad folder used to leave an empty OUT (and split folders)."""
    kitti = make_kitti(tmp_path / "kitti", frames=2, cols=90)
    (kitti / "calib" / "000001.txt").write_text("P2: 1 2 3\n")
    out = tmp_path / "data"
    status, _, err = call("dataset", ["--kitti", kitti, "-o", out, "-q"])
    one_error_line(status, err, "000001.txt")
    assert not out.exists()


def test_pseudo_nir_does_not_read_its_own_outputs(tmp_path, call, assign_inputs):
    """``pseudo_nir DIR -o DIR/pn --recursive`` used to read ``DIR/pn``'s images on a rerun."""
    import shutil

    photos = tmp_path / "photos"
    (photos / "day").mkdir(parents=True)
    shutil.copy(assign_inputs[5], photos / "day" / "a.png")
    shutil.copy(assign_inputs[5], photos / "b.png")
    for out in (photos / "pn", photos / "pn", photos / "pn2"):
        assert call("pseudo_nir", [photos, "-o", out, "-q", "--recursive"])[0] == 0
        index = json.loads((out / "index.json").read_text())
        inputs = sorted(os.path.relpath(e["input"], photos) for e in index["images"])
        assert inputs == ["b.png", "day/a.png"]


# ----------------------------------------------------------------------- meshes and weights


@pytest.mark.parametrize(
    "kind, content, words",
    [
        (
            "ply",
            b"ply\nformat binary_little_endian 1.0\nelement vertex 100\nproperty float x\n"
            b"property float y\nproperty float z\nend_header\n\x00\x01",
            "cannot load the PLY mesh m.ply: read 2 out of 1200 bytes",
        ),
        ("ply", bytes(range(256)) * 8, "m.ply: not a PLY file"),
        (
            "obj",
            b"v 0 0 0\nv 1 0 0\nf 1 2 7\n",
            "cannot load the OBJ mesh m.obj: reference to invalid vertex 7",
        ),
        ("obj", bytes(range(256)) * 8, "m.obj: not an OBJ file (not text)"),
    ],
)
def test_a_corrupt_mesh_is_one_line_naming_it(
    kind, content, words, tmp_path, call, one_error_line, variant
):
    (tmp_path / f"m.{kind}").write_bytes(content)
    mesh = (
        f'<shape type="{kind}"><string name="filename" value="m.{kind}"/><ref id="grey"/></shape>'
    )
    scene = _scene(tmp_path, TINY_SCENE.replace("</scene>", mesh + "</scene>"))
    status, _, err = _quick_render(call, scene, tmp_path / "out")
    one_error_line(status, err, words)
    assert "[" not in err.split(words)[-1]  # no Mitsuba class tags such as [OBJMesh]


def test_weights_without_their_training_configuration(
    tmp_path, call, one_error_line, assign_inputs
):
    import shutil

    from nidar_mi.nidar.pipeline import NidarModel

    weights = tmp_path / "w"
    shutil.copytree(NidarModel.load().weights_dir, weights)
    config = json.loads((weights / "config.json").read_text())
    del config["train"]
    (weights / "config.json").write_text(json.dumps(config))
    status, _, err = call("assign", [*assign_inputs, "-o", tmp_path / "out", "--weights", weights])
    one_error_line(status, err, f"cannot read {weights / 'config.json'}: no 'train' key")
