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
