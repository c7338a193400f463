"""Generated runs: per-scene seeds, distinct layouts, index.json, resumability, rendering."""

import hashlib
import json
import os

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.scenegen.generate import (
    generate,
    generate_scene,
    layout_hash,
    scene_id,
    scene_rng,
)

SMALL = {"width": "48", "height": "27", "cols": "256"}


def test_scene_rng_is_per_scene_and_independent_of_count():
    a = scene_rng(4, 2).random(3)
    np.testing.assert_array_equal(a, scene_rng(4, 2).random(3))
    assert not np.array_equal(a, scene_rng(4, 3).random(3))
    assert not np.array_equal(a, scene_rng(5, 2).random(3))
    assert scene_id(4, 2) == "scene_4_2"


def test_no_two_scenes_of_a_run_share_a_layout():
    layouts = [generate_scene(0, k)[0] for k in range(30)]
    shapes = {layout.shapes for layout in layouts}
    assert len(shapes) == 30
    assert len({tuple(layout.materials()) for layout in layouts}) > 20


def test_run_writes_scenes_and_index(tmp_path):
    out = tmp_path / "gen"
    index = generate(str(out), 3, 9, progress=False)
    files = sorted(p.name for p in out.iterdir())
    scenes = ["index.json", "scene_9_0.xml", "scene_9_1.xml", "scene_9_2.xml"]
    assert files == [".nidar_mi-output.json", *scenes]
    record = json.loads((out / ".nidar_mi-output.json").read_text())
    assert (record["command"], record["files"]) == ("scenegen", scenes)
    on_disk = json.loads((out / "index.json").read_text())
    assert on_disk["scenes"] == index["scenes"]
    assert [e["id"] for e in index["scenes"]] == ["scene_9_0", "scene_9_1", "scene_9_2"]
    for e in index["scenes"]:
        _, text = generate_scene(9, e["index"])
        assert (out / e["file"]).read_text() == text
        assert e["seed"] == 9
        T = np.array(e["camera"]["T_cam_lidar"])
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-7)
    assert index["run"] == {"seed": 9, "count": 3, "written": 3, "skipped": 0}


def test_run_resumes_and_keeps_existing_files(tmp_path):
    out = tmp_path / "gen"
    generate(str(out), 2, 1, progress=False)
    marker = "<!-- edited -->\n"
    kept = out / "scene_1_0.xml"
    kept.write_text(kept.read_text() + marker)
    (out / "scene_1_1.xml").unlink()
    index = generate(str(out), 4, 1, progress=False)
    assert index["run"]["written"] == 3 and index["run"]["skipped"] == 1
    assert kept.read_text().endswith(marker)  # skipped, not rewritten
    entry = next(e for e in index["scenes"] if e["id"] == "scene_1_0")
    assert entry["edited"] and entry["sha256"] == hashlib.sha256(kept.read_bytes()).hexdigest()
    assert (out / "scene_1_1.xml").read_text() == generate_scene(1, 1)[1]
    # a second seed in the same folder adds to the index
    index = generate(str(out), 1, 2, progress=False)
    assert [e["id"] for e in index["scenes"]] == [f"scene_1_{k}" for k in range(4)] + ["scene_2_0"]
    assert not [p for p in out.iterdir() if ".tmp-" in p.name]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"count": 0, "seed": 0}, "`count`"),
        ({"count": 1, "seed": -1}, "`seed`"),
        ({"count": 1, "seed": 0, "kind": "moon"}, "`kind`"),
    ],
)
def test_bad_arguments(tmp_path, kwargs, message):
    with pytest.raises(NidarError, match=message):
        generate(str(tmp_path / "gen"), progress=False, **kwargs)
    assert not (tmp_path / "gen").exists()


def test_a_repeated_layout_in_the_folder_is_refused(tmp_path):
    layout, _ = generate_scene(0, 0)
    assert layout_hash(layout) == layout_hash(generate_scene(0, 0)[0])
    assert layout_hash(layout) != layout_hash(generate_scene(0, 1)[0])
    (tmp_path / "scene_copy.xml").write_text("a copy")
    copy = {"id": "scene_copy", "file": "scene_copy.xml", "seed": -1, "index": 0}
    copy |= {"layout_sha256": layout_hash(layout), "sha256": hashlib.sha256(b"a copy").hexdigest()}
    (tmp_path / "index.json").write_text(json.dumps({"scenes": [copy]}))
    with pytest.raises(NidarError, match="scene_0_0 repeats the layout of scene_copy"):
        generate(str(tmp_path), 1, 0, progress=False)
    assert not (tmp_path / "scene_0_0.xml").exists()


