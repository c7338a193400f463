"""No command destroys a user's data, and every option acts or is refused.

* An output never is, or holds, an input of the command (``--overwrite`` or not).
* Every check that can fail (options, inputs, the Ray cluster) runs before anything existing
  is moved or deleted; a failed build leaves no stray file.
* Options that would have no effect, that conflict, or whose value is out of range are refused
  with one ``error:`` line and status 2, nothing written.
"""

from __future__ import annotations

import json
import os
import socket
import threading
import time

import numpy as np
import pytest

from nidar_mi.eval.suite import OWNER
from nidar_mi.io.atomic import write_record
from nidar_mi.io.ownership import RECORD
from tests.helpers.synthetic_kitti import make_kitti

# ------------------------------------------------------------------ outputs that hold inputs


def test_render_into_the_scene_folder_is_refused(tmp_path, call, one_error_line, snapshot):
    """``render D/x.xml -o D --overwrite`` used to replace D, the scene with it."""
    from tests.cli.conftest import TINY_SCENE

    d = tmp_path / "D"
    d.mkdir()
    (d / "x.xml").write_text(TINY_SCENE)
    before = snapshot(d)
    for out in (d, tmp_path, d / "x.xml"):
        status, _, err = call("render", [d / "x.xml", "-o", out, "--overwrite", "-q"])
        one_error_line(status, err, "holds the input" if out != d / "x.xml" else "is the input")
        assert snapshot(d) == before


def test_render_output_that_holds_an_included_file_is_refused(tmp_path, call, one_error_line):
    from tests.cli.conftest import TINY_SCENE

    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "dome.xml").write_text(
        '<scene version="3.0.0"><bsdf type="diffuse" id="x"/></scene>'
    )
    scene = tmp_path / "x.xml"
    scene.write_text(TINY_SCENE.replace("</scene>", '<include filename="parts/dome.xml"/></scene>'))
    status, _, err = call("render", [scene, "-o", tmp_path / "parts", "--overwrite", "-q"])
    one_error_line(status, err, "parts/dome.xml")
    assert (tmp_path / "parts" / "dome.xml").is_file()


@pytest.mark.parametrize("command", ["dataset", "pseudo_nir", "assign", "evaluate", "calibrate"])
def test_output_that_holds_an_input_is_refused(
    command, tmp_path, call, one_error_line, snapshot, tiny_scene, assign_inputs
):
    scenes = os.path.dirname(tiny_scene)
    folder = os.path.dirname(assign_inputs[1])
    argv = {
        "dataset": ["--scenes", scenes, "-o", scenes, "-q"],
        "pseudo_nir": [folder, "-o", tmp_path, "-q"],
        "assign": [*assign_inputs, "-o", folder],
        "evaluate": ["--photos", folder, "-o", tmp_path, "-q"],
        "calibrate": [folder, "-o", folder, "-q"],
    }[command]
    before = snapshot(tmp_path)
    status, _, err = call(command, [*argv, "--overwrite"])
    one_error_line(status, err, "the input")
    assert snapshot(tmp_path) == before


def test_train_output_that_holds_the_data_is_refused(tmp_path, call, one_error_line):
    from tests.helpers.synthetic_frames import write_synthetic_dataset

    data = write_synthetic_dataset(tmp_path / "run" / "data", height=24, width=32)
    status, _, err = call("train", [data, tmp_path / "run", "--reduced", "--overwrite", "-q"])
    one_error_line(status, err, "holds the input")
    assert (data / "meta.json").is_file()


# -------------------------------------------------- every check before anything is removed


@pytest.fixture()
def built_dataset(tmp_path, call, tiny_scene, variant):
    """A published dataset of the tiny scene: (scenes folder, DATA)."""
    scenes, data = os.path.dirname(tiny_scene), tmp_path / "data"
    assert call("dataset", ["--scenes", scenes, "-o", data, "-q", "--spp", "1"])[0] == 0
    assert (data / "meta.json").is_file() and (data / "train").is_dir()
    return scenes, data


def test_unknown_lidar_is_refused_before_any_render(
    built_dataset, call, one_error_line, snapshot, monkeypatch
):
    scenes, data = built_dataset
    before = snapshot(data)
    monkeypatch.setattr("nidar_mi.simulate.ensure_rendered", pytest.fail)
    argv = ["--scenes", scenes, "-o", data, "-q", "--spp", "1", "--lidar", "nope", "-D", "width=20"]
    status, _, err = call("dataset", argv)
    one_error_line(status, err, "--lidar 'nope': scene tiny has no such lidar (has lidar)")
    assert snapshot(data) == before


