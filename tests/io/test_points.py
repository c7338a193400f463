"""Tests of nidar_mi.io.points: points-dict validation, npz, PLY, dispatch."""

import os

import numpy as np
import plyfile
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io.points import read_npz, read_ply, write_npz, write_ply

# --- npz -----------------------------------------------------------------------------------


def test_npz_round_trip_exact(tmp_path, points, assert_points_equal):
    path = tmp_path / "a" / "scan.npz"
    write_npz(path, points)
    got = read_npz(path)
    assert_points_equal(got, points)
    assert got["material_names"].dtype.kind == "U"  # fixed unicode, never object
    assert os.listdir(path.parent) == ["scan.npz"]


def test_npz_object_string_array_stored_as_unicode(tmp_path, points):
    points["material_names"] = np.array(["a", "bb"], dtype=object)
    write_npz(tmp_path / "s.npz", points)
    names = read_npz(tmp_path / "s.npz")["material_names"]
    assert names.dtype == np.dtype("<U2")
    assert names.tolist() == ["a", "bb"]


def test_npz_reader_refuses_pickled_objects(tmp_path):
    np.savez(tmp_path / "obj.npz", xyz=np.zeros((1, 3)), o=np.array([{"a": 1}], dtype=object))
    with pytest.raises(NidarError, match=r"obj\.npz"):
        read_npz(tmp_path / "obj.npz")


def test_npz_garbage_and_npy(tmp_path):
    (tmp_path / "g.npz").write_bytes(b"not a zip file at all")
    with pytest.raises(NidarError, match=r"cannot read .*g\.npz"):
        read_npz(tmp_path / "g.npz")
    np.save(tmp_path / "a.npy", np.zeros(3))
    os.replace(tmp_path / "a.npy", tmp_path / "a.npz")
    with pytest.raises(NidarError, match="not an npz archive"):
        read_npz(tmp_path / "a.npz")


# --- validation ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda p: p.pop("xyz"), "no 'xyz'"),
        (lambda p: p.update(xyz=np.zeros((4, 2), np.float32)), r"\(N,3\)"),
        (lambda p: p.update(ring=np.zeros((257, 2), np.uint16)), "'ring' must have shape"),
        (lambda p: p.update(xyz_world=np.zeros((257,), np.float32)), "'xyz_world'"),
        (lambda p: p.update(extra=np.zeros(257, np.complex64)), "unsupported dtype"),
    ],
)
@pytest.mark.parametrize("writer", [write_npz, write_ply])
def test_invalid_points_dict(tmp_path, points, change, message, writer):
    change(points)
    with pytest.raises(NidarError, match=message):
        writer(tmp_path / "x.out", points)
    assert os.listdir(tmp_path) == []


# --- PLY -----------------------------------------------------------------------------------


def test_ply_round_trip_exact(tmp_path, points, assert_points_equal):
    points["big_index"] = np.arange(257, dtype=np.int64) * 1000  # fits int32: stored as i4
    points["half"] = np.linspace(0, 1, 257).astype(np.float16)
    write_ply(tmp_path / "scan.ply", points)
    assert_points_equal(read_ply(tmp_path / "scan.ply"), points)


def test_ply_file_layout(tmp_path, points):
    write_ply(tmp_path / "scan.ply", points)
    ply = plyfile.PlyData.read(str(tmp_path / "scan.ply"))
    assert not ply.text and ply.byte_order == "<"
    props = {p.name: p.val_dtype for p in ply["vertex"].properties}
    assert list(props)[:3] == ["x", "y", "z"]
    assert props["x"] == "f4" and props["nidar_observed"] == "u1" and props["ring"] == "u2"
    assert {"xyz_world_0", "xyz_world_1", "xyz_world_2", "intensity_nidar"} <= props.keys()
    assert "xyz" not in props and "material_names" not in props
    assert len(ply["vertex"].data) == 257
    info = " ".join(ply.obj_info)
    assert "birch leaf" in info and "wavelength_nm" in info


def test_ply_empty_point_set(tmp_path, make_points, assert_points_equal):
    empty = make_points(0)
    write_ply(tmp_path / "e.ply", empty)
    assert_points_equal(read_ply(tmp_path / "e.ply"), empty)


