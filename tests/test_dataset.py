"""Training-data builder: split by scene, frame contents, resumability."""

import os
import shutil

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io.ownership import RECORD
from nidar_mi.render_dataset import build_dataset, split_scenes

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_split_is_by_scene_and_seeded():
    names = [f"s{i:02d}" for i in range(20)]
    a = split_scenes(names, (0.8, 0.1, 0.1), seed=1)
    assert [len(a[s]) for s in ("train", "val", "test")] == [16, 2, 2]
    assert sorted(sum(a.values(), [])) == names  # every scene exactly once
    assert a == split_scenes(list(reversed(names)), (0.8, 0.1, 0.1), seed=1)
    assert a != split_scenes(names, (0.8, 0.1, 0.1), seed=2)
    small = split_scenes(["a", "b", "c"], (0.8, 0.1, 0.1))
    assert all(len(v) == 1 for v in small.values())
    with pytest.raises(NidarError):
        split_scenes(names, (1.0, -0.5, 0.5))


@pytest.mark.slow
def test_frames_from_target_scene(variant, tmp_path):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    shutil.copy(os.path.join(REPO, "scenes", "target.xml"), scenes / "target.xml")
    out = tmp_path / "data"
    params = {"cols": "720"}
    meta = build_dataset(
        str(scenes), str(out), fractions=(1, 0, 0), spp=2, params=params, progress=False
    )
    assert meta["frames"]["train"] == ["target__camera"] and meta["wavelength_nm"] == 905.0
    f = np.load(out / "train" / "target__camera.npz")
    H, W = 160, 320
    assert f["rgb"].shape == (H, W, 3) and f["rgb"].dtype == np.uint8
    for k in ("nir", "intensity", "reflectance", "range", "depth"):
        assert f[k].shape == (H, W) and f[k].dtype == np.float32, k
    m = f["mask"]
    assert m.dtype == bool and 50 < m.sum() < m.size
    assert not f["intensity"][~m].any()
    # every projected return lies on a panel: ρ is one of the panel reflectances (or the ramp)
    rho = f["reflectance"][m]
    flat = (
        np.isclose(rho, 0.95, atol=1e-4)
        | np.isclose(rho, 0.5, atol=1e-4)
        | np.isclose(rho, 0.05, atol=1e-4)
    )
    ramp = np.isclose(rho, 0.2 + 0.6 * 505 / 1200, atol=1e-4)
    assert (flat | ramp).all()
    # compensated intensity of a Lambertian panel never exceeds ρ (cos θ ≤ 1, no extinction)
    assert np.all(f["intensity"][m] <= rho + 1e-6) and np.all(f["intensity"][m] > 0)
    # the LiDAR return and the camera see the same surface: camera z-depth at the pixel is
    # no larger than the LiDAR range (the camera is 0.2 m above the LiDAR) plus a margin
    assert np.all(f["depth"][m] <= f["range"][m] + 0.3)
    # the true reflectance per pixel is the same ρ the LiDAR saw there (Lambertian panels; a few
    # silhouette pixels may see another surface than the return that landed on them)
    same = np.isclose(f["R_true"][m], rho, atol=1e-4)
    assert same.mean() > 0.95
    lit = f["R_true"] >= 1e-3
    np.testing.assert_allclose(
        f["R_true"][lit] * f["S_true"][lit], np.pi * f["nir"][lit], rtol=1e-4
    )
    assert not f["S_true"][~lit].any()
    # the visible returns: at least one per masked pixel, their intensities include the map's
    n = len(f["points_xyz"])
    assert f["points_intensity"].shape == f["points_ring"].shape == (n,) and n >= m.sum()
    assert set(np.round(f["intensity"][m], 6)) <= set(np.round(f["points_intensity"], 6))
    assert f["points_ring"].min() >= 0
    # resumable: a second run renders nothing and keeps the frame
    stamp = os.path.getmtime(out / "train" / "target__camera.npz")
    build_dataset(str(scenes), str(out), fractions=(1, 0, 0), spp=2, params=params, progress=False)
    assert os.path.getmtime(out / "train" / "target__camera.npz") == stamp


# --------------------------------------------------------------------------- parallel runs

TINY = {"width": "64", "height": "48", "cols": "256"}
#: Scenes whose renders repeat exactly from one load to the next. Not warehouse.xml: Mitsuba
#: orders its six area lights differently at every load, and so draws other light samples.
REPEATABLE = ("street", "park", "parking_lot")


def _tiny_scenes(root):
    scenes = root / "scenes"
    scenes.mkdir()
    for name in REPEATABLE:
        shutil.copy(os.path.join(REPO, "scenes", f"{name}.xml"), scenes / f"{name}.xml")
    return scenes


def _descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (read from /proc)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry))
    out, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out


