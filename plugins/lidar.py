"""The ``lidar`` sensor: a spinning LiDAR's beam pattern and pose in a Mitsuba scene.

Executed once per Mitsuba variant by :func:`nidar_mi.plugins.register_all`; see
:class:`LidarSensor`.
"""

from __future__ import annotations

import mitsuba as mi

from nidar_mi.lidar.config import PARAMETERS, LidarConfig

from . import PluginParameterError

__all__ = ["VARIANT", "LidarSensor"]

#: The Mitsuba variant this module's class belongs to.
VARIANT = mi.variant()


class LidarSensor(mi.Sensor):
    """A spinning LiDAR: the validated parameters (:class:`nidar_mi.lidar.config.LidarConfig`)
    and the pose. :func:`nidar_mi.lidar.scan.scan` casts its whole beam pattern through Dr.Jit
    and applies the return model of :mod:`nidar_mi.lidar.return_model`.

    .. list-table::
       :header-rows: 1

       * - Parameter
         - Type
         - Meaning
         - Default
       * - ``preset``
         - string
         - ``vlp16``, ``hdl32e``, ``hdl64e``, ``os1_128``, ``waymo_top`` (tables and sources in
           :mod:`nidar_mi.lidar.pattern`)
         - ``vlp16``
       * - ``elevation_angles``
         - string
         - comma-separated ring elevations in degrees, each in [-90, 90]; overrides the
           preset's table and implies the channel count
         - preset's
       * - ``horizontal_resolution``
         - integer
         - columns per scan, >= 1
         - preset's
       * - ``fov_h``
         - float
         - horizontal field of view in degrees, (0, 360]; column j points at azimuth
           (j + 0.5)·fov_h/cols from +x, counter-clockwise
         - 360
       * - ``wavelength``
         - float
         - laser wavelength in nm, [360, 1700]
         - 905
       * - ``gain``
         - float
         - g in I = g·ρ·T²·a(d,θ) + η, > 0
         - 1
       * - ``range_min``
         - float
         - minimum range in m, >= 0
         - preset's
       * - ``range_max``
         - float
         - maximum range in m, > range_min
         - preset's
       * - ``atmospheric_extinction``
         - float
         - α in 1/m (two-way loss exp(-2αd)), >= 0
         - 0
       * - ``intensity_mode``
         - string
         - ``raw`` (a = cosθ·exp(-2αd)/d²) or ``compensated`` (a = cosθ·exp(-2αd))
         - ``raw``
       * - ``noise_intensity_std``
         - float
         - σ of the additive Gaussian intensity noise η (added after detection, the result
           clipped at 0), >= 0
         - 0
       * - ``noise_range_std``
         - float
         - σ of the Gaussian range noise in m, >= 0
         - 0
       * - ``detection_threshold``
         - float
         - a return with g·ρ·T²·a below it is dropped, >= 0 (``hdl64e``: 4e-5, the
           datasheet's 10 % target at 50 m, :mod:`nidar_mi.lidar.calibration`)
         - preset's in ``raw`` mode (0 for the others and in ``compensated`` mode)
       * - ``dropout``
         - float
         - probability of dropping a return at random, [0, 1]
         - 0
       * - ``seed``
         - integer
         - seed of the noise and dropout draws, >= 0
         - 0
       * - ``to_world``
         - transform
         - pose; LiDAR frame x forward, y left, z up
         - identity

    An invalid value fails the scene load with :class:`nidar_mi.plugins.PluginParameterError`:
    one line naming the sensor and the parameter.

    .. code-block:: xml

        <sensor type="lidar" id="roof">
            <string name="preset" value="hdl64e"/>
            <float name="wavelength" value="905"/>
            <transform name="to_world"><translate x="0" y="0" z="1.73"/></transform>
        </sensor>

    The class does not implement Mitsuba's ``Sensor.sample_ray``: an integrator would use it to
    render the scene's radiance along the beams, which is not what a LiDAR measures. The beam
    pattern has one implementation, :func:`nidar_mi.lidar.pattern.beam_directions`, which the
    scan casts as a whole.
    """

    def __init__(self, props: mi.Properties) -> None:
        super().__init__(props)
        values = {k: props.get(k) for k in PARAMETERS if k in props}
        try:
            self.config = LidarConfig.from_mapping(props.id() or "lidar", values)
        except ValueError as e:
            raise PluginParameterError(str(e)) from None

    def to_string(self) -> str:
        return f"LidarSensor[{self.config}]"


mi.register_sensor("lidar", lambda props: LidarSensor(props))
