"""Controlled LiDAR experiments: library-material panels scanned through the real ``lidar`` plugin.

A *panel scene* puts N square panels of library materials (``nidar_material``) around a LiDAR
at height :data:`LIDAR_HEIGHT_M`, every panel centre at that height and on the beam of one column
of a single horizontal ring (elevation 0), so the scan reads each panel at exactly the distance
and incidence angle asked for. A panel faces the LiDAR and is turned about its vertical axis by
its incidence angle. Noise, dropout and ray drop are off; the scene has no ground.

The scene is loaded with :func:`nidar_mi.scene.load_scene` and scanned with
:func:`nidar_mi.lidar.scan.scan`, so what comes back is what the sensor reports: the return
model ``I = g · ρ(m, λ, θ) · T² · a(d, θ)`` of :mod:`nidar_mi.lidar.return_model`, with ρ the BSDF
of the material evaluated monostatically at the laser wavelength (``T² = 1`` unless the beam
passes a glass panel on its way to the backdrop).

* :func:`incidence_sweep`: intensity against incidence angle at a fixed distance.
* :func:`range_sweep`: intensity against distance (``1/d²`` and ``exp(-2αd)``).
* :func:`detection_range` / :func:`max_detection_range`: the range where ``g·ρ·cosθ·exp(-2αd)/d²``
  falls to a detection threshold (pure bisection, and the same with ρ measured by a scan).
* :func:`extinction_from_visibility`: α at a wavelength from the meteorological visibility
  (Kim, McArthur & Korevaar 2001).
"""

from .panels import *  # noqa: F403
from .panels import __all__ as _panels_all
from .sweeps import *  # noqa: F403
from .sweeps import __all__ as _sweeps_all

__all__ = [*_panels_all, *_sweeps_all]
