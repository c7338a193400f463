"""Tests of nidar_mi.resim.prior: without NIDAR's dependencies the fit runs without the prior
and says why."""

import logging

import numpy as np

from nidar_mi import extras
from nidar_mi.resim.drive_folder import open_drive
from nidar_mi.resim.prior import nidar_prior


def test_without_the_nidar_extra_there_is_no_prior_and_a_warning(tmp_path, monkeypatch, caplog):
    for sub in ("velodyne", "image_2", "calib"):
        (tmp_path / sub).mkdir()
    for k in range(2):
        np.zeros((4, 4), np.float32).tofile(tmp_path / "velodyne" / f"{k:06d}.bin")
        (tmp_path / "image_2" / f"{k:06d}.png").write_bytes(b"")
        (tmp_path / "calib" / f"{k:06d}.txt").write_text("")
    drive = open_drive(str(tmp_path))
    monkeypatch.setattr(extras, "installed", lambda module: module != "torch")
    with caplog.at_level(logging.WARNING, logger="nidar_mi.reconstruct"):
        prior = nidar_prior(drive, np.zeros((3, 3)), np.tile(np.eye(4), (2, 1, 1)))
    assert prior is None
    assert "no NIDAR prior" in caplog.text and "'nidar'" in caplog.text and "torch" in caplog.text
