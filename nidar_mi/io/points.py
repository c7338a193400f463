"""Point sets ("points dicts") and their files: npz and PLY.

LAS is in :mod:`nidar_mi.io.las`, PCD in :mod:`nidar_mi.io.pcd`, KITTI ``.bin`` in
:mod:`nidar_mi.io.kitti`, and :func:`nidar_mi.io.point_cloud.read_point_cloud` reads any of
them.

A points dict maps names to numpy arrays. ``xyz`` is required; every other entry is
optional. This table is the schema of the simulator's points (``points.npz`` in a render
folder holds the valid returns of one scan, N points and M materials); the README links here:

===================  =========  ======  ====  ==================================================
name                 dtype      shape   unit  meaning
===================  =========  ======  ====  ==================================================
``xyz``              float32    (N,3)   m     point in the LiDAR frame (x forward, y left, z up)
                                              at the point's firing time
``xyz_world``        float32    (N,3)   m     point in the world frame
``range``            float32    (N,)    m     path length from the beam's origin (after noise)
``intensity``        float32    (N,)    --    g·ρ·a + η, clipped at 0 (``intensity_mode`` ``raw``:
                                              1/m²; ``compensated``: unitless)
``reflectance``      float32    (N,)    --    ρ at the LiDAR wavelength: π × the monostatic BSDF
                                              value (a Lambertian surface gives its albedo;
                                              retroreflectors and rough metals exceed 1)
``cos_incidence``    float32    (N,)    --    cosine of the incidence angle on the shading normal
``ring``             uint16     (N,)    --    beam (channel) index, 0 = highest beam = top row
                                              of the range image
``column``           uint32     (N,)    --    azimuth column index of the firing
``material``         int32      (N,)    --    index into ``material_names``; -1 = none
``material_names``   str (U)    (M,)    --    BSDF ids (anonymous BSDFs: ``<shape id>.bsdf``);
                                              fixed-width unicode, never object
``label``            uint16     (N,)    --    semantic class, SemanticKITTI id (0 = unlabeled;
                                              table: :mod:`nidar_mi.labels.classes`)
``instance``         uint32     (N,)    --    instance (object) id, 1..K; 0 = none
``instance_names``   str (U)    (K+1,)  --    ``instance_names[k]`` names instance k (the
                                              scene's ``instance`` or the shape id); ``[0]`` ""
``t``                float32    (N,)    s     firing time of the point since the sweep's start
``return_index``     uint8      (N,)    --    which return of its beam: 0 = the first listed
                                              (the strongest in ``dual`` mode), 1 = the other
``xyz_deskewed``     float32    (N,3)   m     with ``--deskew``: the point in the LiDAR frame at
                                              the sweep's start (motion compensated)
``intensity_nidar``  float32    (N,)    --    with ``--intensity nidar``: NIDAR's calibrated
                                              intensity in [0, 1], 0 where no camera sees the point
``reflectance_nidar`` float32   (N,)    --    with ``--intensity nidar``: IRNet's reflectance R
                                              at the point (the camera's per-surface cue), 0
                                              where no camera sees the point
``nidar_observed``   bool       (N,)    --    with ``--intensity nidar``: a camera saw the point
``scatterer``        uint8      (N,)    --    in weather (``--fog``, ``--rain``, ``--snow``):
                                              what the return came from, an index into
                                              ``scatterer_names``: 0 surface, 1 fog (the medium's
                                              own return), 2 drop, 3 flake (docs/WEATHER.md)
``scatterer_names``  str (U)    (4,)    --    in weather: ``surface``, ``fog``, ``drop``,
                                              ``flake``
===================  =========  ======  ====  ==================================================

Other entries are carried generically by every writer:

* a *per-point column* is any numeric or bool array whose first dimension is N, e.g.
  ``intensity_nidar`` float32 (N,) or ``nidar_observed`` bool (N,); columns of shape
  (N, k...) are stored as scalar fields ``<name>_0 .. <name>_{k-1}`` in PLY and LAS;
* *metadata* is everything else: string arrays (``material_names``) and numeric scalars or
  arrays of another length. PLY keeps them in an ``obj_info`` line and LAS in a VLR
  (user id ``nidar_mi``, record 1), as JSON that also records each column's dtype and shape
  so that the readers restore the dict exactly (bool, for example, is stored as uint8);
  PCD keeps the same JSON in a ``# nidar_mi.points`` header comment.

Readers accept files from other tools too: they return ``xyz`` (float32) and, when the file
has it, ``intensity`` (float32), plus the file's other per-point fields.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import NidarError
from .atomic import atomic_path, reading

__all__ = [
    "PLY_TYPES",
    "POINTS_TAG",
    "decode_metadata",
    "flatten_columns",
    "header_json",
    "read_npz",
    "read_ply",
    "split_points",
    "unflatten_columns",
    "write_npz",
    "write_ply",
]

#: Marks the package's JSON in PLY ``obj_info`` lines, the LAS VLR and PCD comments.
POINTS_TAG = "nidar_mi.points"
#: Scalar types a PLY field may hold (LAS and PCD add their own).
PLY_TYPES = frozenset({"i1", "u1", "i2", "u2", "i4", "u4", "f4", "f8"})
# Required trailing width of the simulator's columns (None: 1-D).
_KNOWN_SHAPES = {
    "xyz_world": 3,
    "xyz_deskewed": 3,
    "t": None,
    "return_index": None,
    **dict.fromkeys(("range", "intensity", "reflectance", "cos_incidence"), None),
    **dict.fromkeys(("ring", "column", "material", "label", "instance", "scatterer"), None),
}


# --- the points dict ---------------------------------------------------------------------


def split_points(points: Mapping[str, Any]) -> tuple[int, dict, dict]:
    """Check a points dict; split it into per-point columns and metadata.

    Returns:
        ``(n, columns, meta)``: the point count, the per-point columns (``xyz`` included)
        and the metadata, all as numpy arrays (object arrays of str become unicode arrays).
    """
    if not isinstance(points, Mapping):
        raise NidarError(f"points must be a dict of arrays, got {type(points).__name__}")
    if "xyz" not in points:
        raise NidarError("points dict has no 'xyz' entry")
    xyz = np.asarray(points["xyz"])
    if xyz.ndim != 2 or xyz.shape[1] != 3 or xyz.dtype.kind not in "iuf":
        raise NidarError(f"'xyz' must be a numeric (N,3) array, got {xyz.dtype} {xyz.shape}")
    n = xyz.shape[0]
    columns: dict[str, np.ndarray] = {}
    meta: dict[str, np.ndarray] = {}
    for name, value in points.items():
        if not isinstance(name, str) or not name:
            raise NidarError(f"points dict keys must be non-empty str, got {name!r}")
        a = np.asarray(value)
        if a.dtype.kind == "O" and all(isinstance(v, str) for v in a.flat):
            a = a.astype(str)
        if a.dtype.kind == "U":
            meta[name] = a
        elif a.dtype.kind not in "biuf":
            raise NidarError(f"points entry {name!r} has unsupported dtype {a.dtype}")
        elif a.ndim >= 1 and a.shape[0] == n:
            columns[name] = a
        else:
            meta[name] = a
        width = _KNOWN_SHAPES.get(name, 0)
        want = (n,) if width is None else (n, width)
        if width != 0 and a.shape != want:
            raise NidarError(f"points entry {name!r} must have shape {want}, got {a.shape}")
    return n, columns, meta


def _storable(name: str, a: np.ndarray, types: frozenset[str], fmt: str) -> np.ndarray:
    """Cast a column to a little-endian dtype ``fmt`` stores, without changing a value."""
    if a.dtype.kind == "b":
        return a.astype("u1")
    if a.dtype.kind == "f" and a.dtype.itemsize < 4:
        return a.astype("<f4")
    code = f"{a.dtype.kind}{a.dtype.itemsize}"
    if code in types:
        return a.astype(f"<{code}")
    if a.dtype.kind in "iu":
        narrow = np.dtype(f"<{a.dtype.kind}4")
        info = np.iinfo(narrow)
        if a.size == 0 or (a.min() >= info.min and a.max() <= info.max):
            return a.astype(narrow)
    raise NidarError(f"column {name!r}: {fmt} cannot store {a.dtype} values")


def flatten_columns(columns: dict, types: frozenset[str], fmt: str) -> tuple[dict, dict]:
    """Per-point columns -> scalar fields, plus the schema that restores them."""
    fields: dict[str, np.ndarray] = {}
    schema: dict[str, dict] = {}
    for name, a in columns.items():
        stored = _storable(name, a, types, fmt)
        parts = {name: stored}
        if a.ndim > 1:
            flat = stored.reshape(len(a), math.prod(a.shape[1:]))
            parts = {f"{name}_{i}": flat[:, i] for i in range(flat.shape[1])}
        if not parts or fields.keys() & parts.keys():
            raise NidarError(f"column {name!r} cannot be stored in {fmt} (empty or name clash)")
        fields.update(parts)
        schema[name] = {"dtype": a.dtype.str, "shape": list(a.shape[1:])}
    return fields, schema


def unflatten_columns(fields: dict, schema: dict) -> dict:
    """Inverse of :func:`flatten_columns`; fields the schema does not name are kept as they are."""
    out: dict[str, np.ndarray] = {}
    used: set[str] = set()
    for name, spec in schema.items():
        shape = tuple(spec["shape"])
        parts = [f"{name}_{i}" for i in range(math.prod(shape))] if shape else [name]
        if shape:
            a = np.stack([fields[p] for p in parts], axis=1)
            a = a.reshape(len(a), *shape)
        else:
            a = fields[name]
        out[name] = a.astype(spec["dtype"])
        used.update(parts)
    out.update({k: v for k, v in fields.items() if k not in used})
    return out


def header_json(schema: dict, meta: dict, **extra: Any) -> str:
    """The JSON a PLY or LAS file carries to restore the points dict."""
    doc = {"version": 1, **extra, "columns": schema, "metadata": {}}
    for name, a in meta.items():
        doc["metadata"][name] = {"dtype": a.dtype.str, "shape": list(a.shape), "data": a.tolist()}
    try:
        return json.dumps(doc, allow_nan=False, separators=(",", ":"))
    except ValueError:
        raise NidarError(
            "metadata holds NaN or infinity, which the file header cannot store"
        ) from None


def decode_metadata(doc: dict) -> dict:
    """The metadata arrays of a :func:`header_json` document, by name."""
    return {
        name: np.asarray(m["data"], dtype=m["dtype"]).reshape(m["shape"])
        for name, m in doc["metadata"].items()
    }


# --- npz ---------------------------------------------------------------------------------


def write_npz(path: str | os.PathLike, points: Mapping[str, Any]) -> None:
    """Write a points dict as an uncompressed ``.npz`` (every entry kept exactly).

    Raises:
        NidarError: ``points`` is not a valid points dict, or the file cannot be written.
    """
    _, columns, meta = split_points(points)
    arrays = {name: (columns[name] if name in columns else meta[name]) for name in points}
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays)


def read_npz(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read every array of an ``.npz`` (never unpickling: object arrays are refused).

    Raises:
        NidarError: missing, malformed or object-holding file.
    """
    with reading(path) as p:
        with open(p, "rb") as f:
            if f.read(4) not in (b"PK\x03\x04", b"PK\x05\x06"):
                raise ValueError("not an npz archive (no zip signature)")
        with np.load(p, allow_pickle=False) as data:
            return {name: data[name] for name in data.files}


