"""Tests of nidar_mi.io.pcd: hand-written PCD v0.7 files."""

import struct

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io.pcd import read_pcd
from nidar_mi.io.point_cloud import read_point_cloud

ASCII_PCD = """\
# .PCD v0.7 - Point Cloud Data file format
VERSION 0.7
FIELDS x y z intensity ring
SIZE 4 4 4 4 2
TYPE F F F F U
COUNT 1 1 1 1 1
WIDTH 3
HEIGHT 1
VIEWPOINT 0 0 0 1 0 0 0
POINTS 3
DATA ascii
1.5 -2.25 0.125 0.75 3
-4 5e1 nan 12 65535
0 0 0 0 0
"""


def test_pcd_ascii(tmp_path):
    (tmp_path / "a.pcd").write_text(ASCII_PCD)
    got = read_pcd(tmp_path / "a.pcd")
    assert sorted(got) == ["intensity", "ring", "xyz"]
    want = np.array([[1.5, -2.25, 0.125], [-4, 50, np.nan], [0, 0, 0]], np.float32)
    np.testing.assert_array_equal(got["xyz"], want)
    assert got["xyz"].dtype == np.float32 and got["intensity"].dtype == np.float32
    np.testing.assert_array_equal(got["intensity"], [0.75, 12, 0])
    assert got["ring"].dtype == np.uint16
    np.testing.assert_array_equal(got["ring"], [3, 65535, 0])


def _binary_pcd(n_points_header: int, records: list[tuple]) -> bytes:
    header = (
        "VERSION .7\nFIELDS x y z _ t normal intensity\nSIZE 4 4 4 1 8 4 2\n"
        f"TYPE F F F U F F U\nCOUNT 1 1 1 3 1 2 1\nWIDTH {n_points_header}\nHEIGHT 1\n"
        f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n_points_header}\nDATA binary\n"
    )
    body = b"".join(struct.pack("<fff3xd2fH", *r) for r in records)
    return header.encode() + body


RECORDS = [
    (1.0, 2.0, 3.0, 0.5, 0.25, -0.75, 100),
    (-1.5, 0.0, 7.25, 1.5e9, 1.0, 0.0, 65000),
]


def test_pcd_binary(tmp_path):
    (tmp_path / "b.pcd").write_bytes(_binary_pcd(2, RECORDS))
    got = read_point_cloud(tmp_path / "b.pcd")
    assert sorted(got) == ["intensity", "normal", "t", "xyz"]  # "_" padding is skipped
    np.testing.assert_array_equal(got["xyz"], [[1, 2, 3], [-1.5, 0, 7.25]])
    assert got["t"].dtype == np.float64
    np.testing.assert_array_equal(got["t"], [0.5, 1.5e9])
    assert got["normal"].shape == (2, 2)
    np.testing.assert_array_equal(got["normal"], [[0.25, -0.75], [1.0, 0.0]])
    assert got["intensity"].dtype == np.float32
    np.testing.assert_array_equal(got["intensity"], [100, 65000])


def test_pcd_width_height_without_points(tmp_path):
    text = ASCII_PCD.replace("POINTS 3\n", "")
    (tmp_path / "a.pcd").write_text(text)
    assert read_pcd(tmp_path / "a.pcd")["xyz"].shape == (3, 3)


@pytest.mark.parametrize(
    "content, message",
    [
        (ASCII_PCD.replace("DATA ascii", "DATA binary_compressed"), "binary_compressed"),
        (ASCII_PCD.replace("DATA ascii\n", ""), "no DATA line"),
        (ASCII_PCD.replace("FIELDS x y z intensity ring\n", ""), "no FIELDS"),
        (ASCII_PCD.replace("SIZE 4 4 4 4 2", "SIZE 4 4 4 4"), "different lengths"),
        (ASCII_PCD.replace("TYPE F F F F U", "TYPE F F F F X"), "unsupported TYPE"),
        (ASCII_PCD.replace("POINTS 3", "POINTS 4"), "expected 4 x 5"),
        (ASCII_PCD.replace("FIELDS x y z", "FIELDS a b c"), "no x, y, z"),
        (ASCII_PCD.replace("0.75 3", "0.75 3.5"), "invalid literal"),
        (ASCII_PCD.replace("DATA ascii", "DATA xml"), "unknown PCD DATA"),
    ],
)
def test_pcd_malformed(tmp_path, content, message):
    (tmp_path / "bad.pcd").write_text(content)
    with pytest.raises(NidarError, match=rf"cannot read .*bad\.pcd: .*{message}"):
        read_pcd(tmp_path / "bad.pcd")


