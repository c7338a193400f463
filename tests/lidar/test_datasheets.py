"""The sensor presets against their sources (channels, fields of view, columns, frame rates, points
per second, ranges) and their per-laser tables against the published files they were transcribed
from. Every compared number is a published one; the source of each is named beside it (and tabled
in docs/SENSORS.md, with the figures no source was found for)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest

from nidar_mi.lidar.config import LidarConfig
from nidar_mi.lidar.layouts import preset_table
from nidar_mi.lidar.pattern import PRESETS, elevation_table


class Datasheet(NamedTuple):
    """What a sensor's sources state (units: degrees, Hz, m)."""

    channels: int
    top_deg: float  # vertical field of view, upper edge
    bottom_deg: float  # lower edge
    fov_h_deg: float  # horizontal field of view
    frame_rate: float  # frames per second of the preset's mode
    columns: int  # columns per frame: field of view / the stated angular resolution
    points_per_s: float | None  # single return, as stated (None: not stated in the sources)
    points_tol: float  # absolute: half a unit of the figure's last digit ("~600,000": 50,000)
    range_min: float  # stated; for Velodyne, stated nowhere found: ros-drivers' launch default
    range_max: float


# the firing sequences of the Velodyne user manuals: one column per sequence at 10 Hz
VLP32C_SEQUENCE_US = 55.296  # 32 lasers in 16 pairs (ros-drivers/velodyne rawdata.cc, model 32C)
VLS128_SEQUENCE_US = 53.3  # 128 lasers in groups of 8 (user manual 63-9483 Rev A, 9.3.1.1)
VLP32C_COLUMNS = round(1e6 / (10.0 * VLP32C_SEQUENCE_US))  # 1808
VLS128_COLUMNS = round(1e6 / (10.0 * VLS128_SEQUENCE_US))  # 1876

DATASHEETS = {
    # autonomymobilitylab/HenryRTD@054ab7b docs/source/index.rst (the VLP-32C datasheet): 32
    # channels, 200 m, 360 x 40 deg (-25..+15), "~600,000 points per second" single return
    # (no minimum range stated: 0.4 m, ros-drivers/velodyne@29abd0e VLP-32C_points.launch)
    "vlp32c": Datasheet(32, 15.0, -25.0, 360.0, 10.0, VLP32C_COLUMNS, 6e5, 5e4, 0.4, 200.0),
    # ApolloAuto/apollo@54dcc2f docs/specs/Lidar/VLS_128_Installation_Guide.md (Velodyne's key
    # features): 360 deg, +15..-25 deg, up to 300 m, "up to ~9.6 million points per second" over
    # up to 4 returns: 2.4 million per return, to half of 0.1 million / 4 (no minimum range
    # stated: 0.4 m, ros-drivers VLS128_points.launch)
    "vls128": Datasheet(
        128, 15.0, -25.0, 360.0, 10.0, VLS128_COLUMNS, 9.6e6 / 4, 0.05e6 / 4, 0.4, 300.0
    ),
    # isaac-sim/IsaacSim@045ca8b OS0_REV6_128ch10hz2048res.json (Ouster datasheet rev06 v2p5):
    # 128 channels, 90 deg (+45..-45), 360 deg, 2048 x 10 Hz, minimum range 0.3 m, 50 m at >50 %
    # detection probability (100 klx); points/s not stated there
    "os0_128": Datasheet(128, 45.0, -45.0, 360.0, 10.0, 2048, None, 0.0, 0.3, 50.0),
    # OS2_REV6_128ch10hz2048res.json (rev06 v2p5): 22.5 deg (+11.25..-11.25), 2048 x 10 Hz,
    # minimum range 1.0 m, 240 m at >50 % detection probability
    "os2_128": Datasheet(128, 11.25, -11.25, 360.0, 10.0, 2048, None, 0.0, 1.0, 240.0),
    # tier4/nebula@606ac41 pandar_64.hpp: 0.3-200 m, 360 x (-25..+15) deg, 0.2 deg peak
    # resolution; user manual 4.2.2: 600 rpm default, "frame rate (Hz) x 60"
    "pandar64": Datasheet(64, 15.0, -25.0, 360.0, 10.0, round(360 / 0.2), None, 0.0, 0.3, 200.0),
    # IsaacSim Hesai_XT32_SD10.json (XT32 user manual X01-en-220410 p.13): 0.05-120 m, 10 Hz,
    # 0.18 deg; nebula pandar_xt32.hpp: -16..+15 deg
    "xt32": Datasheet(32, 15.0, -16.0, 360.0, 10.0, round(360 / 0.18), None, 0.0, 0.05, 120.0),
    # nebula pandar_at128.hpp: 120 x (-12.5..+12.9) deg, 0.1 deg; PandarAT128.param.yaml: 200 rpm,
    # 10 Hz frames; tier4/AWSIM@ac0a219 LaserArrayLibrary.cs (AT128E2X user manual
    # A01-en-230510): 200 m, near field from 0.5 m
    "at128": Datasheet(128, 12.9, -12.5, 120.0, 10.0, round(120 / 0.1), None, 0.0, 0.5, 200.0),
}