# --- PLY ---------------------------------------------------------------------------------


def write_ply(path: str | os.PathLike, points: Mapping[str, Any]) -> None:
    """Write a points dict as binary little-endian PLY.

    The ``vertex`` element has ``x, y, z`` (``xyz`` cast to float32) followed by every other
    per-point column (bool as uint8; (N, k) columns as ``<name>_<i>``); the metadata and the
    column dtypes are in an ``obj_info nidar_mi.points {json}`` header line.

    Raises:
        NidarError: invalid points dict, a column PLY cannot store, or a write failure.
    """
    from plyfile import PlyData, PlyElement

    n, columns, meta = split_points(points)
    xyz = columns.pop("xyz").astype("<f4")
    fields, schema = flatten_columns(columns, PLY_TYPES, "PLY")
    if {"x", "y", "z"} & fields.keys():
        raise NidarError("PLY columns cannot be named 'x', 'y' or 'z' (they hold xyz)")
    fields = {"x": xyz[:, 0], "y": xyz[:, 1], "z": xyz[:, 2], **fields}
    vertex = np.empty(n, dtype=[(k, v.dtype) for k, v in fields.items()])
    for k, v in fields.items():
        vertex[k] = v
    info = f"{POINTS_TAG} {header_json(schema, meta)}"
    ply = PlyData([PlyElement.describe(vertex, "vertex")], byte_order="<", obj_info=[info])
    with atomic_path(path) as tmp:
        ply.write(str(tmp))


