"""Point Cloud Library ``.pcd`` files (format v0.7): writing (``DATA binary``) and reading
(``DATA ascii`` and ``binary``).

The header names the fields of each point (``FIELDS x y z intensity ...``), their byte size
(``SIZE``), type (``TYPE``: ``F`` float, ``I`` signed, ``U`` unsigned integer) and element
count (``COUNT``, default 1). ``binary`` data are packed little-endian records, one per
point; ``ascii`` data are whitespace-separated numbers in the same order. Fields named
``_`` are padding and skipped. ``binary_compressed`` (LZF) is not supported.

:func:`write_pcd` writes every per-point column of a points dict (:mod:`nidar_mi.io.points`):
``x y z`` (float32), then the other columns in the dict's order with their own type (bool as
``U 1``; (N, k) columns as ``<name>_<i>``). A header comment ``# nidar_mi.points {json}``
(comment lines are allowed by the format and skipped by PCL) carries the metadata and column
dtypes, so :func:`read_pcd` restores a points dict it wrote exactly. ``VIEWPOINT`` is the
identity: the points are in the LiDAR frame.
"""

from __future__ import annotations

import json
import os

import numpy as np

from ..errors import NidarError
from .atomic import atomic_path, reading
from .points import (
    POINTS_TAG,
    decode_metadata,
    flatten_columns,
    header_json,
    split_points,
    unflatten_columns,
)

__all__ = ["read_pcd", "write_pcd"]

_PCD_TYPES = frozenset({"i1", "u1", "i2", "u2", "i4", "u4", "i8", "u8", "f4", "f8"})

_DTYPES = {
    ("F", 4): "<f4",
    ("F", 8): "<f8",
    ("I", 1): "i1",
    ("I", 2): "<i2",
    ("I", 4): "<i4",
    ("I", 8): "<i8",
    ("U", 1): "u1",
    ("U", 2): "<u2",
    ("U", 4): "<u4",
    ("U", 8): "<u8",
}


def write_pcd(path: str | os.PathLike, points) -> None:
    """Write a points dict as a binary PCD v0.7 file (layout in the module docstring).

    Raises:
        NidarError: invalid points dict, a column PCD cannot store or name, or a write failure.
    """
    n, columns, meta = split_points(points)
    xyz = columns.pop("xyz").astype("<f4")
    fields, schema = flatten_columns(columns, _PCD_TYPES, "PCD")
    if {"x", "y", "z"} & fields.keys():
        raise NidarError("PCD columns cannot be named 'x', 'y' or 'z' (they hold xyz)")
    fields = {"x": xyz[:, 0], "y": xyz[:, 1], "z": xyz[:, 2], **fields}
    bad = [k for k in fields if not k.isascii() or any(c.isspace() for c in k)]
    if bad:
        raise NidarError(f"PCD field names cannot hold spaces or non-ASCII: {bad}")
    record = np.empty(n, dtype=[(k, v.dtype.newbyteorder("<")) for k, v in fields.items()])
    for k, v in fields.items():
        record[k] = v
    kinds = {"f": "F", "i": "I", "u": "U"}
    header = [
        "# .PCD v0.7 - Point Cloud Data file format",
        f"# {POINTS_TAG} {header_json(schema, meta)}",
        "VERSION 0.7",
        "FIELDS " + " ".join(fields),
        "SIZE " + " ".join(str(v.dtype.itemsize) for v in fields.values()),
        "TYPE " + " ".join(kinds[v.dtype.kind] for v in fields.values()),
        "COUNT " + " ".join("1" for _ in fields),
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        "DATA binary",
    ]
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(record.tobytes())


def _parse_header(raw: bytes) -> tuple[dict[str, list[str]], int]:
    """Header entries (upper-case key -> values; ``#`` for our JSON comment) and the byte
    offset of the data."""
    header: dict[str, list[str]] = {}
    pos = 0
    while pos < len(raw):
        end = raw.find(b"\n", pos)
        end = len(raw) if end < 0 else end
        line = raw[pos:end].decode("ascii", errors="replace").strip()
        pos = end + 1
        if line.startswith(f"# {POINTS_TAG} "):
            header["#"] = [line[len(POINTS_TAG) + 3 :]]
            continue
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            return header, min(pos, len(raw))
    raise ValueError("no DATA line in the PCD header")


