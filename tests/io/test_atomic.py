"""Tests of nidar_mi.io.atomic: atomic writes and guarded reads."""

import os

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io import atomic
from nidar_mi.io.atomic import atomic_path, atomic_write_json, atomic_write_text, reading
from nidar_mi.io.ownership import RECORD, Owner, read_record


def test_atomic_path_temp_name_and_replace(tmp_path):
    target = tmp_path / "sub" / "dir" / "points.npz"
    with atomic_path(target) as tmp:
        assert tmp.parent == target.parent  # same directory: os.replace stays atomic
        assert tmp.name.startswith(".points.npz.tmp-")
        assert tmp.suffix == ".npz"
        assert tmp != target
        tmp.write_bytes(b"abc")
        assert not target.exists()
    assert target.read_bytes() == b"abc"
    assert os.listdir(target.parent) == ["points.npz"]


def test_atomic_path_exception_leaves_nothing(tmp_path):
    target = tmp_path / "out.txt"
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert os.listdir(tmp_path) == []


def test_atomic_path_exception_keeps_old_target(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(KeyError):
        with atomic_path(target) as tmp:
            tmp.write_text("new")
            raise KeyError("x")
    assert target.read_text() == "old"
    assert os.listdir(tmp_path) == ["out.txt"]


def test_atomic_path_os_error_becomes_nidar_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(NidarError, match="cannot write"):
        atomic_write_text(blocker / "x.txt", "text")  # parent is a file
    with pytest.raises(NidarError, match=r"cannot write .*out\.txt"):
        with atomic_path(tmp_path / "out.txt") as tmp:
            tmp.write_text("partial")
            raise OSError(28, "No space left on device")
    assert os.listdir(tmp_path) == ["file"]


def test_atomic_write_text(tmp_path):
    target = tmp_path / "a" / "note.txt"
    atomic_write_text(target, "héllo\nworld\n")
    assert target.read_bytes() == "héllo\nworld\n".encode()


def test_atomic_write_json_format_and_numpy(tmp_path):
    target = tmp_path / "m.json"
    atomic_write_json(target, {"a": np.int64(3), "b": np.array([0.5, 1.0], np.float32)})
    assert target.read_text() == '{\n  "a": 3,\n  "b": [\n    0.5,\n    1.0\n  ]\n}\n'


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), np.float32("nan")])
def test_atomic_write_json_refuses_nan(tmp_path, bad):
    with pytest.raises(NidarError, match="m.json"):
        atomic_write_json(tmp_path / "m.json", {"x": [1.0, bad]})
    assert os.listdir(tmp_path) == []


def test_reading_missing_and_failing(tmp_path):
    with pytest.raises(NidarError, match=r"cannot read .*nope\.bin: no such file"):
        with reading(tmp_path / "nope.bin"):
            pass
    f = tmp_path / "f.bin"
    f.write_bytes(b"")
    with pytest.raises(NidarError) as info:
        with reading(f):
            raise ValueError("bad\nheader")
    assert str(info.value) == f"cannot read {f}: bad header"


# --- staged_directory ---------------------------------------------------------------------

#: A command for these tests: it writes x.txt, new.txt, newer.txt.
OWNER = Owner("test", "run", names=("*.txt",))


def test_staged_directory_publishes_whole_folder(tmp_path):
    from nidar_mi.io.atomic import staged_directory

    out = tmp_path / "a" / "out"
    with staged_directory(out, owner=OWNER) as stage:
        assert stage.parent == out.parent and stage.name.startswith(".out.partial-")
        (stage / "x.txt").write_text("1")
        assert not out.exists()
    assert sorted(p.name for p in out.iterdir()) == [RECORD, "x.txt"]
    assert read_record(out)["files"] == ["x.txt"] and read_record(out)["command"] == "test"
    assert [p.name for p in out.parent.iterdir()] == ["out"]
    assert out.stat().st_mode & 0o777 == 0o777 & ~_umask()


def _umask() -> int:
    import os

    m = os.umask(0)
    os.umask(m)
    return m