def test_ply_foreign_ascii_file(tmp_path):
    (tmp_path / "f.ply").write_text(
        "ply\nformat ascii 1.0\ncomment from another tool\n"
        "element vertex 2\nproperty double x\nproperty double y\nproperty double z\n"
        "property uchar intensity\nelement face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n1.5 -2 3\n200\n4 5 6.25 7\n3 0 1 1\n".replace("3\n200", "3 200")
    )
    got = read_ply(tmp_path / "f.ply")
    np.testing.assert_array_equal(got["xyz"], np.array([[1.5, -2, 3], [4, 5, 6.25]], np.float32))
    assert got["xyz"].dtype == np.float32
    np.testing.assert_array_equal(got["intensity"], np.array([200, 7], np.uint8))


def test_ply_int64_out_of_range_refused(tmp_path, points):
    points["huge"] = np.full(257, 2**40, dtype=np.int64)
    with pytest.raises(NidarError, match="'huge'"):
        write_ply(tmp_path / "s.ply", points)
    assert os.listdir(tmp_path) == []


def test_ply_writer_failure_leaves_nothing(tmp_path, points, monkeypatch):
    def failing_write(self, stream):
        with open(stream, "wb") as f:
            f.write(b"ply\nformat binary_little_endian 1.0\n")  # partial header
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(plyfile.PlyData, "write", failing_write)
    target = tmp_path / "out" / "scan.ply"
    with pytest.raises(NidarError, match=r"cannot write .*scan\.ply: No space left"):
        write_ply(target, points)
    assert os.listdir(target.parent) == []


def test_ply_malformed(tmp_path):
    (tmp_path / "bad.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vert")
    with pytest.raises(NidarError, match=r"cannot read .*bad\.ply"):
        read_ply(tmp_path / "bad.ply")
    (tmp_path / "noxyz.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nend_header\n1\n"
    )
    with pytest.raises(NidarError, match="no x, y, z"):
        read_ply(tmp_path / "noxyz.ply")


# --- the documented schema -------------------------------------------------------------------

GOLDEN = os.path.join(os.path.dirname(__file__), "..", "golden", "small_scene_points.npz")


def _schema_rows() -> dict[str, str]:
    """name -> its row of the table in the module docstring (continuation lines joined)."""
    from nidar_mi.io import points as module

    rows: dict[str, str] = {}
    name = None
    for line in module.__doc__.splitlines():
        if line.startswith("``"):
            name = line[2 : line.index("``", 2)]
            rows[name] = line
        elif name is not None and line.startswith(" ") and line.strip():
            rows[name] += " " + line.strip()
        else:
            name = None
    return rows


def test_documented_schema_matches_a_simulated_scan():
    rows = _schema_rows()
    assert {"xyz", "ring", "intensity_nidar", "nidar_observed"} <= set(rows)
    scan = read_npz(GOLDEN)
    sizes = {"N": str(len(scan["xyz"])), "M": str(len(scan["material_names"]))}
    if "instance_names" in scan:  # K instances and [0] = "" (none): K+1 names
        assert scan["instance_names"][0] == "" and scan["instance"].max() < len(
            scan["instance_names"]
        )
        sizes["K+1"] = str(len(scan["instance_names"]))
    for name, a in scan.items():
        _, dtype, *rest = rows[name].split()
        shape = rest[1] if dtype == "str" else rest[0]  # "str (U) (M,)"
        assert (a.dtype.kind == "U") if dtype == "str" else (a.dtype == np.dtype(dtype)), name
        shape = shape.replace("K+1", sizes.get("K+1", "K+1"))
        want = "".join(sizes.get(c, c) for c in shape)
        assert str(a.shape).replace(" ", "") == want, name


def test_ring_zero_is_the_highest_beam_as_documented():
    assert "0 = highest beam" in _schema_rows()["ring"]
    scan = read_npz(GOLDEN)
    x, y, z = scan["xyz"].astype(np.float64).T
    elevation = np.arctan2(z, np.hypot(x, y))
    rings = scan["ring"]
    assert elevation[rings == rings.min()].mean() > elevation[rings == rings.max()].mean()