@pytest.fixture()
def not_ray():
    """``host:port`` of a server that answers, but not as a Ray cluster."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            conn.sendall(b"SSH-2.0-OpenSSH_9.6\r\n")
            conn.close()

    threading.Thread(target=serve, daemon=True).start()
    yield f"127.0.0.1:{server.getsockname()[1]}"
    server.close()


def test_a_server_that_is_not_ray_fails_fast_and_removes_nothing(
    built_dataset, call, one_error_line, snapshot, not_ray
):
    pytest.importorskip("ray")
    scenes, data = built_dataset
    before = snapshot(data)
    t0 = time.perf_counter()
    argv = ["--scenes", scenes, "-o", data, "-q", "--spp", "1", "-D", "width=20"]
    status, _, err = call("dataset", [*argv, "--ray-address", not_ray])
    assert time.perf_counter() - t0 < 10
    one_error_line(status, err, "not a Ray cluster")
    assert snapshot(data) == before


def test_the_old_dataset_stays_until_the_cluster_is_connected(
    built_dataset, call, one_error_line, snapshot, monkeypatch
):
    """A cluster that answers but refuses the job (e.g. token authentication) fails in
    ``ray.init``: the published dataset is still there."""
    pytest.importorskip("ray")
    from nidar_mi.errors import NidarError

    def refuse(*args, **kwargs):
        raise NidarError("`ray_address` x:1: the cluster refused the connection")

    scenes, data = built_dataset
    before = snapshot(data)
    monkeypatch.setattr("nidar_mi.tasks._check_address", lambda address: None)
    monkeypatch.setattr("nidar_mi.tasks._connect", refuse)
    argv = ["--scenes", scenes, "-o", data, "-q", "--spp", "1", "-D", "width=20"]
    status, _, err = call("dataset", [*argv, "--ray-address", "x:1"])
    one_error_line(status, err, "refused the connection")
    hidden = [k for k in snapshot(data) if k.startswith(".") and k != RECORD]
    assert {k: v for k, v in snapshot(data).items() if k not in hidden} == before


def test_a_bad_kitti_folder_leaves_no_stray_frame(tmp_path, call, one_error_line):
    good = make_kitti(tmp_path / "good", frames=1, cols=90)
    bad = make_kitti(tmp_path / "bad", frames=1, cols=90)
    (bad / "calib" / "000000.txt").write_text("P2: 1 2 3\n")
    out = tmp_path / "data"
    status, _, err = call("dataset", ["--kitti", good, "--kitti", bad, "-o", out, "-q"])
    one_error_line(status, err, "000000.txt")
    assert not [p for p in out.rglob("*") if p.is_file()]


def test_evaluating_nothing_keeps_the_earlier_results(tmp_path, call, one_error_line, snapshot):
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.json").write_text("{}")
    (out / "results.md").write_text("# earlier results\n")
    write_record(out, OWNER)  # an earlier evaluation's
    (tmp_path / "empty").mkdir()
    before = snapshot(out)
    status, _, err = call("evaluate", ["--photos", tmp_path / "empty", "-o", out, "-q"])
    one_error_line(status, err, "nothing to evaluate")
    assert "--photos" in err and snapshot(out) == before


# ------------------------------------------------------------- every option acts or is refused


def _kitti_args(tmp_path):
    kitti = make_kitti(tmp_path / "kitti", frames=1, cols=90)
    return ["--kitti", kitti, "--frame", "000000"]


def test_assign_input_modes_exclude_each_other(
    tmp_path, call, one_error_line, assign_inputs, snapshot
):
    out = tmp_path / "out"
    status, _, err = call("assign", [*assign_inputs, *_kitti_args(tmp_path), "-o", out])
    one_error_line(status, err, "--kitti reads the frame's own cloud, image and calibration")
    assert "--points, --image, --calib" in err and not out.exists()
    status, _, err = call("assign", [*assign_inputs, "--frame", "000003", "-o", out])
    one_error_line(status, err, "--frame needs --kitti")
    assert not out.exists()


def test_assign_with_an_image_far_too_small_is_refused(tmp_path, call, one_error_line):
    from nidar_mi.io.images import write_png

    argv = _kitti_args(tmp_path)
    write_png(argv[1] / "image_2" / "000000.png", np.zeros((1, 1, 3), np.uint8))
    out = tmp_path / "out"
    status, _, err = call("assign", [*argv, "-o", out])
    one_error_line(status, err, "000000.png is 1x1 but calib P2's principal point (600, 180)")
    assert "does not match the calibration" in err and not out.exists()


def test_scenegen_refuses_a_folder_of_something_else(tmp_path, call, one_error_line, snapshot):
    render = tmp_path / "render"
    render.mkdir()
    (render / "manifest.json").write_text("{}")
    before = snapshot(render)
    status, _, err = call("scenegen", ["--count", "1", "-o", render, "-q"])
    one_error_line(status, err, "holds 1 file(s) that 'scenegen' did not write (manifest.json)")
    assert "--overwrite" in err and snapshot(render) == before
    assert call("scenegen", ["--count", "1", "-o", render, "-q", "--overwrite"])[0] == 0
    assert call("scenegen", ["--count", "2", "-o", render, "-q"])[0] == 0  # its own output now
    assert (render / "manifest.json").read_text() == "{}"  # kept


def test_scenegen_refuses_another_commands_output(
    tmp_path, call, one_error_line, snapshot, assign_inputs
):
    out = tmp_path / "a"
    assert call("assign", [*assign_inputs, "-o", out, "--formats", "npz"])[0] == 0
    before = snapshot(out)
    for extra in ([], ["--overwrite"]):
        status, _, err = call("scenegen", ["--count", "1", "-o", out, "-q", *extra])
        one_error_line(status, err, "is the output of 'assign' (points)")
        assert snapshot(out) == before


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--kind", "city", "--speed", "inf"], "--speed must lie in (0, 70] m/s (got inf)"),
        (["--kind", "city", "--rate", "nan"], "--rate must lie in (0, 100] Hz (got nan)"),
        (["--kind", "urban", "--blocks", "2,2", "--frames", "7"], "--blocks, --frames: options"),
        (["--speed", "5"], "--speed: options of --kind city or suburb (got no --kind)"),
    ],
)
def test_scenegen_drive_options(argv, needle, tmp_path, call, one_error_line):
    out = tmp_path / "gen"
    status, _, err = call("scenegen", ["--count", "1", "-o", out, "-q", *argv])
    one_error_line(status, err, needle)
    assert not out.exists()


def test_evaluate_figures_must_not_be_negative(tmp_path, call, one_error_line, assign_inputs):
    out = tmp_path / "out"
    photos = tmp_path / "photos" / "cat"
    photos.mkdir(parents=True)
    status, _, err = call("evaluate", ["--photos", photos.parent, "--figures", "-1", "-o", out])
    one_error_line(status, err, "--figures must be an integer >= 0 (got -1)")
    assert not out.exists()


@pytest.mark.parametrize("split", ["0.5,0.5,0.5", "0.5,0.2,0.1", "2,0,0"])
def test_dataset_split_fractions_sum_to_one(split, tmp_path, call, one_error_line, tiny_scene):
    out = tmp_path / "data"
    argv = ["--scenes", os.path.dirname(tiny_scene), "-o", out, "--split", split, "-q"]
    status, _, err = call("dataset", argv)
    one_error_line(status, err, "--split: three fractions in [0, 1] summing to 1")
    assert not out.exists()


def test_dataset_kitti_refuses_the_options_of_scenes(tmp_path, call, one_error_line):
    kitti = make_kitti(tmp_path / "kitti", frames=1, cols=90)
    out = tmp_path / "data"
    status, _, err = call("dataset", ["--kitti", kitti, "-o", out, "--spp", "4", "--lidar", "x"])
    one_error_line(status, err, "--spp, --lidar: options of --scenes, not of --kitti")
    assert not out.exists()


def test_calibrate_incidence_needs_the_gbm_form(tmp_path, call, one_error_line):
    flag = "--no-incidence"
    kitti = make_kitti(tmp_path / "kitti", frames=1, cols=90)
    out = tmp_path / "p.json"
    status, _, err = call("calibrate", [kitti, "-o", out, "--form", "range_ring", flag])
    one_error_line(status, err, f"{flag} needs --form gbm or physical (got --form range_ring)")
    assert not out.exists()


def test_materials_plot_is_a_png(tmp_path, call, one_error_line):
    out = tmp_path / "a.txt"
    status, _, err = call("materials", ["--plot", "grass", "-o", out])
    one_error_line(status, err, "name a .png file")
    assert not out.exists()


def test_pseudo_nir_skips_a_truncated_image(tmp_path, call):
    from PIL import Image

    rng = np.random.default_rng(0)
    Image.fromarray(rng.integers(0, 256, (40, 48, 3), dtype=np.uint8)).save(tmp_path / "good.jpg")
    Image.fromarray(rng.integers(0, 256, (40, 48, 3), dtype=np.uint8)).save(tmp_path / "t.png")
    data = (tmp_path / "t.png").read_bytes()
    (tmp_path / "t.png").write_bytes(data[: len(data) // 2])
    out = tmp_path / "out"
    argv = [tmp_path / "good.jpg", tmp_path / "t.png", "-o", out, "-q"]
    status, _, err = call("pseudo_nir", [*argv, "--skip-bad"])
    assert status == 0, err
    assert err.startswith("warning: skipped cannot read") and "t.png" in err
    index = json.loads((out / "index.json").read_text())
    assert [im["outputs"] for im in index["images"]] == [["good.png"]]
    status, _, err = call("pseudo_nir", [*argv, "--overwrite"])  # without --skip-bad: refused
    assert status == 2 and err.strip().splitlines()[-1].startswith("error: cannot read")
    assert json.loads((out / "index.json").read_text()) == index


def test_train_overwrite_reruns_the_same_command(tmp_path, call, one_error_line, synthetic_data):
    out = tmp_path / "weights"
    argv = [synthetic_data, out, "--reduced", "--device", "cpu", "--no-progress", "-q"]
    argv += ["--stage", "stn", "--max-steps", "1"]
    assert call("train", argv)[0] == 0
    status, _, err = call("train", argv)
    one_error_line(status, err, "pass --resume to continue it or --overwrite to replace it")
    (out / "stn.safetensors").write_bytes(b"the earlier run's")
    status, _, err = call("train", [*argv, "--overwrite"])
    assert status == 0, err
    assert (out / "stn.safetensors").read_bytes() != b"the earlier run's"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    status, _, err = call("train", [*argv, "--overwrite", "--resume"])
    one_error_line(status, err, "--overwrite replaces the run that --resume continues")