def test_index_entries_describe_the_files_beside_them(tmp_path):
    """An entry whose file is gone is dropped; an edited file keeps its entry, marked."""
    out = tmp_path / "gen"
    generate(str(out), 3, 5, progress=False)
    (out / "scene_5_1.xml").unlink()
    index = generate(str(out), 1, 5, progress=False)
    assert [e["id"] for e in index["scenes"]] == ["scene_5_0", "scene_5_2"]
    for e in index["scenes"]:
        assert hashlib.sha256((out / e["file"]).read_bytes()).hexdigest() == e["sha256"]


def test_corrupt_index_is_reported(tmp_path):
    (tmp_path / "index.json").write_text("{not json")
    with pytest.raises(NidarError, match="not a scene index"):
        generate(str(tmp_path), 1, 0, progress=False)


@pytest.mark.parametrize("kind", ["urban", "vegetated"])
def test_generated_scene_renders(tmp_path, variant, kind):
    from nidar_mi.render_session import RenderOptions
    from nidar_mi.simulate import render_scene

    scenes = tmp_path / "gen"
    index = generate(str(scenes), 1, 3, kind=kind, progress=False)
    entry = index["scenes"][0]
    out = tmp_path / "render"
    options = RenderOptions(
        str(scenes / entry["file"]), formats=("npz",), seed=0, spp=2, params=SMALL, progress=False
    )
    manifest = render_scene(options, str(out))
    lidar = manifest["lidars"]["lidar_top"]
    assert lidar["parameters"]["preset"] == entry["lidar"]["preset"]
    # Every beam pointing 10 deg or more below the horizon meets the ground within ~11 m
    # (LiDAR at 1.6-2.0 m): bright enough to return unless an object (or 1 % dropout) intervenes.
    from nidar_mi.io.points import read_npz
    from nidar_mi.lidar.pattern import elevation_table

    points = read_npz(out / "lidar_top" / "points.npz")
    low = np.flatnonzero(elevation_table(entry["lidar"]["preset"]) <= -10.0)
    per_ring = np.bincount(points["ring"], minlength=low.max() + 1)[low]
    assert low.size > 0 and np.all(per_ring >= 0.85 * 256), per_ring
    for name in ("rgb.png", "nir.png", "depth.exr", "calib.json"):
        assert (out / "cam_front" / name).is_file()
    calib = json.loads((out / "cam_front" / "calib.json").read_text())
    # the renderer's calibration agrees with the generator's rig
    np.testing.assert_allclose(
        calib["T_cam_lidar"]["lidar_top"], entry["camera"]["T_cam_lidar"], atol=1e-4
    )
    fx = 48 / 2 / np.tan(np.radians(entry["camera"]["fov_deg"]) / 2)
    np.testing.assert_allclose(np.array(calib["K"])[0, 0], fx, rtol=1e-4)
    np.testing.assert_allclose(
        np.array(manifest["lidars"]["lidar_top"]["to_world"]),
        entry["lidar"]["T_world_lidar"],
        atol=1e-4,
    )
    assert os.path.getsize(out / "lidar_top" / "points.npz") > 0


def test_every_scene_of_a_run_loads_and_scans(tmp_path, variant):
    """Eight scenes of one run (both kinds, both presets) load and return beams off the ground."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    index = generate(str(tmp_path), 8, 21, progress=False)
    seen = set()
    for e in index["scenes"]:
        loaded = load_scene(str(tmp_path / e["file"]), variant=variant, params={"cols": "64"})
        assert [s.id() for s in loaded.lidars] == ["lidar_top"]
        assert [c.id() for c in loaded.cameras] == ["cam_front"]
        result = scan(loaded.scene, loaded.lidars[0], seed=0)
        # at least the beams pointing down (half of a VLP-16's, most of an HDL-64E's) return
        assert result.valid.mean() > 0.4, e["id"]
        seen.add((e["kind"], e["lidar"]["preset"]))
    assert {k for k, _ in seen} == {"urban", "vegetated"}
    assert {p for _, p in seen} == {"hdl64e", "vlp16"}


def test_a_run_larger_than_the_free_space_is_refused(tmp_path, monkeypatch):
    import shutil

    from nidar_mi.scenegen.generate import run_bytes

    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage._replace(free=100 << 10))
    need = run_bytes(3, None, None, None)
    assert need > 100 << 10
    with pytest.raises(NidarError, match=r"needs about [\d.]+ KiB \(3 scenes x [\d.]+ KiB\), "
                       r"more than the 100.0 KiB free on "):  # fmt: skip
        generate(str(tmp_path / "gen"), 3, 0, progress=False)
    assert not (tmp_path / "gen").exists()
    # a city's estimate grows with its blocks and drive frames
    small = run_bytes(1, "city", (2, 1), {"frames": 2})
    assert run_bytes(1, "city", (4, 3), {"frames": 2}) > small
    assert run_bytes(1, "city", (2, 1), {"frames": 2000}) > small
