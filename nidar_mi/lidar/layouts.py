"""Per-laser layouts of real spinning LiDARs: the published tables, and calibration files.

A :class:`LaserTable` holds, for every laser (ordered by ring: ring 0 is the highest beam), its
elevation, its azimuth offset from the column's azimuth, where its beam starts, and when it
fires within its column. :mod:`nidar_mi.lidar.pattern` turns it into rays.

Beam origins follow the drivers' point models (frame x forward, y left, z up; ``θ`` the laser's
elevation, ``φ`` its beam's azimuth, ``φ_c`` the column's azimuth)::

    origin = v · (-sinθ cosφ, -sinθ sinφ, cosθ)      Velodyne vert_offset_correction: the beam
           + h · (-sinφ, cosφ, 0)                     line passes v/cosθ above the axis; h sideways
           + n · (cos φ_c, sin φ_c, 0) + (0, 0, z0)   Ouster lidar_origin_to_beam_origin, and the
                                                      lidar origin above the sensor frame

(ros-drivers/velodyne ``velodyne_pointcloud/src/lib/rawdata.cc`` ``RawData::unpack``: ``z = d·sinθ
+ v·cosθ``, ``xy = d·cosθ - v·sinθ``; ouster-sdk ``ouster_core/src/xyzlut.cpp``). The range of a
return is the path length from the beam's own origin; distance corrections of a real unit
(``dist_correction``) are measurement calibration and are not simulated.

Shipped tables (``nidar_mi/lidar/data/*.csv``, each file names its source repository, commit and
path in its header; all BSD-licensed). Hesai's azimuths grow clockwise: a table's azimuth offset
is minus Hesai's (plus the AT128's, whose points are at minus it). Hesai's firing times are kept
as published, less the earliest where some are negative (Pandar64):

========================  ==================================================================
``hdl64e``                HDL-64E S2.1 factory calibration of one unit (ros-drivers/velodyne
                          ``64e_s2.1-sztaki.xml``): two blocks, per-laser vertical/azimuth
                          corrections and offsets; the S2 firing time table. Every HDL-64E
                          unit has its own table: load yours with ``calibration_file``.
``hdl32e``                HDL-32E (ros-drivers/velodyne ``32db.yaml``; offsets from Velodyne
                          drawing 86-0106 via velodyne_decoder); 1.152 µs per firing.
``vlp16``                 VLP-16 (``VLP16db.yaml``; offsets 41.91 mm·tan(-θ)); 2.304 µs per
                          firing.
``os1_64``, ``os1_128``   Ouster OS1-64 (fw v2.1.2) and OS1-128 (fw v2.3.0) sensor metadata
                          (ouster-sdk test data): beam altitude and azimuth tables, beam origin
                          12.163 / 15.806 mm from the axis, lidar origin 36.18 mm above the
                          sensor frame; all beams of a column fire together.
``vlp32c``                VLP-32C (ros-drivers/velodyne ``VeloView-VLP-32C.yaml``; offsets
                          42.4 mm·tan(-θ)); pairs of lasers fire 2.304 µs apart.
``vls128``                VLS-128 / Alpha Prime (ros-drivers/velodyne ``VLS128.yaml``; offsets
                          58.63 mm·tan(-θ)); groups of 8 lasers 2.665 µs apart.
``os0_128``, ``os2_128``  Ouster OS0-128 and OS2-128 (fw v2.3.0) sensor metadata (ouster-sdk test
                          data): beam origin 27.67 / 13.762 mm from the axis, lidar origin
                          36.18 / 78.296 mm above the sensor frame.
``pandar64``              Pandar64 angle and firing time correction files (HesaiLidar_SDK_2.0).
``xt32``                  PandarXT-32 angle and firing time correction files (HesaiLidar_SDK_2.0).
``at128``                 AT128E2X angle correction (binary, HesaiLidar_SDK_2.0) and firing times:
                          128 channels' elevations and azimuth offsets.
========================  ==================================================================

Calibration files (:func:`read_calibration`): a Velodyne ``db.xml`` (degrees and cm, e.g. KITTI's
``velodynecalib_S2_factory_flatness_intensity.xml``), the ROS velodyne driver's YAML (radians and
m), or Ouster sensor metadata JSON.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, replace
from importlib import resources

import numpy as np

__all__ = [
    "LaserTable",
    "TABLE_FILES",
    "uniform_table",
    "preset_table",
    "read_calibration",
]

#: Preset name -> (data file, beam origin radius in m, lidar origin height in m, reference).
TABLE_FILES: dict[str, tuple[str, float, float]] = {
    "vlp16": ("vlp16.csv", 0.0, 0.0),
    "hdl32e": ("hdl32e.csv", 0.0, 0.0),
    "hdl64e": ("hdl64e_s2_sztaki.csv", 0.0, 0.0),
    "os1_64": ("os1_64.csv", 12.163e-3, 36.18e-3),
    "os1_128": ("os1_128.csv", 15.806e-3, 36.18e-3),
    "vlp32c": ("vlp32c.csv", 0.0, 0.0),
    "vls128": ("vls128.csv", 0.0, 0.0),
    "os0_128": ("os0_128.csv", 27.67e-3, 36.18e-3),
    "os2_128": ("os2_128.csv", 13.762e-3, 78.296e-3),
    "pandar64": ("pandar64.csv", 0.0, 0.0),
    "xt32": ("xt32.csv", 0.0, 0.0),
    "at128": ("at128.csv", 0.0, 0.0),
}


@dataclass(frozen=True)
class LaserTable:
    """Per-laser layout, one entry per ring (ring 0 = highest elevation).

    Attributes:
        laser_id: (R,) the laser's id in the sensor's own numbering (firing/packet order).
        elevation_deg: (R,) elevation θ of the beam, degrees, strictly decreasing.
        azimuth_offset_deg: (R,) beam azimuth minus the column's azimuth, degrees
            (counter-clockwise positive; Velodyne ``rot_correction``).
        vertical_offset_m: (R,) Velodyne ``vert_offset_correction`` v, m.
        horizontal_offset_m: (R,) Velodyne ``horiz_offset_correction`` h, m.
        firing_offset_s: (R,) firing time after the column's time, s.
        radial_offset_m: Ouster beam origin distance from the axis n, m.
        z_offset_m: height z0 of the lidar origin above the sensor frame, m.
        source: where the table comes from (file or preset).
    """

    laser_id: tuple[int, ...]
    elevation_deg: tuple[float, ...]
    azimuth_offset_deg: tuple[float, ...]
    vertical_offset_m: tuple[float, ...]
    horizontal_offset_m: tuple[float, ...]
    firing_offset_s: tuple[float, ...]
    radial_offset_m: float = 0.0
    z_offset_m: float = 0.0
    source: str = ""

    @property
    def rings(self) -> int:
        return len(self.elevation_deg)

    @property
    def has_origins(self) -> bool:
        """Whether any beam starts off the sensor origin."""
        return bool(
            self.radial_offset_m
            or self.z_offset_m
            or any(self.vertical_offset_m)
            or any(self.horizontal_offset_m)
        )

    def array(self, name: str) -> np.ndarray:
        """(R,) float64 copy of one per-laser attribute."""
        return np.asarray(getattr(self, name), dtype=np.float64)

    def with_firing(self, firing_offset_s: np.ndarray) -> LaserTable:
        """The same geometry with other firing offsets (indexed by ring)."""
        return replace(self, firing_offset_s=tuple(float(v) for v in firing_offset_s))


def _sorted_table(
    laser_id, elevation, azimuth, v_off, h_off, firing, *, radial=0.0, z0=0.0, source=""
) -> LaserTable:
    """A table from per-laser arrays in any order, sorted by elevation (highest first)."""
    elevation = np.asarray(elevation, dtype=np.float64)
    if elevation.size == 0:
        raise ValueError("has no lasers")
    if not np.all(np.isfinite(elevation)) or np.any(np.abs(elevation) > 90.0):
        raise ValueError("has an elevation outside [-90, 90] degrees")
    cols = [np.asarray(a, dtype=np.float64) for a in (azimuth, v_off, h_off, firing)]
    for c in cols:
        if c.shape != elevation.shape or not np.all(np.isfinite(c)):
            raise ValueError("has a missing or non-finite per-laser value")
    if np.any(np.abs(cols[0]) > 180.0) or np.any(np.abs(cols[1:3]) > 1.0):
        raise ValueError("has an azimuth correction beyond 180 degrees or an offset beyond 1 m")
    order = np.argsort(-elevation, kind="stable")
    if np.any(np.diff(elevation[order]) == 0.0):
        raise ValueError("has two lasers at the same elevation")

    def tup(a):
        return tuple(float(v) for v in np.asarray(a)[order])

    return LaserTable(
        laser_id=tuple(int(v) for v in np.asarray(laser_id)[order]),
        elevation_deg=tup(elevation),
        azimuth_offset_deg=tup(cols[0]),
        vertical_offset_m=tup(cols[1]),
        horizontal_offset_m=tup(cols[2]),
        firing_offset_s=tup(cols[3]),
        radial_offset_m=float(radial),
        z_offset_m=float(z0),
        source=source,
    )


def uniform_table(elevations_deg) -> LaserTable:
    """An ideal table: the given elevations (ring 0 highest), every beam from the origin, every
    laser of a column firing at the column's time."""
    el = np.asarray(elevations_deg, dtype=np.float64)
    zeros = np.zeros_like(el)
    return LaserTable(
        laser_id=tuple(range(len(el))),
        elevation_deg=tuple(float(v) for v in el),
        azimuth_offset_deg=tuple(float(v) for v in zeros),
        vertical_offset_m=tuple(float(v) for v in zeros),
        horizontal_offset_m=tuple(float(v) for v in zeros),
        firing_offset_s=tuple(float(v) for v in zeros),
        source="uniform",
    )


