"""``python -m nidar_mi.drive``: the whole drive study on a reduced drive (CI size)."""

import json

import pytest

from nidar_mi.cli.drive import main

# 4 s of driving (~30 m): no revisit yet (loops on rendered revisits:
# tests/eval/drive/test_loops_rendered.py; the full study: docs/CASE_STUDY.md)
REDUCED = [
    "--blocks", "2,1", "--frames", "40", "--cols", "1024",
    "--width", "64", "--height", "36", "--spp", "1", "-q",
]  # fmt: skip


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("drive")
    assert main(["-o", str(out), *REDUCED]) == 0
    return out


def test_reduced_study_end_to_end(study):
    res = json.loads((study / "results.json").read_text())
    assert res["drive"]["frames"] == 40 and res["drive"]["revisits"] == 0
    odo = res["odometry"]["instantaneous"]
    # KISS-ICP follows the street: well under the ~6 % a street with a little structure gives
    assert 0 <= odo["end_drift"]["pct"] < 5.0
    assert 0 <= odo["ate"]["rmse"] < 0.5
    assert odo["end_drift"]["path_m"] == pytest.approx(res["drive"]["length_m"], rel=1e-3)
    assert set(res["loops"]) == {"physics", "nidar", "rgb_twin", "carla", "none"}
    for source, s in res["loops"].items():
        assert s["revisits"] == 0 and s["average_precision"] is None, source
        g = res["pose_graph"][source]
        assert g["loops"] == 0 and g["ate"]["rmse"] == pytest.approx(odo["ate"]["rmse"])
    # NIDAR saw the points in front of the camera and only those
    assert 0.05 < res["nidar_observed_fraction"] < 0.6
    for fig in ("trajectory.png", "pr.png", "descriptors.png"):
        assert (study / fig).stat().st_size > 1000
    report = (study / "report.md").read_text()
    assert "| physics |" in report and "ATE RMSE" in report


def test_a_second_run_reuses_the_frames(study):
    frame = study / "frames" / "physics" / "000010.npz"
    nidar = next((study / "frames" / "physics").glob("nidar_*/000010.npz"))
    before = frame.stat().st_mtime_ns, nidar.stat().st_mtime_ns
    assert main(["-o", str(study), *REDUCED]) == 0
    assert (frame.stat().st_mtime_ns, nidar.stat().st_mtime_ns) == before


@pytest.mark.parametrize(
    "args, message",
    [
        (["--sources", "physics,lidar"], "error: --sources: unknown 'lidar'"),
        (["--blocks", "1,1"], "error: --blocks expects NX,NY"),
        (["--frames", "3"], "error: --frames must be >= 10"),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path, capsys, args, message):
    assert main(["-o", str(tmp_path / "o"), "-q", *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith(message) and err.count("\n") == 1
    assert not (tmp_path / "o").exists()