def read_ply(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read the ``vertex`` element of a PLY file (ASCII or binary) as a points dict.

    ``x, y, z`` become ``xyz`` (float32); other scalar vertex properties become columns.
    A file written by :func:`write_ply` is restored exactly (the other columns' dtypes and
    shapes, and the metadata).

    Raises:
        NidarError: missing or malformed file, or no vertex ``x, y, z``.
    """
    from plyfile import PlyData

    with reading(path) as p:
        ply = PlyData.read(str(p))
        if "vertex" not in ply:
            raise ValueError("no 'vertex' element")
        data = ply["vertex"].data
        names = data.dtype.names or ()
        if not {"x", "y", "z"} <= set(names):
            raise ValueError("vertex element has no x, y, z properties")
        scalar = [k for k in names if data.dtype[k].kind != "O"]  # list properties are skipped
        fields = {k: np.ascontiguousarray(data[k]) for k in scalar if k not in ("x", "y", "z")}
        docs = [
            line[len(POINTS_TAG) + 1 :]
            for line in ply.obj_info
            if line.startswith(POINTS_TAG + " ")
        ]
        out = {"xyz": np.stack([data["x"], data["y"], data["z"]], axis=1).astype(np.float32)}
        if docs:
            doc = json.loads(docs[0])
            out.update(unflatten_columns(fields, doc["columns"]))
            out.update(decode_metadata(doc))
        else:
            out.update(fields)
        return out