@pytest.mark.parametrize("preset", sorted(DATASHEETS))
def test_preset_against_its_datasheet(preset):
    d = DATASHEETS[preset]
    p = PRESETS[preset]
    el = elevation_table(preset)  # the uniform table spans the datasheet's field of view
    assert el.shape == (d.channels,)
    assert el[0] == pytest.approx(d.top_deg, abs=1e-4)
    assert el[-1] == pytest.approx(d.bottom_deg, abs=1e-4)
    assert np.all(np.diff(el) < 0)
    assert p.fov_h == d.fov_h_deg and p.horizontal_resolution == d.columns
    assert (p.range_min, p.range_max) == (d.range_min, d.range_max)
    cfg = LidarConfig.from_mapping("l", {"preset": preset})  # what a scene gets by default
    assert cfg.frame_rate == pytest.approx(d.frame_rate, rel=1e-12)
    if d.points_per_s is not None:
        points_per_s = d.channels * cfg.horizontal_resolution * cfg.frame_rate
        assert points_per_s == pytest.approx(d.points_per_s, abs=d.points_tol)
    assert cfg.layout == "per_laser" and cfg.rings == d.channels
    assert cfg.fov_h == d.fov_h_deg and cfg.horizontal_resolution == p.horizontal_resolution
    span = cfg.elevations[0] - cfg.elevations[-1]  # the per-laser table: one unit's angles,
    assert span == pytest.approx(d.top_deg - d.bottom_deg, rel=0.03)  # within 3 % (OS2: 2.9 %)


def test_frame_rate_is_the_turn_rate_but_for_the_mirror():
    """A spinning head makes one frame per turn; the AT128's frame is one of three mirror facets
    on a 200 rpm motor (3 · 200 / 60 = 10 Hz), whatever the beam's turn rate is set to."""
    assert LidarConfig.from_mapping("l", {"preset": "vlp16"}).frame_rate == 10.0
    spun = LidarConfig.from_mapping("l", {"preset": "os2_128", "rotation_rate": 20.0})
    assert spun.frame_rate == 20.0
    at128 = LidarConfig.from_mapping("l", {"preset": "at128"})
    assert at128.rotation_rate == pytest.approx(2 * 200 / 60)
    assert at128.frame_rate == pytest.approx(3 * 200 / 60)
    faster = LidarConfig.from_mapping("l", {"preset": "at128", "rotation_rate": 2 * 400 / 60})
    assert faster.frame_rate == pytest.approx(3 * 400 / 60)  # the 400 rpm mode: 20 Hz
    sweep = at128.pattern.column_time_s()
    assert sweep.max() < 1.0 / at128.frame_rate  # a frame holds its 120 deg sweep


class Published(NamedTuple):
    """Entries of a published per-laser table, as the source file gives them."""

    top_deg: float  # its highest elevation
    bottom_deg: float  # its lowest
    entries: dict  # laser_id -> (elevation deg, azimuth offset deg, firing offset us)


