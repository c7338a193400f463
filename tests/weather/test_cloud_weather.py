"""Weather on real point clouds: the detection given the clear-air detection against its closed
form, every format in and out, determinism, and the command's contract (bad input: one
``error:`` line, exit 2, nothing written)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.stats import norm

from nidar_mi.cloud_weather import CloudSensor, add_weather, cloud_sensor
from nidar_mi.weather import Weather
from nidar_mi.weather.media import medium_optics

T, SIGMA = 4e-5, 4e-5 / 3.719016485455709  # the hdl64e preset's link budget


def _wall(n: int = 20000, d: float = 50.0, intensity: float = 0.1, seed: int = 0) -> dict:
    """A KITTI-like cloud: ``n`` returns at range ``d`` of compensated intensity ``i``."""
    rng = np.random.default_rng(seed)
    az, el = rng.uniform(-0.5, 0.5, n), rng.uniform(-0.1, 0.1, n)
    xyz = d * np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    return {
        "xyz": xyz.astype(np.float32),
        "intensity": np.full(n, intensity, np.float32),
        "ring": np.arange(n, dtype=np.uint16) % 64,
    }


def test_a_return_stays_as_often_as_its_weaker_echo_passes_given_it_passed_in_clear_air():
    """A 10 % target at 50 m returns E_c = T (detected half the time in clear air); in fog it
    returns E_h = E_c exp(-2 α d), and given its clear detection it stays with probability
    P(E_h + σ n >= T | E_c + σ n >= T) = Φ((E_h - T)/σ) / Φ((E_c - T)/σ)."""
    fog = Weather(fog=500.0)
    sensor = cloud_sensor("hdl64e", return_mode="last")  # the wall is the last echo
    out = add_weather(_wall(), fog, sensor, np.random.default_rng(1))
    alpha = medium_optics(fog, 905.0).alpha
    e_c = 0.1 / 50.0**2
    e_h = e_c * math.exp(-2 * alpha * 50.0)
    expected = norm.cdf((e_h - T) / SIGMA) / norm.cdf((e_c - T) / SIGMA)
    stayed = (out["scatterer"] == 0).mean() * len(out["xyz"]) / 20000
    assert stayed == pytest.approx(expected, abs=4 * math.sqrt(expected / 20000))
    # the weaker echo is timed less precisely: c τ_H σ_n / π sqrt(1/E_h² - 1/E_c²) more jitter
    r = np.linalg.norm(out["xyz"][out["scatterer"] == 0], axis=1)
    jitter = 3.0 * SIGMA / math.pi * math.sqrt(1 / e_h**2 - 1 / e_c**2)  # c τ_H = 3 m
    assert np.median(r) == pytest.approx(50.0, abs=0.05)
    assert r.std() == pytest.approx(jitter, rel=0.5)


def test_light_weather_keeps_strong_returns_and_their_columns():
    cloud = _wall(n=5000, d=10.0, intensity=0.5)
    out = add_weather(cloud, Weather(fog=20000.0), cloud_sensor(), np.random.default_rng(0))
    assert len(out["xyz"]) == 5000 and (out["scatterer"] == 0).all()
    np.testing.assert_array_equal(out["ring"], cloud["ring"])
    # the two-way transmission of the light fog on the intensity (the noise conditioned on a
    # clear detection far above T barely moves it)
    alpha = medium_optics(Weather(fog=20000.0), 905.0).alpha
    np.testing.assert_allclose(out["intensity"], 0.5 * math.exp(-20 * alpha), rtol=0.02)
    assert list(out["scatterer_names"]) == ["surface", "fog", "drop", "flake"]


def test_sensor_from_a_preset_and_bad_sensors():
    from nidar_mi.errors import NidarError

    s = cloud_sensor("hdl64e")
    assert (s.detection_threshold, s.receiver_noise_std) == pytest.approx((T, SIGMA))
    assert (s.range_min, s.range_max) == (0.9, 120.0)
    assert cloud_sensor("os1_64", detection_threshold=6e-5).detection_threshold == 6e-5
    with pytest.raises(NidarError, match="no published detection threshold"):
        cloud_sensor("os1_64")
    with pytest.raises(NidarError, match="`wavelength` must be in"):
        cloud_sensor("hdl64e", wavelength=2000.0)
    with pytest.raises(NidarError, match="`sensor` must be one of"):
        cloud_sensor("hdl65")
    assert isinstance(s, CloudSensor)


# ------------------------------------------------------------------ the command


def _write_inputs(folder, cloud):
    from nidar_mi.io.kitti import write_kitti_bin
    from nidar_mi.io.las import write_las
    from nidar_mi.io.pcd import write_pcd
    from nidar_mi.io.points import write_ply

    folder.mkdir()
    write_kitti_bin(folder / "000000.bin", cloud["xyz"], cloud["intensity"])
    write_pcd(folder / "a.pcd", cloud)
    write_ply(folder / "b.ply", cloud)
    write_las(folder / "c.las", cloud)
    (folder / "notes.txt").write_text("not a cloud")


def test_command_adds_weather_to_every_format_deterministically(tmp_path, capsys):
    from nidar_mi.cli.weather import main
    from nidar_mi.io.point_cloud import read_point_cloud

    src = tmp_path / "in"
    _write_inputs(src, _wall(n=3000, d=30.0, intensity=0.2))
    args = ["--snow", "4", "--seed", "5", "--no-progress"]
    assert main([str(src), "-o", str(tmp_path / "a"), *args]) == 0
    assert main([str(src), "-o", str(tmp_path / "b"), *args, "-q"]) == 0
    assert "snow 4 mm/h: 4 clouds, 12000 points in" in capsys.readouterr().out
    report = json.loads((tmp_path / "a" / "weather.json").read_text())
    assert set(report["clouds"]) == {"000000.bin", "a.pcd", "b.ply", "c.las"}
    assert report["weather"]["snow"] == 4.0 and report["seed"] == 5
    for name, counts in report["clouds"].items():
        a = read_point_cloud(tmp_path / "a" / name)
        b = read_point_cloud(tmp_path / "b" / name)
        np.testing.assert_array_equal(a["xyz"], b["xyz"])
        assert counts["points_out"] == len(a["xyz"]) <= counts["points_in"]
        assert counts["surface"] + counts["flake"] == counts["points_out"]
        if name != "000000.bin":  # KITTI .bin holds x, y, z and intensity only
            assert set(np.unique(a["scatterer"])) <= {0, 3}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b", "in"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--fog", "-3"], "error: --fog (meteorological optical range) must be > 0"),
        (["--rain", "400"], "error: --rain must be a rate in [0, 300] mm/h"),
        ([], "error: give the weather to add: --fog, --rain or --snow"),
        (["--fog", "50", "--sensor", "os1_64"], "error: the os1_64 preset has no published"),
        (["--fog", "50", "--wavelength", "3000"], "error: --wavelength must be in"),
        (["--fog", "50", "--intensity-scale", "0"], "error: --intensity-scale must be > 0"),
    ],
)
def test_command_refuses_bad_weather_and_sensors(tmp_path, capsys, args, message):
    from nidar_mi.cli.weather import main

    src = tmp_path / "in"
    _write_inputs(src, _wall(n=100))
    assert main([str(src), "-o", str(tmp_path / "out"), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith(message) and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


def test_command_refuses_unknown_formats_and_its_own_input(tmp_path, capsys):
    from nidar_mi.cli.weather import main

    (tmp_path / "cloud.xyz").write_text("1 2 3\n")
    assert main([str(tmp_path / "cloud.xyz"), "-o", str(tmp_path / "o"), "--fog", "50"]) == 2
    assert "unknown point cloud format '.xyz'" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main([str(empty), "-o", str(tmp_path / "o"), "--fog", "50"]) == 2
    assert "no point cloud" in capsys.readouterr().err
    src = tmp_path / "in"
    _write_inputs(src, _wall(n=100))
    assert main([str(src), "-o", str(src), "--fog", "50"]) == 2
    assert "it is the input" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_a_real_kitti_scan_in_fog_and_rain(tmp_path):
    """A real HDL-64E sweep (KITTI, read from the shared data; skipped without it): fog takes
    the far and dark returns and puts fog points near the sensor; light rain barely changes it."""
    import os
    from pathlib import Path

    from nidar_mi.io.kitti import read_kitti_bin

    root = Path(os.environ.get("NIDAR_MI_DATA", Path(__file__).parents[3] / "shared" / "data"))
    path = root / "kitti" / "velodyne" / "000000.bin"
    if not path.is_file():
        pytest.skip(f"real KITTI scans not found at {path} (set NIDAR_MI_DATA)")
    xyz, intensity = read_kitti_bin(path)
    cloud = {"xyz": xyz, "intensity": intensity}
    d = np.linalg.norm(xyz, axis=1)
    fog = add_weather(cloud, Weather(fog=50.0), cloud_sensor(), np.random.default_rng(0))
    kept = fog["scatterer"] == 0
    r = np.linalg.norm(fog["xyz"], axis=1)
    assert kept.sum() < 0.9 * len(d)  # far returns lost
    assert np.median(r[kept]) < np.median(d)
    assert (fog["scatterer"] == 1).sum() > 0 and r[fog["scatterer"] == 1].max() < 15.0
    rain = add_weather(cloud, Weather(rain=2.0), cloud_sensor(), np.random.default_rng(0))
    assert len(rain["xyz"]) > 0.98 * len(d)
    for out in (fog, rain):
        assert np.all(np.isfinite(out["xyz"])) and np.all(np.isfinite(out["intensity"]))
