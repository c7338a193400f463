"""LAS 1.4 files (point format 6) for points dicts, through laspy.

Coordinates are stored at :data:`LAS_SCALE_M` (0.1 mm) with the offset at the minimum corner;
intensity as scaled uint16 counts; every other per-point column as an extra-bytes dimension;
the intensity scale, column dtypes/shapes and metadata as JSON in a VLR (user id
``nidar_mi``, record 1), so that :func:`read_las` restores the points dict (see
:mod:`nidar_mi.io.points` for the schema).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import NidarError
from ..extras import missing_extra
from .atomic import atomic_path, reading
from .points import (
    PLY_TYPES,
    POINTS_TAG,
    decode_metadata,
    flatten_columns,
    header_json,
    split_points,
    unflatten_columns,
)

__all__ = ["LAS_SCALE_M", "write_las", "read_las"]

#: LAS coordinate resolution (m).
LAS_SCALE_M = 1e-4

_USER_ID = "nidar_mi"
_RECORD_ID = 1
_TYPES = PLY_TYPES | {"i8", "u8"}
_DESCRIPTIONS = {
    "range": "range [m]",
    "reflectance": "reflectance at LiDAR wavelength",
    "cos_incidence": "cosine of incidence angle",
    "ring": "beam (ring) index",
    "column": "azimuth column index",
    "material": "material index, -1 = none",
}


def _intensity_scale(intensity: np.ndarray | None, scale: float | None) -> float:
    if scale is not None:
        if not (math.isfinite(scale) and scale > 0):
            raise NidarError(f"intensity_scale must be a positive number, got {scale}")
        return float(scale)
    finite = intensity[np.isfinite(intensity)] if intensity is not None else np.empty(0)
    top = float(finite.max()) if finite.size else 0.0
    return 65535.0 / top if top > 0 else 1.0


def _laz_hint(e: Exception) -> str:
    """laspy's message, plus the fix when LAZ support is missing."""
    hint = f" ({missing_extra('laz', '.laz files', ('lazrs',))})"
    return f"{e}{hint if 'LazBackend' in str(e) else ''}"


def write_las(
    path: str | os.PathLike, points: Mapping[str, Any], intensity_scale: float | None = None
) -> None:
    """Write a points dict as LAS 1.4, point format 6 (``.laz`` needs a LAZ back end).

    Coordinates are stored at :data:`LAS_SCALE_M` resolution with the offset at the minimum
    corner. Intensity is stored as ``uint16 = round(clip(intensity * scale, 0, 65535))``
    (NaN -> 0); ``scale`` defaults to ``65535 / max(intensity)`` (1 when there are no points
    or the maximum is not positive) and is recorded, with the metadata and column dtypes,
    as JSON in a VLR (user id ``nidar_mi``, record 1) so that :func:`read_las` undoes it.
    Every other per-point column becomes an extra-bytes dimension with a description.

    Args:
        path: output ``.las`` (or ``.laz``) file.
        points: points dict (see the module docstring).
        intensity_scale: intensity units per LAS count step, > 0; None = full range.

    Raises:
        NidarError: invalid points dict, non-finite xyz, an extent beyond the int32 range at
            0.1 mm (about 214 km), a column LAS cannot store, or a write failure.
    """
    import laspy

    n, columns, meta = split_points(points)
    xyz = columns.pop("xyz").astype(np.float64)
    if not np.isfinite(xyz).all():
        raise NidarError(f"cannot write {path}: xyz holds NaN or infinity")
    offset = xyz.min(axis=0) if n else np.zeros(3)
    counts = np.round((xyz - offset) / LAS_SCALE_M)
    if n and counts.max() > np.iinfo(np.int32).max:
        raise NidarError(f"cannot write {path}: the point extent is too large for LAS at 0.1 mm")
    intensity = columns.pop("intensity", None)
    scale = _intensity_scale(intensity, intensity_scale)
    fields, schema = flatten_columns(columns, _TYPES, "LAS")
    header = laspy.LasHeader(point_format=6, version="1.4")
    clash = fields.keys() & set(header.point_format.dimension_names)
    long = [k for k in fields if len(k) > 32]
    if clash or long:
        raise NidarError(f"cannot write {path}: LAS cannot store columns {sorted(clash) + long}")
    header.scales = np.full(3, LAS_SCALE_M)
    header.offsets = offset
    header.add_extra_dims(
        [
            laspy.ExtraBytesParams(
                name=k,
                type=v.dtype,
                description=_DESCRIPTIONS.get(k, f"nidar_mi column {k}")[:31],
            )
            for k, v in fields.items()
        ]
    )
    doc = header_json(schema, meta, intensity_scale=scale if intensity is not None else None)
    if len(doc) > 65535:
        raise NidarError(f"cannot write {path}: metadata exceeds the 64 KiB of a LAS VLR")
    header.vlrs.append(laspy.VLR(_USER_ID, _RECORD_ID, f"{POINTS_TAG} JSON", doc.encode("ascii")))
    las = laspy.LasData(header, points=laspy.ScaleAwarePointRecord.zeros(n, header=header))
    las.X, las.Y, las.Z = (counts[:, i].astype(np.int32) for i in range(3))
    las.return_number = np.ones(n, np.uint8)
    las.number_of_returns = np.ones(n, np.uint8)
    if intensity is not None:
        stored = np.clip(np.nan_to_num(intensity.astype(np.float64) * scale, nan=0.0), 0, 65535)
        las.intensity = np.round(stored).astype(np.uint16)
    for k, v in fields.items():
        las[k] = v
    with atomic_path(path) as tmp:
        try:
            las.write(str(tmp))
        except laspy.LaspyException as e:
            raise NidarError(f"cannot write {path}: {_laz_hint(e)}") from e


def read_las(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a LAS/LAZ file as a points dict.

    ``xyz`` is float32; ``intensity`` is float32, divided by the scale recorded by
    :func:`write_las` when its VLR is present (otherwise the raw uint16 counts); every
    extra-bytes dimension becomes a column, and the VLR restores dtypes, shapes and metadata.

    Raises:
        NidarError: missing or malformed file (or a ``.laz`` without a LAZ back end).
    """
    import laspy

    with reading(path) as p:
        try:
            las = laspy.read(str(p))
        except laspy.LaspyException as e:
            raise ValueError(_laz_hint(e)) from e
        docs = [
            v.record_data
            for v in las.header.vlrs
            if v.user_id == _USER_ID and v.record_id == _RECORD_ID
        ]
        doc = json.loads(docs[0]) if docs else None
        out = {"xyz": np.stack([las.x, las.y, las.z], axis=1).astype(np.float32)}
        raw = np.asarray(las.intensity)
        if doc is None:
            out["intensity"] = raw.astype(np.float32)
        elif doc["intensity_scale"] is not None:
            out["intensity"] = (raw / doc["intensity_scale"]).astype(np.float32)
        fields = {k: np.asarray(las[k]) for k in las.point_format.extra_dimension_names}
        if doc is None:
            out.update(fields)
        else:
            out.update(unflatten_columns(fields, doc["columns"]))
            out.update(decode_metadata(doc))
        return out
