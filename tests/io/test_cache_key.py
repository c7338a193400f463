"""Cache keys stay what earlier runs wrote: the same inputs find the same cached files."""

import hashlib
import json
from pathlib import Path

from nidar_mi.io.cache_key import cache_key


def test_the_key_is_the_hash_of_the_canonical_json():
    inputs = {"dirs": ["/data/kitti"], "form": "gbm", "version": 3, "model": {"b": 1.5, "a": None}}
    text = json.dumps(inputs, sort_keys=True)
    assert cache_key(inputs) == hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]
    assert cache_key(inputs, digits=12) == cache_key(inputs)[:12]
    # a value written by an earlier version, pinned
    assert cache_key({"b": [1, 2.5, "x"], "a": None}) == "05147f4c03426688"
    # key order does not matter, values do; non-JSON values count by their str
    assert cache_key({"form": "gbm", "version": 3}) == cache_key({"version": 3, "form": "gbm"})
    assert cache_key({"version": 3}) != cache_key({"version": 4})
    assert cache_key([Path("/a/b")]) == cache_key(["/a/b"])
