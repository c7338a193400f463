"""The reconstruction's files: the surfaces hold reflectance (the fitted ρ over the albedo scale)
and the recovered sensor the scale as its gain, so that their product is the fit's."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from nidar_mi.resim.write import DEFAULT_ALBEDO_SCALE, albedo_scale


def test_the_albedo_scale_is_given_else_nidars_else_the_default():
    prior = np.array([0.1, np.nan, 0.3])
    seen = SimpleNamespace(prior=prior, prior_scale=2.9)
    assert albedo_scale(seen, 1.5) == (1.5, "given")
    assert albedo_scale(seen) == (2.9, "nidar")
    assert albedo_scale(SimpleNamespace(prior=None, prior_scale=np.nan)) == (
        DEFAULT_ALBEDO_SCALE,
        "default",
    )
    # a prior that saw no vertex has no scale
    blind = SimpleNamespace(prior=np.full(3, np.nan), prior_scale=np.nan)
    assert albedo_scale(blind) == (DEFAULT_ALBEDO_SCALE, "default")
