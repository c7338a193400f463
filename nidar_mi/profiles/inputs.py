"""The inputs a ``context`` sensor profile reads at a return, by named group.

A return's intensity depends on the surface (what the camera shows, NIDAR's maps), on how the
beam meets it (range, elevation, incidence), on the laser, and on the surface's shape and
place in the scan (the local geometry). Each input has a name; the names fall in the groups of
:data:`GROUPS`:

* ``return``: ``range_m`` (m), ``elevation_deg`` (degrees above the sensor's xy plane) and
  ``cos_incidence`` (``|cos θ|`` of the ray on the surface), what every profile form reads;
* ``ring``: the laser index (``ring``; missing where the sensor gives none);
* ``geometry``: the neighbourhood descriptors of :mod:`nidar_mi.geometry.local_features`
  (multi-scale linearity / planarity / scatter, ``|n_z|``, height in the sensor frame and above
  the ground, neighbour spacing raw and over the range);
* ``image``: colour, chromaticity, HSV, window means, texture and contrast at the return's
  pixel (:mod:`nidar_mi.profiles.image_context`); needs the camera image;
* ``image_rel``: those of them that scale with the exposure, over the image's mean luminance;
  needs the camera image; not read by default (:data:`DEFAULT_GROUPS`);
* ``nidar``: NIDAR's maps ``R``, ``S``, ``pseudo_nir`` and ``I_hat`` at the return (bilinear,
  as :func:`nidar_mi.geometry.sample_cameras` samples ``R``); needs the image and the networks.

:func:`return_inputs` gives the image-free groups from the points alone (the geometry
computed once per scan, :func:`~nidar_mi.geometry.local_features.local_geometry`, the same
neighbour query serving the incidence); :func:`camera_inputs` the image groups at the returns
the cameras see (occlusion already decided by :func:`~nidar_mi.geometry.locate_in_cameras`),
each return read in the camera that gives it its value. Missing inputs are NaN.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import NidarError
from ..geometry.local_features import (
    GEOMETRY_FEATURES,
    SCALES,
    LocalGeometry,
    geometry_feature_names,
    local_geometry,
)
from .image_context import IMAGE_FEATURES, RELATIVE_FEATURES, image_context

__all__ = [
    "DEFAULT_GROUPS",
    "DEFAULT_INPUTS",
    "GROUPS",
    "IMAGE_GROUPS",
    "NIDAR_MAPS",
    "RETURN_FEATURES",
    "camera_inputs",
    "feature_group",
    "return_inputs",
    "scales_read",
]

#: The per-return inputs every profile form reads.
RETURN_FEATURES = ("range_m", "elevation_deg", "cos_incidence")
#: NIDAR's maps a profile can read at the returns.
NIDAR_MAPS = ("R", "S", "pseudo_nir", "I_hat")
#: Group name -> its inputs, in column order (module docstring).
GROUPS: dict[str, tuple[str, ...]] = {
    "return": RETURN_FEATURES,
    "ring": ("ring",),
    "geometry": GEOMETRY_FEATURES,
    "image": IMAGE_FEATURES,
    "image_rel": RELATIVE_FEATURES,
    "nidar": NIDAR_MAPS,
}
#: The groups that need the camera image.
IMAGE_GROUPS = ("image", "image_rel", "nidar")
#: The groups a ``context`` profile reads unless told (``calibrate --form context``,
#: ``kitti-hdl64e``): every group but ``image_rel``, the inputs measured leave one group out
#: (docs/NIDAR.md, "Local geometry and image context").
DEFAULT_GROUPS = ("return", "ring", "geometry", "image", "nidar")
#: The inputs of :data:`DEFAULT_GROUPS`, in column order.
DEFAULT_INPUTS = tuple(f for g in DEFAULT_GROUPS for f in GROUPS[g])


def feature_group(name: str) -> str:
    """The group of an input name.

    Raises:
        NidarError: a name of no group.
    """
    for group, names in GROUPS.items():
        if name in names:
            return group
    raise NidarError(f"unknown profile input {name!r}")


def return_inputs(
    xyz, ring=None, geometry: LocalGeometry | None = None, scales: tuple[int, ...] = SCALES
) -> dict[str, np.ndarray]:
    """The ``return``, ``ring`` and ``geometry`` inputs of a scan's returns.

    Args:
        xyz: (N, 3) returns in the sensor frame, m (the sensor at the origin, ``z`` up): the
            returns the profile applies to, as it was fitted (a scan's camera-visible ones).
        ring: optional (N,) laser index, -1 unknown (missing).
        geometry: the returns' :func:`~nidar_mi.geometry.local_features.local_geometry` at
            ``scales``, when computed already; None: computed here.
        scales: the neighbourhood sizes of the shape descriptors (:func:`scales_read`).

    Returns:
        name -> (N,) float64, the names of those groups.
    """
    p = np.asarray(xyz, dtype=np.float64)
    geo = local_geometry(p, scales) if geometry is None else geometry
    if len(geo.cos_incidence) != len(p):
        raise NidarError(f"{len(geo.cos_incidence)} descriptors for {len(p)} returns")
    out = {
        "range_m": np.linalg.norm(p, axis=1),
        "elevation_deg": np.degrees(np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1]))),
        "cos_incidence": geo.cos_incidence,
    }
    r = np.full(len(p), np.nan)
    if ring is not None:
        r = np.asarray(ring, dtype=np.float64).reshape(-1)
        if r.shape != (len(p),):
            raise NidarError(f"{r.size} rings for {len(p)} returns")
        r = np.where(r >= 0, r, np.nan)
    out["ring"] = r
    return out | {k: geo.features[k] for k in geometry_feature_names(scales)}


def scales_read(features) -> tuple[int, ...]:
    """The neighbourhood sizes of the shape descriptors among input names (``planarity_k20``:
    20), rising; the normals' own size alone when none is read (the incidence needs it)."""
    import re

    from ..geometry.normals import DEFAULT_NEIGHBOURS

    ks = {int(m.group(1)) for f in features if (m := re.search(r"_k(\d+)$", f))}
    return tuple(sorted(ks)) or (DEFAULT_NEIGHBOURS,)


def camera_inputs(
    sightings,
    images: Sequence[np.ndarray],
    camera_index,
    maps: Sequence[Mapping[str, np.ndarray]] | None = None,
) -> dict[str, np.ndarray]:
    """The ``image`` inputs (and ``nidar``, given the maps) of a cloud's returns.

    Args:
        sightings: :func:`nidar_mi.geometry.locate_in_cameras` of the cloud (N points) in the
            C cameras.
        images: the C (H, W, 3) uint8 sRGB camera images.
        camera_index: (N,) the camera each point is read in (-1: none), as
            :func:`~nidar_mi.geometry.sample_cameras` chose it.
        maps: optional C dicts of NIDAR's (H, W) maps (:data:`NIDAR_MAPS`, those given).

    Returns:
        name -> (N,) float64 (NaN where no camera reads the point): the ``image`` inputs, and
        the ``nidar`` maps that every camera's dict holds.
    """
    n = sightings.n
    cam = np.asarray(camera_index).reshape(-1)
    if cam.shape != (n,) or len(images) != len(sightings.per_camera):
        raise NidarError("camera_inputs: one image per camera and one camera index per point")
    keys = [k for k in NIDAR_MAPS if maps is not None and all(k in m for m in maps)]
    out = {k: np.full(n, np.nan) for k in (*IMAGE_FEATURES, *RELATIVE_FEATURES, *keys)}
    from ..geometry import bilinear_sample

    for c, (index, uv, _) in enumerate(sightings.per_camera):
        pick = cam[index] == c
        idx, at = index[pick], uv[pick]
        if not len(idx):
            continue
        for k, v in image_context(images[c], at).items():
            out[k][idx] = v
        for k in keys:
            out[k][idx] = bilinear_sample(_array(maps[c][k]), at)
    return out


def _array(a) -> np.ndarray:
    """A map as a NumPy array (a tensor copied to the host)."""
    return a.detach().cpu().numpy() if hasattr(a, "detach") else np.asarray(a)
