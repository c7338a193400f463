"""Beam patterns of spinning LiDARs: sensor presets and the (ring, column) ray grid.

Frame: x forward, y left, z up. Azimuth is measured counter-clockwise from +x, elevation positive
up. Column ``j`` of ``cols`` points at azimuth ``a0 + (j + 0.5) * fov_h / cols`` (degrees), with
``a0 = 0`` or, for a centred field of view, ``a0 = -fov_h / 2`` (the columns then span
``±fov_h/2`` around +x); the half-column offset keeps rays off axis-aligned edges. Rings are
ordered like the rows of a range image: ring 0 is the **highest** beam, the last ring the lowest.

Timing (:class:`BeamPattern`): the head spins at ``rotation_rate`` Hz, clockwise seen from above
(Velodyne and Ouster alike; Ouster's SDK numbers columns by decreasing encoder angle) or
counter-clockwise; a sweep starts when the head points at ``scan_start_azimuth`` (default 180°,
behind the sensor, where Ouster frames split and Velodyne-on-KITTI scans wrap). Column ``j``
fires at ``t_j = T · frac(s · (a_j - a_start) / 360°)`` with ``T = 1 / rotation_rate`` and
``s = -1`` (clockwise) or ``+1``; the laser of ring ``r`` fires ``τ_r`` later (its firing offset,
:mod:`nidar_mi.lidar.layouts`), when the head has turned on by ``s · 360° · τ_r / T``.

Uniform elevation tables (degrees; the per-laser tables are in :mod:`nidar_mi.lidar.layouts`):

* ``vlp16`` — Velodyne VLP-16 user manual (63-9243 Rev. E), Table 9-1: -15..+15 in 2 deg steps.
* ``hdl32e`` — Velodyne HDL-32E user manual (63-9113 Rev. J), laser table: -30.67..+10.67 in 4/3 deg
  steps (the sensor of nuScenes, Caesar et al., CVPR 2020).
* ``hdl64e`` — Velodyne HDL-64E S2 datasheet: vertical field of view +2 deg up to -24.8 deg down
  with 64 equally spaced subdivisions (~0.4 deg); the sensor of KITTI (Geiger et al., IJRR 2013:
  26.8 deg vertical field of view).
* ``os1_64`` — Ouster OS1 datasheet (early revision, "High Resolution Imaging LIDAR"): 64 channels,
  vertical field of view +16.6 .. -16.6 deg, uniform spacing; 1024 columns.
* ``os1_128`` — Ouster OS1 Rev 6 datasheet: 128 channels, 45 deg vertical field of view, uniform
  spacing (-22.5..+22.5).
* ``waymo_top`` — Waymo Open Dataset top LiDAR (Sun et al., CVPR 2020, Table 1): 64 beams over
  -17.6..+2.4 deg; the real beam inclinations are non-uniform and per-vehicle, here uniform over that
  field of view; 2650 columns as in the dataset's range images.
* ``vlp32c`` — Velodyne VLP-32C: 32 channels over +15..-25 deg (user manual 63-9325 Rev C,
  Table 9-6); 1808 columns, the 55.296 µs firing sequences of one turn at 10 Hz.
* ``vls128`` — Velodyne VLS-128: 128 channels over +15..-25 deg (Velodyne's key features as quoted
  in Apollo's installation guide); 1876 columns, the 53.3 µs firing sequences (user manual
  63-9483 Rev A, 9.3.1.1) of one turn at 10 Hz.
* ``os0_128`` — Ouster OS0 Rev 6 datasheet (v2.5): 128 channels over +45..-45 deg; 2048 columns
  (the 2048 x 10 Hz mode).
* ``os2_128`` — Ouster OS2 Rev 6 datasheet (v2.5): 128 channels over 22.5 deg
  (+11.25..-11.25); 2048 columns.
* ``pandar64`` — Hesai Pandar64: 64 channels over +15..-25 deg (the real channels are denser near
  the horizon: the per-laser table); 1800 columns (0.2 deg at 10 Hz).
* ``xt32`` — Hesai PandarXT-32 user manual X01-en-220410: 32 channels, +15..-16 deg 1 deg apart;
  2000 columns (0.18 deg at 10 Hz).
* ``at128`` — Hesai AT128 (AT128E2X): 128 channels over +12.9..-12.5 deg (0.2 deg apart), a
  120 deg horizontal field of view centred on +x, 1200 columns (0.1 deg). Its channels are fixed;
  a mirror of three facets (the SDK's correction file) on a motor turning at 200 rpm sweeps
  them, the beam at twice the mirror's angle (the SDK's azimuth is 2 · (encoder - facet start)),
  so ``rotation_rate`` is 2 · 200 / 60 = 6.67 Hz of the beam: the 120 deg view in 50 ms (one
  column every 41.67 µs, as TIER IV's decoder times the blocks), from +60 deg clockwise. Each
  facet is one frame: 120 deg of mirror, 240 deg of beam (``frame_sweep_deg``), 100 ms, so the
  frame rate is 3 · 200 / 60 = 10 Hz (:attr:`nidar_mi.lidar.config.LidarConfig.frame_rate`);
  half of each frame the beam is outside the view and nothing fires.
* ``livox_mid40`` — Livox Mid-40: one laser, a 38.4 deg circular field of view around +x swept
  in a non-repetitive rosette by two Risley prisms (:mod:`nidar_mi.lidar.risley`); 10,000 shots
  per sweep at 10 Hz (100,000 points/s).

Ranges and every other figure of these presets, with the source of each (and where none was
found): ``docs/SENSORS.md``, "Presets against their sources".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .layouts import LaserTable
from .risley import MID40_PRISMS, RisleyPrisms

__all__ = [
    "Preset",
    "PRESETS",
    "elevation_table",
    "parse_angles",
    "azimuths_deg",
    "beam_directions",
    "BeamPattern",
    "RisleyPattern",
]


@dataclass(frozen=True)
class Preset:
    """A sensor's beam pattern and nominal limits.

    Attributes:
        elevations_deg: (R,) elevation of each ring in degrees, ring 0 highest (the uniform
            table; the per-laser table, where there is one, is
            :func:`nidar_mi.lidar.layouts.preset_table`).
        horizontal_resolution: columns per revolution.
        range_min: minimum range in m.
        range_max: maximum range in m.
        reference: datasheet or paper the table comes from.
        fov_h: default horizontal field of view, degrees (360 for a spinning head).
        fov_h_centred: whether the default field of view is centred on +x.
        rotation_rate: default rate of the horizontal sweep, Hz: turns per second of the head,
            or of the beam for a scanning mirror (``at128``).
        scan_start_azimuth: default azimuth where a sweep starts, degrees.
        frame_sweep_deg: beam azimuth swept per frame, degrees: 360 for a spinning head (one
            frame per turn); 240 for the ``at128``, whose frame is one 120 deg mirror facet.
        risley: the prism pair of a Risley-prism (rosette) sensor, None for a spinning head or a
            scanning mirror (:mod:`nidar_mi.lidar.risley`).
        detection_threshold: default ``raw``-mode detection threshold (1/m², gain 1): 0 where
            the datasheet gives no range for a stated reflectivity; for ``hdl64e`` the
            datasheet's 10 % at 50 m (:mod:`nidar_mi.lidar.link_budget`).
        receiver_noise_std: default ``raw``-mode receiver noise σ_n (1/m², gain 1): the
            threshold over ``Q⁻¹(P_FA)`` for a false-alarm probability of 1e-4 per ranging
            event (:func:`nidar_mi.lidar.link_budget.noise_for`); 0 (a step at the
            threshold) where the threshold is 0.
    """

    elevations_deg: tuple[float, ...]
    horizontal_resolution: int
    range_min: float
    range_max: float
    reference: str
    detection_threshold: float = 0.0
    receiver_noise_std: float = 0.0
    fov_h: float = 360.0
    fov_h_centred: bool = False
    rotation_rate: float = 10.0
    scan_start_azimuth: float = 180.0
    frame_sweep_deg: float = 360.0
    risley: RisleyPrisms | None = None


def _desc(values: np.ndarray) -> tuple[float, ...]:
    return tuple(float(round(v, 4)) for v in sorted(values.tolist(), reverse=True))


PRESETS: dict[str, Preset] = {
    "vlp16": Preset(
        _desc(np.arange(-15.0, 15.0 + 1e-9, 2.0)),
        1800,
        0.5,
        100.0,
        "Velodyne VLP-16 user manual 63-9243 Rev. E",
    ),
    "hdl32e": Preset(
        _desc(-30.67 + np.arange(32) * (41.34 / 31.0)),
        1084,
        0.5,
        100.0,
        "Velodyne HDL-32E user manual 63-9113 Rev. J (nuScenes)",
    ),
    "hdl64e": Preset(
        _desc(np.linspace(2.0, -24.8, 64)),
        2048,
        0.9,
        120.0,
        "Velodyne HDL-64E S2 datasheet (KITTI, Geiger et al. IJRR 2013)",
        4.0e-5,  # 0.10 / 50 m²: 10 % at normal incidence detected to 50 m (datasheet)
        4.0e-5 / 3.719016485455709,  # T / Q⁻¹(1e-4): false alarms 1e-4 per ranging event
    ),
    "os1_64": Preset(
        _desc(np.linspace(16.6, -16.6, 64)),
        1024,
        0.8,
        120.0,
        "Ouster OS1 datasheet (early revision): +16.6..-16.6 deg, 0.8-120 m",
    ),
    "os1_128": Preset(
        _desc(np.linspace(-22.5, 22.5, 128)),
        2048,
        0.3,
        120.0,
        "Ouster OS1 Rev 6 datasheet",
    ),
    "waymo_top": Preset(
        _desc(np.linspace(-17.6, 2.4, 64)),
        2650,
        0.5,
        75.0,
        "Waymo Open Dataset top LiDAR (Sun et al. CVPR 2020)",
    ),
    "vlp32c": Preset(
        _desc(np.linspace(15.0, -25.0, 32)),
        1808,  # firing sequences per turn at 10 Hz: 1 / (10 Hz x 55.296 us) = 1808.4
        0.4,  # ros-drivers/velodyne VLP-32C_points.launch min_range (no datasheet minimum found)
        200.0,
        "Velodyne VLP-32C user manual 63-9325 Rev C (elevations, firing in pairs) and datasheet "
        "as quoted in autonomymobilitylab/HenryRTD: 32 channels, +15..-25 deg, 360 deg, "
        "200 m, ~600,000 points/s single return",
    ),
    "vls128": Preset(
        _desc(np.linspace(15.0, -25.0, 128)),
        1876,  # firing sequences per turn at 10 Hz: 1 / (10 Hz x 53.3 us) = 1876.2
        0.4,  # ros-drivers/velodyne VLS128_points.launch min_range (no datasheet minimum found)
        300.0,
        "Velodyne VLS-128 user manual 63-9483 Rev A (53.3 us firing sequence, groups of 8) and "
        "key features as quoted in ApolloAuto/apollo: 128 channels, +15..-25 deg, 360 deg, "
        "up to 300 m, up to ~9.6 million points/s over 4 returns",
    ),
    "os0_128": Preset(
        _desc(np.linspace(45.0, -45.0, 128)),
        2048,
        0.3,
        50.0,
        "Ouster OS0 Rev 6 datasheet v2.5 as quoted in isaac-sim/IsaacSim: 128 channels, "
        "+45..-45 deg, 360 deg, 2048 x 10 Hz, minimum range 0.3 m, 50 m (>50 % detection, "
        "100 klx)",
    ),
    "os2_128": Preset(
        _desc(np.linspace(11.25, -11.25, 128)),
        2048,
        1.0,
        240.0,
        "Ouster OS2 Rev 6 datasheet v2.5 as quoted in isaac-sim/IsaacSim: 128 channels, "
        "+11.25..-11.25 deg, 360 deg, 2048 x 10 Hz, minimum range 1.0 m, 240 m (>50 % "
        "detection, 100 klx)",
    ),
    "pandar64": Preset(
        _desc(np.linspace(15.0, -25.0, 64)),
        1800,  # 0.2 deg at 10 Hz
        0.3,
        200.0,
        "Hesai Pandar64 (TIER IV nebula decoder's sensor constants; user manual 4.2.2: 600 rpm "
        "default): 64 channels, +15..-25 deg, 360 deg, 0.2 deg at 10 Hz, 0.3-200 m",
    ),
    "xt32": Preset(
        _desc(np.linspace(15.0, -16.0, 32)),
        2000,  # 0.18 deg at 10 Hz
        0.05,
        120.0,
        "Hesai PandarXT-32 user manual X01-en-220410 p.13 (as quoted in isaac-sim/IsaacSim) and "
        "TIER IV nebula: 32 channels, +15..-16 deg, 360 deg, 0.18 deg at 10 Hz, 0.05-120 m",
    ),
    "at128": Preset(
        _desc(np.linspace(12.9, -12.5, 128)),
        1200,  # 0.1 deg over 120 deg, one frame per mirror facet, 10 frames/s
        0.5,
        200.0,
        "Hesai AT128E2X (HesaiLidar_SDK_2.0 correction file: 3 mirror facets; TIER IV nebula: "
        "120 x 25.4 deg, 0.1 x 0.2 deg, 200 rpm; user manual A01-en-230510 as transcribed in "
        "tier4/AWSIM: 200 m, near field from 0.5 m)",
        fov_h=120.0,
        fov_h_centred=True,
        # the beam sweeps at twice the mirror's 200 rpm: 2400 deg/s, 120 deg in 50 ms, from the
        # left edge (+60 deg) clockwise; a frame is one facet, 240 deg of beam (100 ms)
        rotation_rate=2.0 * 200.0 / 60.0,
        scan_start_azimuth=60.0,
        frame_sweep_deg=240.0,
    ),
    "livox_mid40": Preset(
        (0.0,),  # one laser behind two turning prisms
        10_000,  # shots per sweep: 100,000 points/s at 10 sweeps/s
        1.0,  # HELIOS++ livox_mid-40 rangeMin_m (no datasheet minimum found)
        260.0,
        "Livox Mid-40 (Livox wiki, Mid series point cloud specifications): 38.4 deg circular "
        "field of view, 100,000 points/s, 260 m at 80 % reflectivity; the rosette of two "
        "Risley prisms (nidar_mi.lidar.risley)",
        fov_h=38.4,
        fov_h_centred=True,
        risley=MID40_PRISMS,
    ),
}


def elevation_table(preset: str) -> np.ndarray:
    """(R,) float64 uniform elevations in degrees of a preset, ring 0 highest."""
    return np.asarray(PRESETS[preset].elevations_deg, dtype=np.float64)


def parse_angles(text: str) -> np.ndarray:
    """Parse a comma- or space-separated list of elevation angles in degrees.

    Returns:
        (R,) float64 sorted with ring 0 highest.

    Raises:
        ValueError: a value is not a number, not finite, or outside [-90, 90], or the list is empty.
    """
    parts = [p for p in text.replace(",", " ").split() if p]
    if not parts:
        raise ValueError("is empty")
    values = []
    for p in parts:
        try:
            v = float(p)
        except ValueError:
            raise ValueError(f"has a non-numeric angle '{p}'") from None
        if not np.isfinite(v) or abs(v) > 90.0:
            raise ValueError(f"has an angle outside [-90, 90] degrees: {p}")
        values.append(v)
    return np.sort(np.asarray(values, dtype=np.float64))[::-1].copy()


def azimuths_deg(cols: int, fov_h: float = 360.0, start_deg: float = 0.0) -> np.ndarray:
    """(cols,) azimuth of each column in degrees: ``start_deg + (j + 0.5) * fov_h / cols``."""
    az = (np.arange(cols, dtype=np.float64) + 0.5) * (fov_h / cols)
    return az + start_deg if start_deg else az


def beam_directions(
    elevations_deg: np.ndarray, cols: int, fov_h: float = 360.0, start_deg: float = 0.0
) -> np.ndarray:
    """Unit ray directions of a uniform scan in the LiDAR frame.

    Args:
        elevations_deg: (R,) ring elevations in degrees.
        cols: columns per scan.
        fov_h: horizontal field of view in degrees.
        start_deg: azimuth where column 0's edge lies (``-fov_h / 2`` for a centred view).

    Returns:
        (R, cols, 3) float64 unit vectors; ``[r, j]`` is ring r, column j.
    """
    el = np.deg2rad(np.asarray(elevations_deg, dtype=np.float64))[:, None]
    az = np.deg2rad(azimuths_deg(cols, fov_h, start_deg))[None, :]
    return np.stack(
        [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el) * np.ones_like(az)], axis=-1
    )


@dataclass(frozen=True)
class BeamPattern:
    """Every beam of one sweep: direction, origin and firing time, for flat beam indices.

    Beam ``b`` is ring ``b // cols``, column ``b % cols`` (row-major over the range image), so any
    range of beams can be generated on its own (scans are cast in chunks of bounded memory).

    Attributes:
        table: the per-laser layout (one entry per ring).
        cols: columns per sweep.
        fov_h: horizontal field of view, degrees.
        start_deg: azimuth of column 0's edge, degrees (0, or ``-fov_h/2`` when centred).
        rotation_rate: spin rate, Hz.
        spin: -1 clockwise seen from above, +1 counter-clockwise.
        scan_start_azimuth: azimuth where a sweep starts, degrees.
    """

    table: LaserTable
    cols: int
    fov_h: float = 360.0
    start_deg: float = 0.0
    rotation_rate: float = 10.0
    spin: int = -1
    scan_start_azimuth: float = 180.0

    @property
    def rings(self) -> int:
        return self.table.rings

    @property
    def size(self) -> int:
        """Number of beams, rings × columns."""
        return self.rings * self.cols

    @property
    def _ideal(self) -> bool:
        t = self.table
        return not (t.has_origins or any(t.azimuth_offset_deg) or any(t.firing_offset_s))

    def column_azimuth_deg(self) -> np.ndarray:
        """(C,) float64 azimuth of each column, degrees."""
        return azimuths_deg(self.cols, self.fov_h, self.start_deg)

    def column_time_s(self) -> np.ndarray:
        """(C,) float64 firing time of each column since the sweep's start, s, in [0, T)."""
        turn = self.spin * (self.column_azimuth_deg() - self.scan_start_azimuth) / 360.0
        return np.mod(turn, 1.0) / self.rotation_rate

    def time_s(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """(n,) float64 firing time of beams ``start..stop`` since the sweep's start, s."""
        ring, col = self._index(start, stop)
        return self.column_time_s()[col] + self.table.array("firing_offset_s")[ring]

    def _index(self, start: int, stop: int | None) -> tuple[np.ndarray, np.ndarray]:
        stop = self.size if stop is None else stop
        b = np.arange(start, stop, dtype=np.int64)
        return b // self.cols, b % self.cols

    def beams(self, start: int = 0, stop: int | None = None):
        """Directions and origins of beams ``start..stop`` in the LiDAR frame.

        Returns:
            ``(directions, origins)``: (n, 3) float64 unit vectors and (n, 3) float64 beam origins
            in m, or None when every beam starts at the origin. An ideal table (no offsets,
            corrections or firing offsets) gives exactly :func:`beam_directions`.
        """
        ring, col = self._index(start, stop)
        if self._ideal:
            el = np.deg2rad(self.table.array("elevation_deg"))
            az = np.deg2rad(self.column_azimuth_deg())
            cos_el, sin_el, cos_az, sin_az = np.cos(el), np.sin(el), np.cos(az), np.sin(az)
            d = np.stack(
                [cos_el[ring] * cos_az[col], cos_el[ring] * sin_az[col], sin_el[ring]], axis=-1
            )
            return d, None
        return self.rays_at(ring, self.column_azimuth_deg()[col])

    def rays_at(self, ring: np.ndarray, column_azimuth_deg: np.ndarray):
        """Directions and origins of lasers ``ring`` fired in columns at ``column_azimuth_deg``.

        Args:
            ring: (n,) int ring indices.
            column_azimuth_deg: (n,) azimuth of the column (the head's angle), degrees.

        Returns:
            ``(directions, origins)``: (n, 3) float64, origins None when every beam starts at
            the origin.
        """
        t = self.table
        drift = self.spin * 360.0 * self.rotation_rate * t.array("firing_offset_s")
        phi_c = np.deg2rad(np.asarray(column_azimuth_deg, dtype=np.float64))
        phi = phi_c + np.deg2rad(t.array("azimuth_offset_deg") + drift)[ring]
        theta = np.deg2rad(t.array("elevation_deg"))[ring]
        cp, sp, ct, st = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta)
        d = np.stack([ct * cp, ct * sp, st], axis=-1)
        if not t.has_origins:
            return d, None
        v = t.array("vertical_offset_m")[ring]
        h = t.array("horizontal_offset_m")[ring]
        n = t.radial_offset_m
        o = np.stack(
            [
                -v * st * cp - h * sp + n * np.cos(phi_c),
                -v * st * sp + h * cp + n * np.sin(phi_c),
                v * ct + t.z_offset_m,
            ],
            axis=-1,
        )
        return d, o


