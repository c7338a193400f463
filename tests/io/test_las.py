"""Tests of nidar_mi.io.las: LAS 1.4 point format 6 writer and reader."""

import json
import os

import laspy
import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io.las import LAS_SCALE_M, read_las, write_las


def _vlr_json(path):
    las = laspy.read(str(path))
    (vlr,) = [v for v in las.header.vlrs if v.user_id == "nidar_mi" and v.record_id == 1]
    return las, json.loads(vlr.record_data)


def test_las_round_trip(tmp_path, points):
    path = tmp_path / "d" / "scan.las"
    write_las(path, points)
    got = read_las(path)
    assert sorted(got) == sorted(points)
    assert got["xyz"].dtype == np.float32
    # 0.1 mm quantisation (half a step) plus float32 rounding of coordinates below 80 m.
    np.testing.assert_allclose(got["xyz"], points["xyz"], rtol=0, atol=LAS_SCALE_M)
    scale = 65535 / points["intensity"].max()
    assert got["intensity"].dtype == np.float32
    np.testing.assert_allclose(got["intensity"], points["intensity"], rtol=0, atol=1 / scale)
    for k, v in points.items():
        if k not in ("xyz", "intensity"):
            assert got[k].dtype == np.asarray(v).dtype, k
            np.testing.assert_array_equal(got[k], v, err_msg=k)
    assert os.listdir(path.parent) == ["scan.las"]


def test_las_file_layout_and_default_scale(tmp_path):
    xyz = np.array([[10.0, -5.0, 1.0], [12.5, -4.0, 0.5], [11.0, -3.0, 2.0]], np.float32)
    intensity = np.array([0.0, 0.5, 2.0], np.float32)
    write_las(tmp_path / "s.las", {"xyz": xyz, "intensity": intensity, "range": intensity + 1})
    las, doc = _vlr_json(tmp_path / "s.las")
    assert str(las.header.version) == "1.4" and las.header.point_format.id == 6
    np.testing.assert_array_equal(las.header.scales, [1e-4, 1e-4, 1e-4])
    np.testing.assert_array_equal(las.header.offsets, [10.0, -5.0, 0.5])  # the minimum corner
    np.testing.assert_array_equal(las.X, [0, 25000, 10000])
    # scale = 65535 / 2 = 32767.5: 0.5 -> 16383.75 -> 16384; 2.0 -> 65535
    assert doc["intensity_scale"] == 32767.5
    np.testing.assert_array_equal(las.intensity, [0, 16384, 65535])
    np.testing.assert_array_equal(las.return_number, [1, 1, 1])
    (dim,) = las.point_format.extra_dimensions
    assert (dim.name, dim.description) == ("range", "range [m]")
    got = read_las(tmp_path / "s.las")
    np.testing.assert_allclose(got["intensity"], [0.0, 16384 / 32767.5, 2.0], rtol=1e-7)


def test_las_explicit_scale_clips(tmp_path):
    xyz = np.zeros((4, 3), np.float32)
    intensity = np.array([0.0123, 70.0, -1.0, np.nan], np.float32)
    write_las(tmp_path / "s.las", {"xyz": xyz, "intensity": intensity}, intensity_scale=1000)
    las, doc = _vlr_json(tmp_path / "s.las")
    assert doc["intensity_scale"] == 1000
    np.testing.assert_array_equal(las.intensity, [12, 65535, 0, 0])
    np.testing.assert_allclose(read_las(tmp_path / "s.las")["intensity"], [0.012, 65.535, 0, 0])


def test_las_material_names_in_vlr(tmp_path, points):
    write_las(tmp_path / "s.las", points)
    _, doc = _vlr_json(tmp_path / "s.las")
    assert doc["metadata"]["material_names"]["data"] == ["asphalt", "concrete", "birch leaf"]
    assert doc["columns"]["nidar_observed"] == {"dtype": "|b1", "shape": []}