def _read_csv(text: str) -> dict[str, np.ndarray]:
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    header = lines[0].split(",")
    rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]], dtype=np.float64)
    return {name: rows[:, i] for i, name in enumerate(header)}


_preset_cache: dict[str, LaserTable] = {}


def preset_table(preset: str) -> LaserTable:
    """The published per-laser table of a preset (:data:`TABLE_FILES`).

    Raises:
        KeyError: the preset has no per-laser table.
    """
    if preset not in _preset_cache:
        fname, radial, z0 = TABLE_FILES[preset]
        text = resources.files("nidar_mi.lidar").joinpath("data", fname).read_text("utf-8")
        c = _read_csv(text)
        _preset_cache[preset] = _sorted_table(
            c["laser_id"].astype(int),
            c["elevation_deg"],
            c["azimuth_offset_deg"],
            c["vertical_offset_m"],
            c["horizontal_offset_m"],
            c["firing_offset_us"] * 1e-6,
            radial=radial,
            z0=z0,
            source=f"nidar_mi/lidar/data/{fname}",
        )
    return _preset_cache[preset]


# --------------------------------------------------------------------------- calibration files


def _velodyne_db_xml(path: str) -> LaserTable:
    """A Velodyne ``db.xml`` (boost serialisation: ``points_/item/px`` with ``id_``,
    ``vertCorrection_`` and ``rotCorrection_`` in degrees, ``vertOffsetCorrection_`` and
    ``horizOffsetCorrection_`` in cm). Python's expat refuses entity-expansion attacks."""
    import xml.etree.ElementTree as ET

    root = ET.parse(path).getroot()
    rows = []
    for px in root.iter("px"):
        f = {child.tag: (child.text or "").strip() for child in px}
        try:
            rows.append(
                (
                    int(f["id_"]),
                    float(f["vertCorrection_"]),
                    float(f["rotCorrection_"]),
                    float(f.get("vertOffsetCorrection_", 0.0)) / 100.0,
                    float(f.get("horizOffsetCorrection_", 0.0)) / 100.0,
                )
            )
        except KeyError as e:
            raise ValueError(f"a laser entry has no {e.args[0]}") from None
    if not rows:
        raise ValueError("has no <px> laser entries (not a Velodyne db.xml?)")
    a = np.array(rows, dtype=np.float64)
    enabled_node = root.find(".//enabled_")
    if enabled_node is not None:  # item i is laser id i
        flags = [(c.text or "").strip() != "0" for c in enabled_node.findall("item")]
        a = a[[int(i) >= len(flags) or flags[int(i)] for i in a[:, 0]]]
    return _sorted_table(
        a[:, 0].astype(int), a[:, 1], a[:, 2], a[:, 3], a[:, 4], np.zeros(len(a)), source=path
    )


