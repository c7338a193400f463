"""Fitting a profile on a sensor's scans."""

from __future__ import annotations

import numpy as np
import pytest


def test_incidence_fit_survives_a_scan_with_too_few_returns():
    """Fitting with the incidence on scans one of which has two returns: that scan's incidence
    is head-on (a warning), the fit goes on."""
    from nidar_mi.datasets.profile_fitting import fit_values_profile
    from nidar_mi.datasets.scans import ScanFrame

    rng = np.random.default_rng(0)
    scans = []
    for i, n in enumerate((4000, 2)):
        xyz = rng.uniform([2, -10, -2], [40, 10, 2], (n, 3))
        scans.append(
            ScanFrame(f"s{i}", xyz, rng.uniform(0, 1, n), np.full(n, -1, np.int16), cameras=[])
        )
    with pytest.warns(UserWarning, match="too few for a surface normal"):
        p = fit_values_profile(
            scans, lambda s: np.linspace(0, 1, len(s.xyz)), name="t", sensor="", input="nidar:R",
            form="gbm", incidence=True, trees=5,
        )  # fmt: skip
    assert p.uses_incidence and p.provenance["returns"] == 4002


def test_the_recording_of_a_frame(tmp_path):
    """A converted KITTI frame's recording is its source folder's name; a data folder's frame
    belongs to the data folder above its split; a frame read from a KITTI folder, that folder."""
    from nidar_mi.datasets.scans import recording_of

    assert recording_of("kitti_more__r0005_0140", "/x/train/kitti_more__r0005_0140.npz") == (
        "kitti_more"
    )
    data = tmp_path / "data"
    assert recording_of("0007", str(data / "val" / "0007.npz")) == str(data)
    assert recording_of("0007", str(tmp_path / "points" / "0007.npz")) == str(tmp_path / "points")
    assert recording_of("000003", str(tmp_path)) == str(tmp_path)
