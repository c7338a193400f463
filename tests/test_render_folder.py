"""The render folder: request as cache key, reuse, re-render on any change, replaced whole."""

from __future__ import annotations

import os
import shutil

import pytest

from nidar_mi import render_folder as rf
from nidar_mi.errors import NidarError
from nidar_mi.io.ownership import RECORD
from nidar_mi.render_session import RenderOptions

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TARGET = os.path.join(REPO, "scenes", "target.xml")
FAST = dict(formats=("npz",), params={"cols": "128"}, cameras=False, progress=False)


def test_request_is_the_cache_key(tmp_path, variant):
    from nidar_mi.simulate import ensure_rendered

    scene = tmp_path / "target.xml"
    shutil.copy(TARGET, scene)
    out = tmp_path / "r"
    m1 = ensure_rendered(RenderOptions(str(scene), seed=1, **FAST), str(out))
    stamp = os.path.getmtime(out / rf.MANIFEST)
    assert rf.is_current(out, rf.RenderRequest.of(scene, seed=1, **_req(FAST)))
    assert ensure_rendered(RenderOptions(str(scene), seed=1, **FAST), str(out)) == m1
    assert os.path.getmtime(out / rf.MANIFEST) == stamp  # reused
    # another seed, another parameter, an edited scene: each is rendered again
    for change in (
        dict(seed=2),
        dict(seed=1, params={"cols": "64"}),
    ):
        m = ensure_rendered(RenderOptions(str(scene), **(FAST | change)), str(out))
        assert m["request"]["seed"] == change["seed"]
        assert m["request"]["params"] == change.get("params", FAST["params"])
    rings_cols = m["lidars"]["lidar"]["rays"]
    scene.write_text(scene.read_text().replace('value="905"', 'value="1550"'))
    m = ensure_rendered(
        RenderOptions(str(scene), seed=1, **(FAST | {"params": {"cols": "64"}})), str(out)
    )
    assert m["lidars"]["lidar"]["parameters"]["wavelength"] == 1550.0
    assert m["lidars"]["lidar"]["rays"] == rings_cols
    # a half-deleted folder is not current
    os.unlink(out / "lidar" / "points.npz")
    req = rf.RenderRequest.of(scene, seed=1, **_req(FAST | {"params": {"cols": "64"}}))
    assert not rf.is_current(out, req)


def _req(options: dict) -> dict:
    return {k: v for k, v in options.items() if k != "progress"}


def test_earlier_render_is_replaced_whole_and_user_folders_refused(tmp_path, variant):
    from nidar_mi.simulate import render_scene

    out = tmp_path / "r"
    render_scene(RenderOptions(TARGET, seed=1, **(FAST | {"formats": ("npz", "ply")})), str(out))
    assert (out / "lidar" / "points.ply").is_file()
    render_scene(RenderOptions(TARGET, seed=1, **FAST), str(out))
    assert not (out / "lidar" / "points.ply").exists()  # nothing stale from the first run
    assert sorted([*rf.read_manifest(out)["files"], RECORD]) == sorted(
        str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()
    )
    user = tmp_path / "mine"
    user.mkdir()
    (user / "notes.txt").write_text("keep")
    for overwrite in (False, True):
        with pytest.raises(NidarError, match="did not write \\(notes.txt\\)"):
            render_scene(RenderOptions(TARGET, seed=1, **FAST), str(user), overwrite=overwrite)
        assert [p.name for p in user.iterdir()] == ["notes.txt"]


def test_read_render_errors(tmp_path):
    with pytest.raises(NidarError, match="no readable manifest.json"):
        rf.read_render(tmp_path)
    (tmp_path / rf.MANIFEST).write_text("{not json")
    with pytest.raises(NidarError, match="not valid JSON"):
        rf.read_render(tmp_path)
    (tmp_path / rf.MANIFEST).write_text('{"lidars": {}}')
    with pytest.raises(NidarError, match="lists no lidar"):
        rf.read_render(tmp_path)


def test_nidar_request_covers_the_weights_contents(tmp_path):
    """A render with NIDAR intensity is keyed by what its weights folder holds, not only its
    path: a refitted default profile at the same path is another request; physics renders
    carry no weights key."""
    from nidar_mi.nidar.pipeline import shipped_weights_dir

    w = tmp_path / "w"
    shutil.copytree(shipped_weights_dir(), w)
    a = rf.RenderRequest.of(TARGET, intensity="nidar", weights=str(w))
    assert a.weights_sha256 == rf.weights_sha256(w) == rf.weights_sha256(shipped_weights_dir())
    assert rf.RenderRequest.of(TARGET, intensity="nidar").weights_sha256 == a.weights_sha256
    prof = w / "profiles" / "sim-905.json"
    prof.write_text(prof.read_text().replace('"sim-905"', '"sim-905b"', 1))
    b = rf.RenderRequest.of(TARGET, intensity="nidar", weights=str(w))
    assert b.weights_sha256 != a.weights_sha256 and b.to_dict() != a.to_dict()
    prof.unlink()  # without the profile: calibration.json decides, another key again
    assert rf.weights_sha256(w) not in (a.weights_sha256, b.weights_sha256)
    assert rf.RenderRequest.of(TARGET).weights_sha256 is None