def _velodyne_yaml(path: str) -> LaserTable:
    """The ROS velodyne driver's calibration YAML (``lasers:`` with ``laser_id``,
    ``vert_correction`` and ``rot_correction`` in radians, offsets in m)."""
    import yaml

    with open(path, encoding="utf-8") as f:
        doc = yaml.safe_load(f)
    lasers = doc.get("lasers") if isinstance(doc, dict) else None
    if not isinstance(lasers, list) or not lasers:
        raise ValueError("has no 'lasers' list (not a ROS velodyne calibration?)")
    try:
        a = np.array(
            [
                (
                    int(L["laser_id"]),
                    np.degrees(float(L["vert_correction"])),
                    np.degrees(float(L.get("rot_correction", 0.0))),
                    float(L.get("vert_offset_correction", 0.0)),
                    float(L.get("horiz_offset_correction", 0.0)),
                )
                for L in lasers
            ],
            dtype=np.float64,
        )
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"has a malformed laser entry ({e})") from None
    return _sorted_table(
        a[:, 0].astype(int), a[:, 1], a[:, 2], a[:, 3], a[:, 4], np.zeros(len(a)), source=path
    )


def _ouster_json(path: str) -> LaserTable:
    """Ouster sensor metadata (``beam_altitude_angles``, ``beam_azimuth_angles`` in degrees,
    ``lidar_origin_to_beam_origin_mm``, ``lidar_to_sensor_transform``; flat or under
    ``beam_intrinsics``)."""
    with open(path, encoding="utf-8") as f:
        doc = json.load(f)
    if not isinstance(doc, dict):
        raise ValueError("is not a JSON object")
    beams = doc.get("beam_intrinsics", doc)
    try:
        alt = np.asarray(beams["beam_altitude_angles"], dtype=np.float64)
        az = np.asarray(beams["beam_azimuth_angles"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise ValueError("has no beam_altitude_angles / beam_azimuth_angles") from None
    n = float(beams.get("lidar_origin_to_beam_origin_mm", 0.0)) / 1000.0
    lidar_to_sensor = doc.get("lidar_intrinsics", doc).get("lidar_to_sensor_transform")
    z0 = float(lidar_to_sensor[11]) / 1000.0 if lidar_to_sensor else 0.0
    zeros = np.zeros_like(alt)
    return _sorted_table(
        np.arange(len(alt)), alt, -az, zeros, zeros, zeros, radial=n, z0=z0, source=path
    )


def read_calibration(path: str | os.PathLike) -> LaserTable:
    """Read a per-laser calibration file; the format comes from its suffix.

    ``.xml``: Velodyne ``db.xml``; ``.yaml``/``.yml``: ROS velodyne YAML; ``.json``: Ouster sensor
    metadata. Firing offsets are zero (a preset given beside the file supplies its timing).

    Raises:
        ValueError: one line naming the file and what is wrong with it.
    """
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    readers = {".xml": _velodyne_db_xml, ".yaml": _velodyne_yaml, ".yml": _velodyne_yaml}
    readers[".json"] = _ouster_json
    if ext not in readers:
        raise ValueError(f"'{path}': unknown calibration format (use .xml, .yaml or .json)")
    if not os.path.isfile(path):
        raise ValueError(f"'{path}': no such file")
    try:
        return readers[ext](path)
    except ValueError as e:
        raise ValueError(f"'{path}' {e}") from None
    except Exception as e:  # malformed XML/YAML/JSON: many exception types
        text = " ".join(str(e).split()) or type(e).__name__
        raise ValueError(f"'{path}' cannot be read as a calibration file ({text})") from None