def _record_dtype(header: dict[str, list[str]]) -> tuple[list[str], np.dtype]:
    """Field names and the numpy record type of one point."""
    for key in ("FIELDS", "SIZE", "TYPE"):
        if key not in header:
            raise ValueError(f"PCD header has no {key} line")
    names = header["FIELDS"]
    counts = header.get("COUNT", ["1"] * len(names))
    if not (len(names) == len(header["SIZE"]) == len(header["TYPE"]) == len(counts)):
        raise ValueError("PCD header FIELDS, SIZE, TYPE and COUNT have different lengths")
    formats = []
    for name, size, kind, count in zip(names, header["SIZE"], header["TYPE"], counts):
        code = _DTYPES.get((kind.upper(), int(size)))
        if code is None:
            raise ValueError(f"PCD field {name!r} has unsupported TYPE {kind} SIZE {size}")
        formats.append((code, (int(count),)) if int(count) != 1 else code)
    # Positional record names: PCD may repeat a name (padding fields are all "_").
    return names, np.dtype({"names": [f"f{i}" for i in range(len(names))], "formats": formats})


def read_pcd(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a PCD v0.7 file (``DATA ascii`` or ``binary``) as a points dict.

    Returns:
        ``xyz`` (N, 3) float32, ``intensity`` (N,) float32 if the file has that field, and
        every other field in its own dtype ((N,) or (N, COUNT)); N = ``POINTS`` (default
        ``WIDTH * HEIGHT``). A file written by :func:`write_pcd` is restored exactly (column
        dtypes and shapes, and the metadata).

    Raises:
        NidarError: missing or malformed file, no x/y/z fields, or ``binary_compressed``.
    """
    with reading(path) as p:
        raw = p.read_bytes()
        header, offset = _parse_header(raw)
        names, record = _record_dtype(header)
        if "POINTS" in header:
            n = int(header["POINTS"][0])
        elif "WIDTH" in header and "HEIGHT" in header:
            n = int(header["WIDTH"][0]) * int(header["HEIGHT"][0])
        else:
            raise ValueError("PCD header has neither POINTS nor WIDTH and HEIGHT")
        data = (header["DATA"] or ["(none)"])[0].lower()
        if data == "binary_compressed":
            raise NidarError(f"cannot read {p}: PCD DATA binary_compressed is unsupported")
        if data == "binary":
            if len(raw) - offset < n * record.itemsize:
                raise ValueError(f"binary data hold fewer than the {n} points announced")
            rows = np.frombuffer(raw, dtype=record, count=n, offset=offset)
        elif data == "ascii":
            tokens = np.array(raw[offset:].split())
            width = sum(max(1, int(np.prod(record[i].shape))) for i in range(len(names)))
            if tokens.size != n * width:
                raise ValueError(f"ascii data hold {tokens.size} values, expected {n} x {width}")
            tokens = tokens.reshape(n, width)
            rows = np.empty(n, dtype=record)
            col = 0
            for i in range(len(names)):
                k = max(1, int(np.prod(record[i].shape)))
                rows[f"f{i}"] = (
                    tokens[:, col : col + k].astype(record[i].base).reshape(rows[f"f{i}"].shape)
                )
                col += k
        else:
            raise ValueError(f"unknown PCD DATA type {data!r}")
        fields = {name: rows[f"f{i}"].copy() for i, name in enumerate(names) if name != "_"}
        if not {"x", "y", "z"} <= fields.keys():
            raise ValueError("PCD has no x, y, z fields")
        out = {"xyz": np.stack([fields.pop(k) for k in "xyz"], axis=1).astype(np.float32)}
        if "#" in header:
            doc = json.loads(header["#"][0])
            out.update(unflatten_columns(fields, doc["columns"]))
            out.update(decode_metadata(doc))
            return out
        if "intensity" in fields:
            out["intensity"] = fields.pop("intensity").astype(np.float32)
        out.update(fields)
        return out
