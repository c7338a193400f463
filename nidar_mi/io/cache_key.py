"""Cache keys: a short hash of everything that decides a derived result.

A cache (fitted profiles, training frames built from real data, ablation runs, a render's record
of its profile) is named by :func:`cache_key` of the inputs that decide its content, so changed
inputs give a new name and never a stale result. The text hashed is the canonical JSON of the
inputs (keys sorted, non-JSON values by their ``str``), so a key written today is found again by
a later run with the same inputs.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

__all__ = ["cache_key"]


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