PUBLISHED = {
    # ros-drivers/velodyne VeloView-VLP-32C.yaml (radians): laser 0 vert -0.4363323 (-25 deg),
    # rot -0.0244346 (-1.4 deg); laser 29 (0.2617994, 0.0244346), laser 31 (-0.0232652,
    # 0.0244346); pairs fire 2.304 us apart, the last pair at 15 x 2.304 us
    "vlp32c": Published(
        15.0, -25.0, {0: (-25.0, -1.4, 0.0), 29: (15.0, 1.4, 32.256), 31: (-1.333, 1.4, 34.56)}
    ),
    # VLS128.yaml: laser 0 vert -0.2049366 rad (-11.742 deg), rot -0.1108982 rad (-6.354 deg),
    # laser 63 (-0.0232129, 0.1108982) rad, laser 64 (-0.0980875, -0.1108982) rad; groups of 8
    # every 2.665 us, one idle group after laser 63 (VLS128_SEQ_TDURATION 53.3 us)
    "vls128": Published(
        15.0,
        -25.0,
        {0: (-11.742, -6.354, 0.0), 63: (-1.33, 6.354, 7 * 2.665), 64: (-5.62, -6.354, 9 * 2.665)},
    ),
    # ouster-sdk OS-0-128-U1_v2.3.0_1024x10.json (beam_altitude_angles, beam_azimuth_angles):
    # beam 0 (45.75, 11.24), beam 64 (-0.77, 8.39), beam 127 (-46.26, -11.35)
    "os0_128": Published(
        45.75, -46.26, {0: (45.75, -11.24, 0.0), 64: (-0.77, -8.39, 0.0), 127: (-46.26, 11.35, 0.0)}
    ),
    # OS-2-128-U1_v2.3.0_1024x10.json: beam 0 (10.76, 2.07), beam 63 (-0.05, -2.05), beam 127
    # (-11.09, -2.04)
    "os2_128": Published(
        10.76, -11.09, {0: (10.76, -2.07, 0.0), 63: (-0.05, 2.05, 0.0), 127: (-11.09, 2.04, 0.0)}
    ),
    # HesaiLidar_SDK_2.0 Pandar64 angle correction: channel 1 (14.708, -1.042), channel 64
    # (-25.071, -1.042); fire times: channels 12 and 40 first (-54.668 us), 51 and 61 last
    # (-3.62 us)
    "pandar64": Published(
        14.708,
        -25.071,
        {0: (14.708, 1.042, 54.668 - 23.18), 11: (0.839, 1.042, 0.0), 50: (-5.739, -5.208, 51.048)},
    ),
    # PandarXT angle correction: +15..-16 deg, 1 deg apart, azimuth 0; fire time 6 + 1.512 us
    # per channel
    "xt32": Published(15.0, -16.0, {0: (15.0, 0.0, 6.0), 31: (-16.0, 0.0, 52.872)}),
    # AT128E2X angle correction (binary, 1/12800 deg): channel 1 elevation 164907 / 12800,
    # azimuth -30720 / 12800; fire time of channel 3 8.24 us
    "at128": Published(
        164907 / 12800, -159010 / 12800, {0: (164907 / 12800, -2.4, 0.0), 2: (None, None, 8.24)}
    ),
}


@pytest.mark.parametrize("preset", sorted(PUBLISHED))
def test_per_laser_table_is_the_published_one(preset):
    pub, d = PUBLISHED[preset], DATASHEETS[preset]
    t = preset_table(preset)
    assert t.rings == d.channels and sorted(t.laser_id) == list(range(d.channels))
    assert t.elevation_deg[0] == pytest.approx(pub.top_deg, abs=1e-6)
    assert t.elevation_deg[-1] == pytest.approx(pub.bottom_deg, abs=1e-6)
    assert np.all(np.diff(t.elevation_deg) < 0)
    for laser, (elevation, azimuth, firing_us) in pub.entries.items():
        i = t.laser_id.index(laser)
        if elevation is not None:
            assert t.elevation_deg[i] == pytest.approx(elevation, abs=1e-6), laser
            assert t.azimuth_offset_deg[i] == pytest.approx(azimuth, abs=1e-6), laser
        assert t.firing_offset_s[i] == pytest.approx(firing_us * 1e-6, abs=1e-12), laser
    assert min(t.firing_offset_s) >= 0.0


