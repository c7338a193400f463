"""The ``lidar`` sensor: a spinning LiDAR's beam pattern in a Mitsuba scene.

The plugin holds the validated parameters and the pose; :func:`nidar_mi.lidar.raycast.scan` casts
the whole pattern through Dr.Jit and applies the return model.

.. list-table::
   :header-rows: 1

   * - Parameter
     - Type
     - Meaning
     - Default
   * - ``preset``
     - string
     - ``vlp16``, ``hdl32e``, ``hdl64e``, ``os1_128``, ``waymo_top``
     - ``vlp16``
   * - ``elevation_angles``
     - string
     - comma-separated ring elevations (deg); overrides the preset's table
     - preset's
   * - ``horizontal_resolution``
     - integer
     - columns per scan
     - preset's
   * - ``fov_h``
     - float
     - horizontal field of view (deg); column j at azimuth (j+0.5)·fov_h/cols from +x
     - 360
   * - ``wavelength``
     - float
     - laser wavelength (nm)
     - 905
   * - ``gain``, ``range_min``, ``range_max``, ``atmospheric_extinction``, ``intensity_mode``,
       ``noise_intensity_std``, ``noise_range_std``, ``detection_threshold``, ``dropout``, ``seed``
     - see :mod:`nidar_mi.lidar.config`
     -
     -
   * - ``to_world``
     - transform
     - pose; LiDAR frame x forward, y left, z up
     - identity

.. code-block:: xml

    <sensor type="lidar" id="roof">
        <string name="preset" value="hdl64e"/>
        <float name="wavelength" value="905"/>
        <transform name="to_world"><translate x="0" y="0" z="1.73"/></transform>
    </sensor>
"""

from __future__ import annotations

import mitsuba as mi

from nidar_mi.lidar.config import PARAMETERS, LidarConfig

__all__ = ["register", "lidar_class", "LOAD_ERRORS"]

#: Validation messages of the last failed load, read by :mod:`nidar_mi.scene`.
LOAD_ERRORS: list[str] = []

_classes: dict[str, type] = {}


def lidar_class() -> type:
    """The ``lidar`` sensor class of the active variant."""
    return _classes[mi.variant()]


def register() -> None:
    """Define the sensor class for the active variant and register it as ``lidar``."""
    import drjit as dr

    class LidarSensor(mi.Sensor):
        def __init__(self, props: mi.Properties):
            super().__init__(props)
            name = props.id() or "lidar"
            values = {k: props.get(k) for k in PARAMETERS if k in props}
            try:
                self.config = LidarConfig.from_mapping(name, values)
            except ValueError as e:
                LOAD_ERRORS.append(str(e))
                raise

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            """A ray of the beam pattern: ``sample2.x`` picks the column, ``sample2.y`` the ring."""
            cfg = self.config
            el = mi.Float(cfg.elevations)
            ring = mi.UInt32(dr.minimum(sample2.y * cfg.rings, cfg.rings - 1))
            col = dr.minimum(
                mi.UInt32(sample2.x * cfg.horizontal_resolution), cfg.horizontal_resolution - 1
            )
            e = dr.deg2rad(dr.gather(mi.Float, el, ring))
            a = dr.deg2rad((mi.Float(col) + 0.5) * (cfg.fov_h / cfg.horizontal_resolution))
            d = mi.Vector3f(dr.cos(e) * dr.cos(a), dr.cos(e) * dr.sin(a), dr.sin(e))
            T = self.world_transform()
            return mi.Ray3f(T @ mi.Point3f(0.0), dr.normalize(T @ d), time), mi.Spectrum(1.0)

        def to_string(self):
            return f"LidarSensor[{self.config}]"

    _classes[mi.variant()] = LidarSensor
    mi.register_sensor("lidar", lambda props: LidarSensor(props))
