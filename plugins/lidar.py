"""The ``lidar`` sensor: a spinning LiDAR's beam pattern and pose in a Mitsuba scene.

Executed once per Mitsuba variant by :func:`nidar_mi.plugins.register_all`; see
:class:`LidarSensor`.
"""

from __future__ import annotations

import re

import mitsuba as mi

from nidar_mi.errors import NidarError
from nidar_mi.extras import require
from nidar_mi.lidar.config import PARAMETERS, LidarConfig
from nidar_mi.weather.conditions import PARAMETERS as WEATHER_PARAMETERS
from nidar_mi.weather.conditions import Weather

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
         - ``vlp16``, ``hdl32e``, ``hdl64e``, ``os1_64``, ``os1_128``, ``waymo_top``,
           ``vlp32c``, ``vls128``, ``os0_128``, ``os2_128``, ``pandar64``, ``xt32``, ``at128``,
           ``livox_mid40`` (tables and sources in :mod:`nidar_mi.lidar.pattern` and
           :mod:`nidar_mi.lidar.layouts`); a preset also sets the defaults of
           ``horizontal_resolution``, ``range_min``, ``range_max`` and, for ``at128``,
           ``fov_h`` (120), ``fov_h_centred``, ``rotation_rate`` and ``scan_start_azimuth``;
           ``livox_mid40``: one laser behind two Risley prisms (:mod:`nidar_mi.lidar.risley`),
           ``horizontal_resolution`` shots per sweep, ``rotation_rate`` sweeps per second
           (their product the point rate), ``fov_h``, ``spin`` and ``scan_start_azimuth``
           unused
         - ``vlp16``
       * - ``layout``
         - string
         - ``uniform``: the preset's uniform elevation table, every beam from the origin, all
           lasers of a column firing together; ``per_laser``: the preset's published per-laser
           table (elevations, azimuth corrections, beam origins, firing order and timing; not
           ``waymo_top``)
         - ``per_laser`` (for a preset with a table or with ``calibration_file``; ``uniform``
           for ``waymo_top`` and with ``elevation_angles``)
       * - ``calibration_file``
         - string
         - per-laser calibration of your own unit: a Velodyne ``db.xml``, a ROS velodyne
           ``.yaml`` or Ouster metadata ``.json`` (relative to the scene); with a preset of the
           same laser count, the preset's firing timing is kept
         - none
       * - ``elevation_angles``
         - string
         - comma-separated ring elevations in degrees, each in [-90, 90]; overrides the
           preset's uniform table and implies the channel count
         - preset's
       * - ``horizontal_resolution``
         - integer
         - columns per scan, >= 1
         - preset's
       * - ``fov_h``
         - float
         - horizontal field of view in degrees, (0, 360]; column j points at azimuth
           a0 + (j + 0.5)·fov_h/cols from +x, counter-clockwise
         - 360 (``at128``: 120)
       * - ``fov_h_centred``
         - boolean
         - ``true``: a0 = -fov_h/2, the columns span ±fov_h/2 around +x (forward);
           ``false``: a0 = 0, they span 0..fov_h
         - ``false`` (``at128``: ``true``)
       * - ``rotation_rate``
         - float
         - spin rate in Hz, (0, 100]; a 360° turn takes 1/rotation_rate s, a sweep of
           ``fov_h`` fov_h/360 of it; a sequence's default frame rate (one frame per turn;
           ``at128``: one mirror facet, 240° of beam, so 1.5 · rotation_rate)
         - 10 (``at128``: 6.67, its beam's turn rate: 120° in 50 ms, 10 frames/s)
       * - ``spin``
         - string
         - ``cw`` (clockwise seen from above, as Velodyne and Ouster sensors spin) or ``ccw``
         - ``cw``
       * - ``scan_start_azimuth``
         - float
         - azimuth in degrees where a sweep starts (firing time 0), [-360, 360]
         - 180 (``at128``: 60)
       * - ``wavelength``
         - float
         - laser wavelength in nm, [360, 1700]
         - 905
       * - ``gain``
         - float
         - g in I = g·ρ·T²·a(d,θ) + η, > 0
         - 1
       * - ``laser_gains``
         - string
         - comma-separated per-laser gains G_r, one per ring (ring 0 the highest), each > 0:
           a return of ring r is G_r·g·ρ·T²·a(d,θ) (a real unit's lasers differ; recovered by
           ``python -m nidar_mi.reconstruct``)
         - all 1
       * - ``range_response``
         - string
         - comma-separated ``d:f`` pairs (ranges in m, strictly increasing; factors >= 0): the
           expected intensity is multiplied by r(d), linear between the pairs and constant
           outside (a receiver's range-dependent gain, e.g. a sensor's own range compensation)
         - none (r = 1)
       * - ``laser_range_response``
         - string
         - per-laser factors m_r at the knots of ``range_response``: rows separated by ``;``,
           one per ring (ring 0 the highest), each comma-separated factors >= 0, one per knot;
           a return of ring r at range d is multiplied by r(d)·m_r(d), m_r linear between the
           knots and constant outside (each laser's own range compensation, as an HDL-64E's
           per-laser focal distance and slope give it; recovered by
           ``python -m nidar_mi.reconstruct``)
         - none (m_r = 1)
       * - ``intensity_offset``
         - float
         - b >= 0: the reported intensity is max(output - b, 0) (an encoding that reads 0 for
           weak returns it still detects, as KITTI's HDL-64E does); detection is unchanged
         - 0
       * - ``laser_offsets``
         - string
         - comma-separated per-laser offsets b_r >= 0, one per ring (ring 0 the highest): a
           return of ring r reports max(output - b - b_r, 0) (each laser's own floor, as an
           HDL-64E's per-laser minimum intensity sets it)
         - all 0
       * - ``laser_shadow``
         - string
         - beams the mounting blocks (the vehicle's roof, a mirror), comma-separated
           ``r:from:to`` triples: laser r (ring 0 the highest) returns nothing where its beam's
           sensor-frame azimuth atan2(y, x) lies in [from, to) degrees (-180 <= from < to <=
           180; an interval across ±180° is two triples); on every path, in any weather
           (recovered by ``python -m nidar_mi.reconstruct``)
         - none
       * - ``laser_range_offsets``
         - string
         - comma-separated per-laser range offsets o_r in m, |o_r| <= 1, one per ring (ring 0
           the highest): a return of ring r reports its range as d + o_r (no lower than 0;
           each laser's own timing bias, what a Velodyne's per-laser distance correction
           leaves; recovered by ``python -m nidar_mi.reconstruct``); detection, intensity and
           the range gates read d
         - all 0
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
         - T: a return is reported when the receiver's output g·ρ·T²·a + σ_n·n reaches it
           (n standard normal), >= 0 (``hdl64e``: 4e-5, the datasheet's 10 % target at 50 m
           detected half the time, :mod:`nidar_mi.lidar.link_budget`)
         - preset's in ``raw`` mode (0 for the others and in ``compensated`` mode)
       * - ``receiver_noise_std``
         - float
         - σ_n, the receiver noise on a return before the detection test (the unit of
           ``detection_threshold``), >= 0: P(detect) = Φ((g·ρ·T²·a − T)/σ_n); the reported
           intensity is the receiver's output. 0: a step at the threshold (``hdl64e``: 1.08e-5
           = T/3.72, false alarms 1e-4 per ranging event)
         - preset's in ``raw`` mode (0 for the others and in ``compensated`` mode)
       * - ``dropout``
         - float
         - probability of dropping a return at random, [0, 1]
         - 0
       * - ``beam_divergence``
         - float
         - full-angle beam divergence at 1/e² irradiance in mrad, [0, 100]; 0: ideal rays;
           > 0: sub-rays over the Gaussian footprint (:mod:`nidar_mi.lidar.footprint`), several
           returns per beam, specular echoes of glass
         - 0
       * - ``beam_sample_quality``
         - integer
         - rings of sub-rays over the footprint q, [1, 12]: 1 + 3·q·(q-1) sub-rays per beam
           (HELIOS++'s beamSampleQuality)
         - 3
       * - ``return_mode``
         - string
         - ``strongest``, ``first``, ``last`` or ``dual`` (strongest and last; the second
           strongest when they coincide); ``dual`` needs ``beam_divergence`` > 0 (refused
           without: a beam of no width has one return)
         - ``strongest``
       * - ``return_separation``
         - float
         - minimum range difference between two returns of one beam in m, > 0
         - 0.5
       * - ``seed``
         - integer
         - seed of the noise and dropout draws, >= 0
         - 0
       * - ``fog``
         - float
         - fog by its meteorological optical range in m, [5, 100000] (α at 550 nm = ln 20 /
           MOR; droplets by ``fog_type``): attenuation, the fog's own soft return
           (:mod:`nidar_mi.lidar.weather_returns`, docs/WEATHER.md)
         - none
       * - ``fog_type``
         - string
         - ``advection`` or ``radiation`` (droplet sizes, :mod:`nidar_mi.weather.particles`)
         - ``advection``
       * - ``rain``
         - float
         - rain rate in mm/h, [0, 300]: attenuation, drops in the beam
         - none
       * - ``snow``
         - float
         - snowfall rate as melted water in mm/h, [0, 50]; not with ``rain``
         - none
       * - ``to_world``
         - transform
         - pose; LiDAR frame x forward, y left, z up
         - identity

    An invalid value fails the scene load with :class:`nidar_mi.errors.NidarError`:
    one line naming the sensor and the parameter.

    .. code-block:: xml

        <sensor type="lidar" id="roof">
            <string name="preset" value="hdl64e"/>
            <float name="wavelength" value="905"/>
            <transform name="to_world"><translate x="0" y="0" z="1.73"/></transform>
        </sensor>

    The class does not implement Mitsuba's ``Sensor.sample_ray``: an integrator would use it to
    render the scene's radiance along the beams, which is not what a LiDAR measures. The beam
    pattern has one implementation, :class:`nidar_mi.lidar.pattern.BeamPattern`, which the
    scan casts as a whole.
    """

    def __init__(self, props: mi.Properties) -> None:
        super().__init__(props)
        values = {k: props.get(k) for k in PARAMETERS if k in props}
        if "calibration_file" in values:  # relative to the scene file
            path = str(values["calibration_file"])
            values["calibration_file"] = str(mi.file_resolver().resolve(path))
        name = props.id() or "lidar"
        self.config = LidarConfig.from_mapping(name, values)
        weather = {k: props.get(k) for k in WEATHER_PARAMETERS if k in props}
        try:
            #: the sensor's own weather (None: clear), what a scan uses unless told otherwise
            self.weather = Weather.from_mapping(weather)
        except NidarError as e:
            message = re.sub(r"`(\w+)`", r"parameter '\1'", str(e))
            raise NidarError(f"lidar '{name}': {message}") from None
        if self.weather is not None and not self.weather.clear:
            # checked when the scene loads, before any scan: only the XML says it needs it
            require("weather", f"lidar '{name}' with fog, rain or snow")

    def to_string(self) -> str:
        return f"LidarSensor[{self.config}]"


mi.register_sensor("lidar", lambda props: LidarSensor(props))