@pytest.mark.parametrize("scale", [0, -1.0, float("nan"), float("inf")])
def test_las_bad_scale(tmp_path, points, scale):
    with pytest.raises(NidarError, match="intensity_scale"):
        write_las(tmp_path / "s.las", points, intensity_scale=scale)
    assert os.listdir(tmp_path) == []


def test_las_empty_and_no_intensity(tmp_path, make_points):
    empty = make_points(0)
    write_las(tmp_path / "e.las", empty)
    got = read_las(tmp_path / "e.las")
    assert got["xyz"].shape == (0, 3) and got["ring"].dtype == np.uint16
    assert got["xyz_world"].shape == (0, 3)
    write_las(tmp_path / "n.las", {"xyz": np.ones((2, 3), np.float32)})
    assert sorted(read_las(tmp_path / "n.las")) == ["xyz"]


def test_las_foreign_file_raw_intensity(tmp_path):
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales = [0.01, 0.01, 0.01]
    las = laspy.LasData(header)
    las.x, las.y, las.z = [1.0, 2.0], [3.0, 4.0], [5.0, 6.5]
    las.intensity = np.array([7, 40000], np.uint16)
    las.write(str(tmp_path / "f.las"))
    got = read_las(tmp_path / "f.las")
    np.testing.assert_allclose(got["xyz"], [[1, 3, 5], [2, 4, 6.5]], atol=1e-6)
    np.testing.assert_array_equal(got["intensity"], np.array([7, 40000], np.float32))
    assert got["intensity"].dtype == np.float32


def test_las_refusals(tmp_path, points):
    bad = dict(points, xyz=np.array([[0, 0, np.nan]], np.float32))
    for k in list(bad):
        if k not in ("xyz", "material_names", "wavelength_nm"):
            bad.pop(k)
    with pytest.raises(NidarError, match="NaN"):
        write_las(tmp_path / "a.las", bad)
    far = {"xyz": np.array([[0, 0, 0], [300e3, 0, 0]], np.float32)}
    with pytest.raises(NidarError, match="extent"):
        write_las(tmp_path / "b.las", far)
    clash = dict(points, classification=np.zeros(257, np.uint8))
    with pytest.raises(NidarError, match="classification"):
        write_las(tmp_path / "c.las", clash)
    assert os.listdir(tmp_path) == []


def test_las_malformed(tmp_path):
    (tmp_path / "g.las").write_bytes(b"LASF" + b"\0" * 50)
    with pytest.raises(NidarError, match=r"cannot read .*g\.las"):
        read_las(tmp_path / "g.las")


def test_laz_without_backend(tmp_path, points, monkeypatch):
    """Without lazrs (laspy then finds no LAZ back end): one line naming the ``laz`` extra."""
    monkeypatch.setattr(laspy.LazBackend, "detect_available", staticmethod(lambda: ()))
    with pytest.raises(NidarError, match=r"s\.laz.*pip install 'nidar_mi\[laz\]'"):
        write_las(tmp_path / "s.laz", points)
    assert os.listdir(tmp_path) == []


def test_laz_holds_what_las_holds(tmp_path, points):
    """``.laz`` (lazrs) stores the same records as ``.las``, compressed: both read back equal,
    and the LAZ file is the LAS file's point data compressed (laspy decompresses it to the
    same bytes)."""
    write_las(tmp_path / "s.las", points)
    write_las(tmp_path / "s.laz", points)
    las, laz = read_las(tmp_path / "s.las"), read_las(tmp_path / "s.laz")
    assert sorted(las) == sorted(laz)
    for k in las:
        np.testing.assert_array_equal(laz[k], las[k], err_msg=k)
    raw_las, raw_laz = laspy.read(str(tmp_path / "s.las")), laspy.read(str(tmp_path / "s.laz"))
    assert raw_laz.header.are_points_compressed and not raw_las.header.are_points_compressed
    assert raw_laz.points.array.tobytes() == raw_las.points.array.tobytes()
