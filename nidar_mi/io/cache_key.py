"""Cache keys and file hashes: a short hash of everything that decides a derived result.

A cache (fitted profiles, training frames built from real data, ablation runs, a render's record
of its profile) is named by :func:`cache_key` of the inputs that decide its content, so changed
inputs give a new name and never a stale result. The text hashed is the canonical JSON of the
inputs (keys sorted, non-JSON values by their ``str``), so a key written today is found again by
a later run with the same inputs. A file enters a key by its content: :func:`file_sha256`.
"""

from __future__ import annotations

import hashlib
import json
import os
from typing import Any

__all__ = ["cache_key", "file_sha256"]

#: Bytes read at a time while hashing a file (memory stays bounded for any file size).
_CHUNK = 1 << 20


def cache_key(obj: Any, digits: int = 16) -> str:
    """The first ``digits`` hex digits of the SHA-256 of ``obj`` as canonical JSON
    (``json.dumps(obj, sort_keys=True, default=str)``, UTF-8).

    Args:
        obj: the inputs: JSON values (dicts, lists, strings, numbers, None); other values
            count by their ``str``.
        digits: how many hex digits, 1 to 64.
    """
    text = json.dumps(obj, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:digits]


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 (64 digits) of a file's bytes, read in chunks of 1 MiB.

    Raises:
        OSError: the file cannot be read.
    """
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(_CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()
