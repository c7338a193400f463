"""Golden regression: the scan of tests/golden/small_scene.xml against the stored points.

Tolerances: the same (ring, column) returns (at most 0.2 % may differ, for returns sitting on the
detection threshold on another CPU's float rounding); on common returns range within 1e-4 m,
intensity within 1e-4 relative (+1e-7 absolute), reflectance and cos_incidence within 1e-5, the
material names and ids identical. Regenerate with ``make fixtures`` after an intended change.
"""

import importlib.util
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def _regen_module():
    spec = importlib.util.spec_from_file_location("regenerate", os.path.join(HERE, "regenerate.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_scan_matches_golden(variant):
    from nidar_mi.io.points import read_npz

    regen = _regen_module()
    gold = read_npz(regen.GOLDEN)
    new = regen.scan_golden_scene()
    key_g = gold["ring"].astype(np.int64) * 100000 + gold["column"]
    key_n = new["ring"].astype(np.int64) * 100000 + new["column"]
    common, ig, in_ = np.intersect1d(key_g, key_n, return_indices=True)
    differ = len(key_g) + len(key_n) - 2 * len(common)
    assert differ <= 0.002 * len(key_g), f"{differ} returns differ from the golden scan"
    assert list(gold["material_names"]) == list(new["material_names"])
    np.testing.assert_array_equal(gold["material"][ig], new["material"][in_])
    np.testing.assert_allclose(new["range"][in_], gold["range"][ig], atol=1e-4)
    np.testing.assert_allclose(new["intensity"][in_], gold["intensity"][ig], rtol=1e-4, atol=1e-7)
    np.testing.assert_allclose(new["reflectance"][in_], gold["reflectance"][ig], atol=1e-5)
    np.testing.assert_allclose(new["cos_incidence"][in_], gold["cos_incidence"][ig], atol=1e-5)
    np.testing.assert_allclose(new["xyz"][in_], gold["xyz"][ig], atol=2e-4)


def test_golden_fixture_is_small():
    assert os.path.getsize(os.path.join(HERE, "small_scene_points.npz")) < 1_000_000
