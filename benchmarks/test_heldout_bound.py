"""The incidence of the held-out bound on a plane facing the camera (analytic)."""

from __future__ import annotations

import os
import sys

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import heldout_bound as bench  # noqa: E402


def test_cos_incidence_of_a_fronto_parallel_plane(tmp_path):
    from nidar_mi.training_frames import list_frames
    from tests.helpers.synthetic_frames import write_synthetic_dataset

    data = write_synthetic_dataset(tmp_path / "d", height=24, width=32)
    src = list_frames(data, "train")[0]
    with np.load(src) as npz:
        frame = {k: npz[k] for k in npz.files}
    frame["depth"] = np.full_like(frame["depth"], 7.0)  # the plane z = 7 m
    frame["T_cam_lidar"] = np.eye(4)  # the LiDAR at the camera's centre
    path = tmp_path / "plane.npz"
    np.savez(path, **frame)
    out = bench.returns(path)
    k = frame["K"]
    sel = frame["mask"] & (frame["R_true"] >= 1e-3)
    v, u = np.nonzero(sel)
    x = (u - k[0, 2]) / k[0, 0] * 7.0  # OpenCV: pixel centres at whole numbers
    y = (v - k[1, 2]) / k[1, 1] * 7.0
    expected = 7.0 / np.sqrt(x**2 + y**2 + 49.0)  # |n · ray| with n = (0, 0, 1)
    assert len(out["cos"]) == sel.sum() > 0
    np.testing.assert_allclose(out["cos"], expected, rtol=1e-9)
    np.testing.assert_array_equal(out["r_true"], np.clip(frame["R_true"][sel], 0, 1))


def test_empty_folders_are_one_line_errors(tmp_path, capsys):
    assert bench.main([str(tmp_path), str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: no rendered frames")
