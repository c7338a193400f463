"""``reconstruct``: bad drives are one ``error:`` line, status 2, before any work, and nothing is
written."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.cli.reconstruct import main


def _drive(root, frames: int = 3, poses=None):
    vel = root / "velodyne"
    vel.mkdir(parents=True)
    for k in range(frames):
        np.zeros((8, 4), "<f4").tofile(vel / f"{k:06d}.bin")
    if poses is not None:
        np.savetxt(root / "poses.txt", np.asarray(poses).reshape(len(poses), -1)[:, :12])
    return root


def _eye(n):
    return np.tile(np.eye(4)[:3].ravel(), (n, 1))


@pytest.mark.parametrize(
    "case, needle",
    [
        ("one scan", "at least 2"),
        ("no velodyne", "no velodyne/"),
        ("pose count", "3 poses for 4 scans"),
        ("nan pose", "poses.txt:2: a value is not finite"),
        ("not rigid", "poses.txt:1: the 3x3 part is not a rotation"),
        ("unknown holdout", "--holdout names frames that are not in"),
        ("all held out", "--holdout holds out every frame"),
        ("bad range", "not a range"),
        ("missing poses file", "does not exist"),
        ("negative transient frames", "--transient-frames must lie in [0, 400] (got -1)"),
        ("weights without the prior", "no effect with --no-prior"),
        ("weights not a folder", "is not a folder"),
        ("no odometry", "needs the optional 'drive' and 'resim' dependencies (kiss_icp, open3d"),
        ("out holds the poses", "holds the input"),
        ("out in the scans", "lies in the drive's scans"),
        (
            "huge holdout range",
            "names 300000001 ids, more than a drive may hold (--max-frames 400)",
        ),
        ("scan too large", "more than a scan may (4000000)"),
        ("carving passes", "--carve-passes must lie in [0, 16] (got -3)"),
        ("iterations", "--iterations must lie in [1, 10000] (got 99999999999)"),
        ("max frames", "--max-frames must be >= 2 (got -5)"),
        ("albedo scale", "--albedo-scale must lie in [0.01, 100] (got 0)"),
        ("albedo scale nan", "--albedo-scale must lie in [0.01, 100] (got nan)"),
        ("empty scan", "0 returns beyond 2.5 m; a scan needs at least 1000"),
        ("all-zero scans", "0 returns beyond 2.5 m; a scan needs at least 1000"),
    ],
)
def test_bad_drives_are_one_line_and_write_nothing(case, needle, tmp_path, capsys, monkeypatch):
    root = tmp_path / "drive"
    extra: list[str] = []
    if case == "one scan":
        _drive(root, 1)
    elif case == "no velodyne":
        root.mkdir()
    elif case == "pose count":
        _drive(root, 4, _eye(3))
    elif case == "nan pose":
        p = _eye(3)
        p[1, 3] = np.nan
        _drive(root, 3, p)
    elif case == "not rigid":
        p = _eye(3)
        p[0, 0] = 2.0
        _drive(root, 3, p)
    elif case == "unknown holdout":
        _drive(root, 3)
        extra = ["--holdout", "000001,000009"]
    elif case == "all held out":
        _drive(root, 3)
        extra = ["--holdout", "000000:000002"]
    elif case == "bad range":
        _drive(root, 3)
        extra = ["--holdout", "000002:000001"]
    elif case == "missing poses file":
        _drive(root, 3)
        extra = ["--poses", str(tmp_path / "nope.txt")]
    elif case == "negative transient frames":
        _drive(root, 3)
        extra = ["--transient-frames", "-1"]
    elif case == "weights without the prior":
        _drive(root, 3, _eye(3))
        extra = ["--weights", str(tmp_path), "--no-prior"]
    elif case == "weights not a folder":
        _drive(root, 3, _eye(3))
        extra = ["--weights", str(tmp_path / "nope")]
    elif case == "out holds the poses":
        _drive(root, 3)
        (tmp_path / "out").mkdir()
        np.savetxt(tmp_path / "out" / "poses.txt", _eye(3))
        extra = ["--poses", str(tmp_path / "out" / "poses.txt"), "--overwrite"]
    elif case == "out in the scans":
        _drive(root, 3, _eye(3))
        extra = ["-o", str(root / "velodyne" / "sub.bin")]
    elif case == "huge holdout range":
        _drive(root, 3, _eye(3))
        extra = ["--holdout", "000000:300000000"]
    elif case == "scan too large":
        _drive(root, 3, _eye(3))
        with open(root / "velodyne" / "000001.bin", "r+b") as f:
            f.truncate(16 * 4_000_001)  # sparse: no disk used
    elif case in ("carving passes", "iterations", "max frames"):
        _drive(root, 3, _eye(3))
        flag = {"carving passes": "--carve-passes", "max frames": "--max-frames"}
        value = {"carving passes": "-3", "iterations": "99999999999", "max frames": "-5"}
        extra = [flag.get(case, "--iterations"), value[case]]
    elif case.startswith("albedo scale"):
        _drive(root, 3, _eye(3))
        extra = ["--albedo-scale", "nan" if case.endswith("nan") else "0"]
    elif case in ("empty scan", "all-zero scans"):
        _drive(root, 3, _eye(3))  # all-zero points; one scan empty
        if case == "empty scan":
            (root / "velodyne" / "000001.bin").write_bytes(b"")
        extra = ["--no-prior"]
    elif case == "no odometry":
        from nidar_mi import extras

        _drive(root, 3)
        monkeypatch.setattr(extras, "installed", lambda m: m not in ("kiss_icp", "open3d"))
    out = [] if "-o" in extra else ["-o", str(tmp_path / "out")]
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    status = main([str(root), *out, *extra])
    err = capsys.readouterr().err
    assert status == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert needle in lines[0], lines[0]
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_holdout_ranges_expand_with_their_width():
    from nidar_mi.resim.drive_folder import parse_ids

    assert parse_ids("000008:000011, r5") == ["000008", "000009", "000010", "000011", "r5"]
    assert parse_ids("") == []


def test_each_step_switch_turns_its_step_off(monkeypatch):
    # every --no-* flag of STEP_SWITCHES reaches ReconstructOptions as its step off, the others on
    import nidar_mi.resim.reconstruction as rec
    from nidar_mi.cli.reconstruct import STEP_SWITCHES, main

    field = {
        "--no-moving": "moving",
        "--no-holes": "holes",
        "--no-see-through": "through",
        "--no-splats": "splats",
        "--no-range-offsets": "range_offsets",
        "--no-prior": "prior",
    }
    assert sorted(field) == sorted(flag for flag, _ in STEP_SWITCHES)
    seen = []
    monkeypatch.setattr(rec, "check", lambda options: seen.append(options))
    monkeypatch.setattr(rec, "reconstruct", lambda options: {})
    monkeypatch.setattr("nidar_mi.backend.set_variant", lambda *a, **k: None)
    for flag, name in field.items():
        assert main(["drive", "-o", "out", "-q", flag]) == 0
        assert getattr(seen[-1], name) is False
        assert all(getattr(seen[-1], other) is True for other in field.values() if other != name)
