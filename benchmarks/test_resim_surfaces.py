"""The surface a re-simulated return lies on (benchmarks/resim_surfaces.py), by hand."""

from __future__ import annotations

import os
import sys

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import resim_surfaces as bench  # noqa: E402


def test_points_on_the_mesh_on_a_splat_and_off_both():
    # the fused mesh: the unit square z = 0 (two triangles); then one splat, the square
    # x in [5, 5.1], y in [0, 0.1] at z = 1 (two triangles)
    v = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [5, 0, 1], [5.1, 0, 1], [5.1, 0.1, 1],
         [5, 0.1, 1]], dtype=float,
    )  # fmt: skip
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    pts = np.array(
        [
            [0.5, 0.5, 0.0],  # on the mesh
            [0.2, 0.7, 0.04],  # 4 cm above it: still on it
            [5.05, 0.05, 1.0],  # on the splat
            [5.05, 0.05, 1.0 - 0.049],  # just within ON_PLY_M of it
            [0.5, 0.5, 0.06],  # 6 cm above the mesh: a surface that moved
            [3.0, 0.0, 0.5],  # far from both
        ]
    )
    np.testing.assert_array_equal(bench.surface_kind(pts, v, f, 2), [0, 0, 1, 1, 2, 2])
    # every triangle counted as the mesh's: no splat
    np.testing.assert_array_equal(bench.surface_kind(pts, v, f, 4), [0, 0, 0, 0, 2, 2])


def test_far_causes_read_the_real_beam_beside_each_return():
    # real returns: one 5 m along +x, one 10 m along +y, one 20 m along -x
    real = np.array([[5.0, 0, 0], [0, 10.0, 0], [-20.0, 0, 0]])
    az = np.radians(0.2)  # within BEAM_DEG (0.3°) of +x
    sim = np.array(
        [
            [9.0 * np.cos(az), 9.0 * np.sin(az), 0],  # +x at 9 m: the real beam stopped at 5 m
            [0, 8.0, 0],  # +y at 8 m: the real beam went on to 10 m
            [0, 0, 7.0],  # straight up: no real return within 0.3°
            [-20.3, 0, 0],  # -x, 0.3 m past the real return: within FAR_M
            [5.0 * np.cos(0.01), 5.0 * np.sin(0.01), 0],  # 0.57° off +x: no real beam
        ]
    )
    np.testing.assert_array_equal(bench.far_causes(sim, real), [0, 1, 2, 3, 2])


def test_a_work_folder_lists_its_runs_and_refuses_what_it_lacks(tmp_path, capsys):
    import pytest
    from work_folder import work_parser, work_runs

    for run in ("r2", "r1"):
        (tmp_path / "out" / run).mkdir(parents=True)
        (tmp_path / "out" / run / "report.json").write_text("{}")
        (tmp_path / "drives" / run).mkdir(parents=True)
    (tmp_path / "out" / "unfinished").mkdir()  # no report.json: not listed
    ap = work_parser("test")
    assert work_runs(ap.parse_args(["--work", str(tmp_path)])) == ["r1", "r2"]
    assert work_runs(ap.parse_args(["--work", str(tmp_path), "--runs", "r2"])) == ["r2"]
    for argv, said in (
        (["--work", str(tmp_path), "--runs", "r3"], "no run 'r3'"),
        (["--work", str(tmp_path), "--runs", "unfinished"], "no run 'unfinished'"),
        (["--work", str(tmp_path / "none")], "is not a resim_drives.py --work folder"),
    ):
        with pytest.raises(SystemExit) as stop:
            work_runs(ap.parse_args(argv))
        assert stop.value.code == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and said in err and err.count("\n") == 1
