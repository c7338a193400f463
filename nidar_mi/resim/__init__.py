"""Re-simulation of recorded drives: a Mitsuba scene built from real scans, the surfaces'
reflectance and the sensor's response recovered by differentiable inversion of the ``lidar``
plugin's return model, scored against held-out scans.

One concept per module, in the order of the work (:func:`nidar_mi.resim.reconstruction.reconstruct`
runs them): :mod:`.drive_folder` (the input folder and its checks), :mod:`.range_image` (each return's
laser and column), :mod:`.laser_layout` (the sensor's per-laser elevations from its own returns),
:mod:`.poses` (poses from a file or KISS-ICP), :mod:`.range_offsets` (each laser's range offset,
taken out of the training returns), :mod:`.mesh` (surfaces from the scans),
:mod:`.observations` (what the training scans saw, cast into the mesh), :mod:`.inversion` (the
fit), :mod:`.scene_files` (the scene written out), :mod:`.scan_scores` (held-out metrics and the
baselines).
"""