def test_staged_directory_never_mixes_runs(tmp_path):
    from nidar_mi.io.atomic import staged_directory

    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.md").write_text("user data")
    for overwrite in (False, True):  # a file the command did not write is never deleted
        with pytest.raises(
            NidarError, match=r"holds 1 file\(s\) that 'test' did not write \(mine.md\)"
        ):
            with staged_directory(out, owner=OWNER, overwrite=overwrite):
                raise AssertionError("not reached")
    assert (out / "mine.md").read_text() == "user data"
    # a folder of nidar_mi 0.1.0 (no record) whose files are all the command's: --overwrite
    (out / "mine.md").unlink()
    (out / "old.txt").write_text("0")
    with pytest.raises(NidarError, match="no record of what wrote it.*`overwrite`"):
        with staged_directory(out, owner=OWNER):
            raise AssertionError("not reached")
    with staged_directory(out, owner=OWNER, overwrite=True) as stage:
        (stage / "new.txt").write_text("2")
    assert sorted(p.name for p in out.iterdir()) == [RECORD, "new.txt"]
    # an earlier output (its record) is replaced whole without overwrite
    with staged_directory(out, owner=OWNER) as stage:
        (stage / "newer.txt").write_text("3")
    assert sorted(p.name for p in out.iterdir()) == [RECORD, "newer.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


@pytest.mark.parametrize("exc", [RuntimeError, KeyboardInterrupt])
def test_staged_directory_failure_leaves_target_untouched(tmp_path, exc):
    from nidar_mi.io.atomic import staged_directory

    out = tmp_path / "out"
    with pytest.raises(exc):
        with staged_directory(out, owner=OWNER) as stage:
            (stage / "half.txt").write_text("x")
            raise exc()
    assert list(tmp_path.iterdir()) == []


def test_staged_directory_failure_removes_the_folders_it_created(tmp_path):
    """The parents made for ``out`` go again when the run fails; one that existed stays."""
    from nidar_mi.io.atomic import staged_directory

    (tmp_path / "kept").mkdir()
    out = tmp_path / "kept" / "a" / "b" / "out"
    with pytest.raises(KeyboardInterrupt):
        with staged_directory(out, owner=OWNER) as stage:
            (stage / "half.txt").write_text("x")
            raise KeyboardInterrupt()
    assert [p.name for p in tmp_path.iterdir()] == ["kept"]
    assert list((tmp_path / "kept").iterdir()) == []


def test_staged_directory_bad_targets(tmp_path):
    from nidar_mi.io.atomic import staged_directory

    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(NidarError, match="not a folder"):
        with staged_directory(f, owner=OWNER):
            pass
    with pytest.raises(NidarError, match="cannot write"):
        with staged_directory(f / "sub" / "out", owner=OWNER):
            pass


_KILLED_WRITER = """
import os, signal, sys
from nidar_mi.io.atomic import atomic_path, staged_directory
from nidar_mi.io.ownership import Owner
folder = sys.argv[1]
with atomic_path(os.path.join(folder, "frame.npz")) as tmp:
    tmp.write_bytes(b"half")
    with staged_directory(os.path.join(folder, "scene.v1"), owner=Owner("t", "t")) as stage:
        (stage / "manifest.json").write_text("{")
        os.kill(os.getpid(), signal.SIGKILL)
"""


def test_leftovers_of_a_killed_writer_are_found_by_target_name(tmp_path):
    import subprocess
    import sys

    (tmp_path / "scene.v1").mkdir()  # an earlier output, and a foreign hidden file
    (tmp_path / ".hidden").write_text("mine")
    proc = subprocess.run([sys.executable, "-c", _KILLED_WRITER, str(tmp_path)])
    assert proc.returncode == -9  # really killed inside both with-blocks
    found = atomic.leftovers(tmp_path)
    assert [name for name, _ in found] == ["frame.npz", "scene.v1"]
    tmp_file, partial = (p for _, p in sorted(found, key=lambda f: f[0]))
    assert tmp_file.name.startswith(".frame.npz.tmp-") and tmp_file.suffix == ".npz"
    assert partial.name.startswith(".scene.v1.partial-") and (partial / "manifest.json").is_file()
    old = tmp_path / ".scene.v1.old-0123abcd"
    old.mkdir()
    assert ("scene.v1", old) in atomic.leftovers(tmp_path)
    assert atomic.leftovers(tmp_path / "missing") == []


def test_folder_lock_makes_a_second_writer_wait_its_turn(tmp_path, caplog):
    """Two writers of one shared cache: the second waits (and says so) until the first is done."""
    import logging
    import threading
    import time

    from nidar_mi.io.atomic import folder_lock

    order: list[str] = []
    inside, release = threading.Event(), threading.Event()

    def first():
        with folder_lock(tmp_path / "cache"):
            order.append("first in")
            inside.set()
            release.wait(10)
            order.append("first out")

    def second():
        with folder_lock(tmp_path / "cache", "the cache") as folder:
            order.append(f"second in {folder.name}")

    caplog.set_level(logging.INFO, logger="nidar_mi")
    a = threading.Thread(target=first)
    a.start()
    assert inside.wait(10)
    b = threading.Thread(target=second)
    b.start()
    time.sleep(0.3)
    assert order == ["first in"]  # still waiting
    release.set()
    a.join(10)
    b.join(10)
    assert order == ["first in", "first out", "second in cache"]
    assert "waiting for another process writing the cache" in caplog.text
    with folder_lock(tmp_path / "cache"):  # released: taken at once
        pass
    (tmp_path / "file").write_text("")
    with pytest.raises(NidarError, match="cannot write"):  # a file where the folder goes
        with folder_lock(tmp_path / "file" / "cache"):
            pass