def test_velodyne_firing_sequences_give_the_datasheet_rates():
    """Points per second of the manuals' firing sequences (VLP-32C: 32 lasers per 55.296 us,
    578,704; VLS-128: 128 per 53.3 us, 20 groups of 2.665 us, 2,401,501) within the rounding of
    the datasheets' "~600,000" and "~9.6 million" over 4 returns; the tables' last firing ends
    inside the sequence."""
    for preset, lasers, sequence_us in (
        ("vlp32c", 32, VLP32C_SEQUENCE_US),
        ("vls128", 128, VLS128_SEQUENCE_US),
    ):
        d = DATASHEETS[preset]
        assert lasers / (sequence_us * 1e-6) == pytest.approx(d.points_per_s, abs=d.points_tol)
        assert max(preset_table(preset).firing_offset_s) < sequence_us * 1e-6
    # 16 groups of 8 and one idle slot: rawdata.cc's 17 timing slots, of the 20 slots of
    # 2.665 us in 53.3 us
    assert max(preset_table("vls128").firing_offset_s) == pytest.approx(16 * 2.665e-6, abs=1e-12)


def test_at128_sweeps_its_120_degrees_from_left_to_right_in_50_ms():
    """The AT128's beam turns at twice its mirror's 200 rpm (2400 deg/s): the 120 deg field of
    view takes 50 ms of each 100 ms frame, first column at +60 deg (left), 0.1 deg apart, one
    column every 41.67 us (TIER IV nebula's pandar_at128.hpp: 41666 ns per block)."""
    pattern = LidarConfig.from_mapping("l", {"preset": "at128"}).pattern
    az, t = pattern.column_azimuth_deg(), pattern.column_time_s()
    np.testing.assert_allclose(np.diff(az), 0.1, atol=1e-9)
    assert az.min() == pytest.approx(-59.95) and az.max() == pytest.approx(59.95)
    assert az[np.argmin(t)] == pytest.approx(59.95) and az[np.argmax(t)] == pytest.approx(-59.95)
    assert t.max() - t.min() == pytest.approx((120.0 - 0.1) / 2400.0)
    np.testing.assert_allclose(np.diff(np.sort(t)), 41.666e-6, atol=1e-9)


WALL = """
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.5, 1700:0.5"/></bsdf>
    <shape type="rectangle" id="wall"><transform name="to_world"><scale value="40"/>
        <rotate y="1" angle="-90"/><translate x="10"/></transform><ref id="grey"/></shape>
"""


@pytest.mark.parametrize("preset", sorted(DATASHEETS))
def test_every_preset_scans(variant, write_scene, preset):
    """Each preset's default (per-laser) pattern, 60 columns over its horizontal field of view,
    cast at a wall 10 m ahead spanning +-40 m: every beam whose ray meets the wall within the
    range limits returns, at
    the ray-plane intersection from its own origin (the AT128's whole 120 deg view does)."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    sensor = f"""<sensor type="lidar" id="l"><string name="preset" value="{preset}"/>
        <integer name="horizontal_resolution" value="60"/></sensor>"""
    loaded = load_scene(write_scene(sensor + WALL))
    cfg = loaded.lidars[0].config
    p = scan(loaded.scene, loaded.lidars[0], to_world=np.eye(4)).points()
    d, o = cfg.pattern.beams()
    o = np.zeros_like(d) if o is None else o
    with np.errstate(divide="ignore"):
        t = (10.0 - o[:, 0]) / d[:, 0]
    hit = o + t[:, None] * d
    meets = (d[:, 0] > 0) & (np.abs(hit[:, 1]) < 40.0) & (np.abs(hit[:, 2]) < 40.0)
    meets &= (t >= cfg.range_min) & (t <= cfg.range_max)
    beam = p["ring"].astype(np.int64) * cfg.horizontal_resolution + p["column"]
    assert np.array_equal(np.sort(beam), np.flatnonzero(meets))
    np.testing.assert_allclose(p["xyz"], hit[beam], atol=2e-3)
    if preset == "at128":
        assert meets.all()
