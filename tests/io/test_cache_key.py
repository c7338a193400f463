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


def test_keys_in_use_are_found_again():
    """The caches named before the shared helper keep their names (ablation runs, a render's
    record of its profile)."""
    from nidar_mi.eval.suite import _ablation_key
    from nidar_mi.render_session import profile_key

    meta = {"request": {"scene": "a.xml", "spp": 4}, "frames": 3, "intensity_scale": 1.5}
    assert _ablation_key(meta, "/nonexistent/stn.pt") == "d99ad2ac5bf0f3df"

    class Profile:
        name = "sim-905"

        def to_dict(self):
            mapping = {"edges": [0.0, 10.0], "gain": [1.0, 0.5]}
            return {"name": "sim-905", "form": "range_ring", "mapping": mapping, "version": 1}

    assert profile_key(Profile()) == "sim-905@3330e7ee029d1c91"
    assert profile_key(None) is None
