"""The calibration panels in fog (:func:`nidar_mi.studies.weather_curves.panel_sweep`): each
panel's points and intensity against Beer-Lambert's two-way transmission."""

import math

from nidar_mi.studies import weather_curves as ws
from nidar_mi.weather import Weather
from nidar_mi.weather.media import medium_optics


def test_panel_intensity_follows_two_way_transmission(variant):
    fog = Weather(fog=100.0)
    points = ws.panel_sweep(ws.SENSORS["HDL-64E-like"], 905.0, [fog], cols=512)
    alpha = medium_optics(fog, 905.0).alpha
    bright = [p for p in points if p.material in ("white_95", "grey_50") and p.incidence == 0]
    assert {(p.material, p.distance) for p in bright} == {
        (m, d) for m in ("white_95", "grey_50") for d in (5.0, 10.0, 20.0)
    }
    for p in bright:
        assert p.npc_clear > 0
        assert p.npc_ratio == 1.0, p.panel  # far above the threshold at these ranges
        # the panel's centre distance; its 1 m width adds at most 0.03 m of path at 5 m
        assert math.isclose(p.intensity_ratio, math.exp(-2 * alpha * p.distance), rel_tol=0.01)
