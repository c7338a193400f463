"""``render --fog/--rain/--snow``: the points say what they hit, the camera sees the medium, the
request and manifest record the weather; bad weather is one ``error:`` line, exit 2, nothing
written."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STREET = os.path.join(REPO, "scenes", "street.xml")
TINY = ["-D", "width=24", "-D", "height=14", "-D", "cols=128", "--spp", "1", "-q"]


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--fog", "0"], "error: --fog (meteorological optical range) must be > 0"),
        (["--fog", "-20"], "error: --fog (meteorological optical range) must be > 0"),
        (["--rain", "-1"], "error: --rain must be a rate in [0, 300] mm/h"),
        (["--snow", "1e6"], "error: --snow must be a rate in [0, 50] mm/h"),
        (["--rain", "inf"], "error: --rain must be a finite number"),
        (["--rain", "2", "--snow", "1"], "error: --rain and --snow cannot fall together"),
        (["--fog-type", "radiation"], "error: --fog-type needs --fog"),
        (["--fog", "50", "--intensity", "nidar"], "error: --intensity nidar reads the surfaces"),
        (["--fog", "fifty"], "error: argument --fog: invalid float value"),
    ],
)
def test_bad_weather_is_refused_before_any_work(tmp_path, capsys, flags, message):
    from nidar_mi.cli.render import main

    out = tmp_path / "out"
    try:
        status = main([STREET, "-o", str(out), *TINY, *flags])
    except SystemExit as e:  # a usage error (argparse)
        status = e.code
    assert status == 2
    err = capsys.readouterr().err
    assert err.startswith(message) and err.count("\n") == 1, err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_rain_render_labels_its_drops(variant, tmp_path):
    from nidar_mi.cli.render import main
    from nidar_mi.io.las import read_las
    from nidar_mi.io.points import read_npz, read_ply
    from nidar_mi.render_session import RenderOptions

    out = tmp_path / "rain"
    flags = ["--rain", "60", "--no-cameras", "--seed", "1"]
    assert main([STREET, "-o", str(out), *TINY, *flags]) == 0
    pts = read_npz(out / "lidar_top" / "points.npz")
    assert list(pts["scatterer_names"]) == ["surface", "fog", "drop", "flake"]
    assert set(np.unique(pts["scatterer"])) <= {0, 2} and (pts["scatterer"] == 0).any()
    for read, name in ((read_ply, "points.ply"), (read_las, "points.las")):
        np.testing.assert_array_equal(read(out / "lidar_top" / name)["scatterer"], pts["scatterer"])
    manifest = json.loads((out / "manifest.json").read_text())
    rain = {"fog": None, "fog_type": "advection", "rain": 60.0, "snow": None}
    assert manifest["weather"] == manifest["request"]["weather"] == rain
    assert manifest["lidars"]["lidar_top"]["weather"] == rain
    # the cache key tells the weather apart; a clear request stays what it was
    assert "weather" not in RenderOptions(STREET).key().to_dict()


def test_fog_render_sees_the_fog(variant, tmp_path):
    """The camera renders through the fog (finite, other images in RGB and NIR: the medium's
    physics is checked below) and the LiDAR of the same render returns from it."""
    from nidar_mi.cli.render import main
    from nidar_mi.io.images import read_exr
    from nidar_mi.io.points import read_npz

    clear, fog = tmp_path / "clear", tmp_path / "fog"
    assert main([STREET, "-o", str(clear), *TINY, "--seed", "2"]) == 0
    assert main([STREET, "-o", str(fog), *TINY, "--seed", "2", "--fog", "25"]) == 0

    def image(folder, name):
        return np.stack(list(read_exr(folder / "cam_front" / name).values()), axis=-1)

    for name in ("rgb.exr", "nir.exr"):
        a, b = image(clear, name), image(fog, name)
        assert np.all(np.isfinite(b)) and b.shape == a.shape
        assert np.abs(b - a).mean() > 0.1 * a.mean()
    pts = read_npz(fog / "lidar_top" / "points.npz")
    assert (pts["scatterer"] == 1).mean() > 0.2


def test_the_camera_medium_has_the_lidars_extinction(variant):
    """Mitsuba's medium (σ_t, albedo) at the visible bands and at the LiDAR's wavelength is the
    LiDAR's medium (:func:`nidar_mi.weather.media.medium_optics`)."""
    import drjit as dr
    import mitsuba as mi

    from nidar_mi.weather import Weather
    from nidar_mi.weather.camera_medium import medium_dict
    from nidar_mi.weather.media import medium_optics

    w = Weather(fog=80.0, rain=10.0)
    medium = mi.load_dict(medium_dict(w, [905.0]))
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.p = mi.Point3f(0.0, 0.0, 0.0)
    mei.wavelengths = mi.UnpolarizedSpectrum(550.0, 905.0, 450.0, 700.0)
    sigma_s, _, sigma_t = medium.get_scattering_coefficients(mei)
    for i, wl in enumerate((550.0, 905.0, 450.0)):
        o = medium_optics(w, wl)
        assert sigma_t[i][0] == pytest.approx(o.alpha, rel=1e-5)
        assert sigma_s[i][0] == pytest.approx(o.alpha * o.albedo, rel=1e-5)
    # 700 nm lies between 650 and 905 nm: interpolated, within the two
    bounds = sorted(medium_optics(w, wl).alpha for wl in (650.0, 905.0))
    assert bounds[0] * (1 - 1e-6) <= sigma_t[3][0] <= bounds[1] * (1 + 1e-6)


def test_fog_phase_table_is_the_droplets_phase_function():
    """The tabulated phase function integrates to 1 over the sphere and has the asymmetry g of
    the fog's droplets at 550 nm (:func:`nidar_mi.weather.media.bulk_optics`)."""
    from nidar_mi.weather.camera_medium import fog_phase_table
    from nidar_mi.weather.media import bulk_optics
    from nidar_mi.weather.particles import fog_distribution

    table = fog_phase_table("advection")
    mu = np.linspace(-1.0, 1.0, table.size)
    assert 2 * np.pi * np.trapezoid(table, mu) == pytest.approx(1.0, rel=1e-9)
    g = bulk_optics(fog_distribution("advection"), 550.0).g
    assert 2 * np.pi * np.trapezoid(table * mu, mu) == pytest.approx(g, abs=0.01)
    assert table[-1] > 1000 * table[table.size // 2]  # the diffraction peak forward
