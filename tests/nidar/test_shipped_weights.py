"""The model shipped in the package loads (safetensors only) and gives deterministic output that
matches the reference recorded when it was shipped (``weights/reference_output.json``)."""

import json

import numpy as np
import pytest

from nidar_mi.nidar.pipeline import NidarModel, shipped_weights_dir

WEIGHTS = shipped_weights_dir()
pytestmark = pytest.mark.skipif(
    not (WEIGHTS / "irnet.safetensors").is_file(), reason="no shipped weights in this build"
)


def reference_image(h: int = 96, w: int = 160) -> np.ndarray:
    """A fixed, procedural 8-bit sRGB test image (sky, road, two coloured blocks)."""
    y, x = np.mgrid[0:h, 0:w]
    img = np.zeros((h, w, 3), dtype=np.float64)
    img[: h // 3] = [0.55, 0.65, 0.85]
    img[h // 3 :] = (0.25 + 0.15 * (y[h // 3 :, :, None] / h)) * np.array([1.0, 1.0, 1.0])
    img[h // 4 : h // 2, w // 8 : w // 3] = [0.15, 0.45, 0.12]  # green block
    img[h // 3 : 2 * h // 3, w // 2 : 3 * w // 4] = [0.7, 0.2, 0.15]  # red block
    img += 0.02 * np.sin(x[..., None] / 3.0)
    return np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)


def test_shipped_files_are_safetensors_and_json():
    names = {p.name for p in WEIGHTS.iterdir()}
    assert {"stn.safetensors", "irnet.safetensors", "config.json", "calibration.json"} <= names
    assert not [n for n in names if n.endswith((".pt", ".pth", ".pkl", ".bin"))]
    total = sum(p.stat().st_size for p in WEIGHTS.iterdir())
    assert total < 20_000_000


def test_deterministic_and_matches_reference():
    model = NidarModel.load(device="cpu")
    img = reference_image()
    a = model.predict_image(img)
    b = model.predict_image(img)
    for k in ("pseudo_nir", "R", "S", "I_hat"):
        np.testing.assert_array_equal(a[k], b[k])
        assert a[k].shape == img.shape[:2] and np.isfinite(a[k]).all()
    assert ((a["R"] > 0) & (a["R"] < 1)).all()
    ref = json.loads((WEIGHTS / "reference_output.json").read_text())
    for k, stats in ref["maps"].items():
        assert float(a[k].mean()) == pytest.approx(stats["mean"], rel=1e-3, abs=1e-5), k
        assert float(a[k].std()) == pytest.approx(stats["std"], rel=1e-3, abs=1e-5), k
    q = model.calibration.mapping.quantile_map
    assert np.all(np.diff(q.q_source) > 0) and np.all(np.diff(q.q_reference) >= 0)