def _kill_a_rendering_worker(renders, stop, killed):
    """Once a render is being staged, SIGKILL one Ray worker of this process that runs a task."""
    import signal
    import time

    while not stop.is_set():
        if renders.is_dir() and any(".partial-" in p.name for p in renders.iterdir()):
            for pid in _descendants(os.getpid()):
                try:
                    with open(f"/proc/{pid}/cmdline", "rb") as f:
                        title = f.read()
                except OSError:
                    continue
                if title.startswith(b"ray::_execute"):
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
                    return
        time.sleep(0.01)


def _arrays(path):
    with np.load(path, allow_pickle=False) as f:
        return {k: f[k] for k in f.files}


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_workers_give_the_serial_frames_even_when_a_worker_is_killed(variant, tmp_path):
    """Two Ray workers, one SIGKILLed mid-render: its scene is rendered again, and every file
    matches the serial run (LiDAR data exactly; camera images to float32 rounding, since the
    film sums samples in thread order)."""
    import threading

    pytest.importorskip("ray")
    scenes = _tiny_scenes(tmp_path)
    opts = dict(fractions=(1, 1, 1), spp=1, params=TINY, progress=False)
    serial = build_dataset(str(scenes), str(tmp_path / "serial"), **opts)
    stop, killed = threading.Event(), []
    renders = tmp_path / "ray" / "renders"
    killer = threading.Thread(target=_kill_a_rendering_worker, args=(renders, stop, killed))
    killer.start()
    try:
        parallel = build_dataset(str(scenes), str(tmp_path / "ray"), workers=2, **opts)
    finally:
        stop.set()
        killer.join()
    assert killed, "no worker was caught rendering"
    assert parallel == serial
    for name in REPEATABLE:
        a = _arrays(tmp_path / "serial" / "renders" / name / "lidar_top" / "points.npz")
        b = _arrays(renders / name / "lidar_top" / "points.npz")
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a), name
    for split, fids in serial["frames"].items():
        for fid in fids:
            a = _arrays(tmp_path / "serial" / split / f"{fid}.npz")
            b = _arrays(tmp_path / "ray" / split / f"{fid}.npz")
            for k in ("intensity", "reflectance", "range", "mask", "K", "T_cam_lidar"):
                assert np.array_equal(a[k], b[k]), (fid, k)
            for k in ("nir", "depth"):
                np.testing.assert_allclose(b[k], a[k], rtol=1e-5, atol=1e-6 * a[k].max(), err_msg=k)
            assert np.abs(a["rgb"].astype(int) - b["rgb"].astype(int)).max() <= 1
    hidden = [p for p in (tmp_path / "ray").rglob(".*") if p.name != RECORD]
    assert hidden == []  # the killed render's staging folder was removed
    stamps = {p: p.stat().st_mtime for p in renders.glob("*/manifest.json")}
    build_dataset(str(scenes), str(tmp_path / "ray"), workers=2, **opts)  # resumed: all done
    assert {p: p.stat().st_mtime for p in renders.glob("*/manifest.json")} == stamps


def test_a_failing_scene_is_named_and_the_others_are_rendered(variant, tmp_path, capsys):
    """A scene that fails is named, the others are rendered, nothing is published; the next run
    reuses the renders."""
    from nidar_mi.cli.dataset import main

    scenes = _tiny_scenes(tmp_path)
    (scenes / "broken.xml").write_text(
        '<scene version="3.0.0"><shape type="sphere"/></scene>\n', encoding="utf-8"
    )
    out = tmp_path / "data"
    args = ["--scenes", str(scenes), "-o", str(out), "--spp", "1", "--split", "1,0,0", "-q"]
    args += [f"-D{k}={v}" for k, v in TINY.items()]
    assert main(args) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("error: broken: ") and "no lidar sensor" in err[0]
    assert err[1:] == [
        "error: 1 of 4 scenes failed (broken); the other 3 are written; "
        "run again to retry the failed ones"
    ]
    assert sorted(p.name for p in out.iterdir()) == [RECORD, "renders"]  # no split, no meta
    renders = out / "renders"
    assert sorted(p.name for p in renders.iterdir()) == sorted(REPEATABLE)
    stamps = {p: p.stat().st_mtime for p in renders.glob("*/manifest.json")}
    (scenes / "broken.xml").unlink()
    assert main(args) == 0
    assert {p: p.stat().st_mtime for p in renders.glob("*/manifest.json")} == stamps
    assert sorted(p.name for p in (out / "train").iterdir()) == [
        f"{n}__cam_front.npz" for n in sorted(REPEATABLE)
    ]


def test_workers_without_ray_is_one_line_and_writes_nothing(tmp_path, capsys, monkeypatch):
    import sys

    from nidar_mi.cli.dataset import main

    scenes = _tiny_scenes(tmp_path)
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` fails as if not installed
    out = tmp_path / "data"
    assert main(["--scenes", str(scenes), "-o", str(out), "--workers", "2", "-q"]) == 2
    assert capsys.readouterr().err == (
        "error: --workers and --ray-address need Ray: pip install 'nidar_mi[ray]'\n"
    )
    assert not out.exists()
