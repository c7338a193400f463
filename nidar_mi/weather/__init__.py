"""Weather: fog, rain and snow as scattering media, from their particle size distributions
through Mie theory (docs/WEATHER.md).

The physics of the media is here (:mod:`.conditions` the conditions, :mod:`.particles` the size
distributions, :mod:`.refractive_index` water and ice, :mod:`.mie` the efficiencies,
:mod:`.media` the coefficients); what a LiDAR sees of them is :mod:`nidar_mi.lidar.weather_returns`'s,
the camera's medium :mod:`.camera`'s, real clouds :mod:`nidar_mi.cloud_weather`'s.
"""

from .conditions import Weather, check_weather

__all__ = ["Weather", "check_weather"]