def test_pcd_binary_truncated(tmp_path):
    (tmp_path / "t.pcd").write_bytes(_binary_pcd(3, RECORDS))
    with pytest.raises(NidarError, match="fewer than the 3 points"):
        read_pcd(tmp_path / "t.pcd")


# --- writing ------------------------------------------------------------------------------


def test_write_pcd_round_trip(tmp_path, make_points, assert_points_equal):
    from nidar_mi.io.pcd import write_pcd

    pts = make_points(257) | {
        "label": np.arange(257, dtype=np.uint16) % 100,
        "instance": np.arange(257, dtype=np.uint32),
        "t": np.linspace(0.0, 0.1, 257, dtype=np.float32),
        "instance_names": np.array(["", "car_1"]),
    }
    write_pcd(tmp_path / "p.pcd", pts)
    assert_points_equal(read_pcd(tmp_path / "p.pcd"), pts)
    assert_points_equal(read_point_cloud(tmp_path / "p.pcd"), pts)


def test_write_pcd_layout_follows_the_pcd_spec(tmp_path):
    """The file read by hand against the PCD v0.7 specification (pointclouds.org, "The PCD
    (Point Cloud Data) file format"): header entries in the prescribed order, one ``SIZE`` /
    ``TYPE`` / ``COUNT`` per field, ``WIDTH * HEIGHT == POINTS``, and binary data of packed
    little-endian records of exactly ``POINTS * sum(SIZE)`` bytes right after ``DATA binary``."""
    from nidar_mi.io.pcd import write_pcd

    xyz = np.array([[1.5, -2.0, 0.25], [100.0, 0.0, -3.5], [0.0, 7.0, 1.0]], np.float32)
    pts = {
        "xyz": xyz,
        "intensity": np.array([0.5, 0.0, 2.0], np.float32),
        "ring": np.array([0, 63, 7], np.uint16),
        "label": np.array([40, 10, 0], np.uint16),
        "time": np.array([0.0, 0.05, 0.099], np.float64),
        "valid": np.array([True, False, True]),
        "xyz_world": xyz + 10.0,
    }
    write_pcd(tmp_path / "p.pcd", pts)
    raw = (tmp_path / "p.pcd").read_bytes()
    lines, pos = [], 0
    while True:
        end = raw.index(b"\n", pos)
        lines.append(raw[pos:end].decode("ascii"))
        pos = end + 1
        if lines[-1].startswith("DATA"):
            break
    entries = [ln for ln in lines if not ln.startswith("#")]
    keys = [ln.split()[0] for ln in entries]
    assert keys == [
        "VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS",
        "DATA",
    ]  # fmt: skip
    h = {ln.split()[0]: ln.split()[1:] for ln in entries}
    assert h["VERSION"] == ["0.7"] and h["DATA"] == ["binary"]
    names = ["x", "y", "z", "intensity", "ring", "label", "time", "valid"]
    names += ["xyz_world_0", "xyz_world_1", "xyz_world_2"]
    assert h["FIELDS"] == names
    assert h["SIZE"] == ["4", "4", "4", "4", "2", "2", "8", "1", "4", "4", "4"]
    assert h["TYPE"] == ["F", "F", "F", "F", "U", "U", "F", "U", "F", "F", "F"]
    assert h["COUNT"] == ["1"] * 11
    assert h["WIDTH"] == ["3"] and h["HEIGHT"] == ["1"] and h["POINTS"] == ["3"]
    assert h["VIEWPOINT"] == ["0", "0", "0", "1", "0", "0", "0"]
    record = "<ffffHHdBfff"
    assert len(raw) - pos == 3 * struct.calcsize(record)
    for i in range(3):
        got = struct.unpack_from(record, raw, pos + i * struct.calcsize(record))
        want = (*xyz[i], pts["intensity"][i], pts["ring"][i], pts["label"][i], pts["time"][i])
        want += (int(pts["valid"][i]), *(xyz[i] + 10.0))
        np.testing.assert_array_equal(np.array(got, np.float64), np.array(want, np.float64))


def test_write_pcd_refuses_bad_points(tmp_path):
    from nidar_mi.io.pcd import write_pcd

    with pytest.raises(NidarError, match="no 'xyz'"):
        write_pcd(tmp_path / "p.pcd", {"intensity": np.zeros(3, np.float32)})
    with pytest.raises(NidarError, match="cannot be named 'x'"):
        write_pcd(tmp_path / "p.pcd", {"xyz": np.zeros((2, 3)), "x": np.zeros(2)})
    with pytest.raises(NidarError, match="spaces"):
        write_pcd(tmp_path / "p.pcd", {"xyz": np.zeros((2, 3)), "a b": np.zeros(2)})
    assert not (tmp_path / "p.pcd").exists()