@dataclass(frozen=True)
class RisleyPattern(BeamPattern):
    """The beams of one sweep of a Risley-prism LiDAR (:mod:`nidar_mi.lidar.risley`): one ring
    (the laser), one column per shot, shot ``j`` at ``t_j = j / (cols · rotation_rate)``.

    Attributes:
        prisms: the prism pair (required).
        (the rest as :class:`BeamPattern`; the laser's firing offset, ``fov_h``, ``start_deg``,
        ``spin`` and ``scan_start_azimuth`` do not move its beams)
    """

    prisms: RisleyPrisms | None = None

    def column_time_s(self) -> np.ndarray:
        """(C,) float64 firing time of each shot since the sweep's start, s."""
        return np.arange(self.cols, dtype=np.float64) / (self.cols * self.rotation_rate)

    def column_azimuth_deg(self) -> np.ndarray:
        """(C,) float64 azimuth of each shot's beam, degrees (counter-clockwise from +x)."""
        d = self.prisms.directions(self.column_time_s())
        return np.degrees(np.arctan2(d[:, 1], d[:, 0]))

    def time_s(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """(n,) float64 firing time of beams ``start..stop`` since the sweep's start, s."""
        _, col = self._index(start, stop)
        return self.column_time_s()[col]

    def beams(self, start: int = 0, stop: int | None = None):
        """``(directions, None)`` of beams ``start..stop``: (n, 3) float64 unit vectors, every
        beam from the sensor origin."""
        return self.prisms.directions(self.time_s(start, stop)), None

    def rays_at(self, ring: np.ndarray, column_azimuth_deg: np.ndarray):
        """Not defined for a Risley pattern (a shot's direction is not set by an azimuth).

        Raises:
            ValueError: always.
        """
        raise ValueError("a Risley-prism pattern has no beams per column azimuth")
