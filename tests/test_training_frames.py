"""Tests for nidar_mi.training_frames (the training-frame format, apart from any frame builder)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.training_frames import (
    CORE_KEYS,
    FRAME_KEYS,
    FRAME_SOURCES,
    SPLITS,
    check_frame,
    frame_has,
    list_frames,
    load_frame,
    load_meta,
    write_frame,
)


def _kitti_like(h=4, w=6, n=3) -> dict[str, np.ndarray]:
    frame = {}
    for key in FRAME_SOURCES["kitti"]:
        dtype, shape, _ = FRAME_KEYS[key]
        frame[key] = np.zeros([{"H": h, "W": w, "N": n}.get(d, d) for d in shape], dtype=dtype)
    return frame


def test_the_format_loads_no_renderer():
    code = textwrap.dedent(
        """
        import sys
        import nidar_mi.training_frames
        loaded = {"mitsuba", "drjit", "torch", "nidar_mi.simulate", "nidar_mi.scene",
                  "nidar_mi.render_dataset", "nidar_mi.render_folder"} & set(sys.modules)
        assert not loaded, loaded
        """
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_write_list_and_load_a_frame(tmp_path):
    frame = _kitti_like()
    frame["points_ring"][:] = [0, 5, -1]
    write_frame(tmp_path / "train" / "a.npz", frame)
    (tmp_path / "meta.json").write_text('{"source": "kitti", "intensity_scale": 1.0}')
    assert load_meta(tmp_path)["source"] == "kitti"
    paths = list_frames(tmp_path, "train")
    assert [p.name for p in paths] == ["a.npz"] and list_frames(tmp_path, "val") == []
    back = load_frame(paths[0])
    assert set(back) == set(FRAME_SOURCES["kitti"]) and set(CORE_KEYS) <= set(back)
    np.testing.assert_array_equal(back["points_ring"], [0, 5, -1])
    assert frame_has(paths[0], ("points_xyz",)) and not frame_has(paths[0], ("R_true",))
    assert set(SPLITS) == {"train", "val", "test"}


def test_a_frame_off_the_format_is_refused(tmp_path):
    frame = _kitti_like()
    frame["range"] = frame["range"].astype(np.float64)
    with pytest.raises(NidarError, match="range has dtype float64"):
        write_frame(tmp_path / "a.npz", frame)
    assert not (tmp_path / "a.npz").exists()
    frame = _kitti_like()
    frame["points_ring"] = np.zeros(4, dtype=np.int16)  # N = 3 elsewhere
    with pytest.raises(NidarError, match=r"points_ring has shape \(4,\), expected \(3,\)"):
        check_frame(frame)
    with pytest.raises(NidarError, match="unknown split"):
        list_frames(tmp_path, "holdout")
