"""Sensor profiles: how one sensor turns a surface's model value into its intensity.

NIDAR's networks rank surfaces (a reflectance-like value per pixel); how bright a return of a
given surface comes out depends on the sensor: its range response (some sensors report
range-compensated intensity, some do not), per-laser gains, its intensity scale. A sensor
profile holds that part, fitted on the sensor's own scans (``python -m nidar_mi.calibrate``)
and kept out of the model. Five forms, one interface (:mod:`~nidar_mi.profiles.forms`):

* ``distance_quantile``: the paper's (§III.E) distance encoding and quantile map
  (:class:`~nidar_mi.profiles.distance_quantile.DistanceQuantileMap`; a weights folder's
  ``calibration.json`` is one);
* ``range_ring``: a monotone map of the model value per range bin and a gain per ring
  (:class:`~nidar_mi.profiles.range_ring.RangeRingMap`);
* ``gbm``: a gradient-boosted regression of the intensity on the value, the range and the
  elevation, monotone in the value, or on the range and elevation alone; optionally also on
  the incidence ``|cos θ|`` of the ray on the surface, estimated from the scan's own points;
  or on the value and the incidence alone, without range and elevation
  (:class:`~nidar_mi.profiles.gbm.GbmMap`; LightGBM's text model in the file);
* ``context``: a gradient-boosted regression on a return's named inputs
  (:mod:`~nidar_mi.profiles.inputs`): range, elevation, incidence, the laser, the local
  geometry of the scan, the image around the return's pixel and NIDAR's maps there; the file
  says which it reads, and one that reads the image refuses without it
  (:class:`~nidar_mi.profiles.context.ContextMap`);
* ``physical``: the LiDAR equation in closed form, ``clip(k·ρ·|cos θ|/d^p, 0, 1)`` with ``p = 2``
  for a raw sensor and ``p = 0`` for a range-compensated one
  (:class:`~nidar_mi.profiles.physical.PhysicalMap`; the generic profiles of sensors not
  calibrated).

Every map and every :class:`SensorProfile` is called the same way,
``profile(values, range_m, *, ring=None, elevation_deg=None, cos_incidence=None)`` (and
``context=`` the named inputs, for a ``context`` profile), and every
form is fitted by :func:`fit`. The profile file format is
:mod:`~nidar_mi.profiles.sensor_profile`'s.
Which data a profile is fitted on, and the named profiles (``sim-905``, ``kitti-hdl64e``, ``generic-raw``,
``generic-compensated``), are
the datasets' side (:mod:`nidar_mi.datasets.sensor_profiles`). Pure NumPy and LightGBM (and
the scan geometry of :mod:`nidar_mi.geometry`): the package imports neither the networks nor
any data.
"""

from .context import ContextMap
from .distance_quantile import DistanceQuantileMap
from .forms import FORMS, ProfileMap, fit
from .gbm import GbmMap
from .physical import PhysicalMap
from .quantile_map import QuantileMap
from .range_ring import RangeRingMap
from .sensor_profile import PROFILE_SCHEMA, SensorProfile, load_profile

__all__ = [
    "FORMS",
    "PROFILE_SCHEMA",
    "ContextMap",
    "DistanceQuantileMap",
    "GbmMap",
    "PhysicalMap",
    "ProfileMap",
    "QuantileMap",
    "RangeRingMap",
    "SensorProfile",
    "fit",
    "load_profile",
]
