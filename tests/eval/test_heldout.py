"""eval.heldout.render_scenes: cached renders of scene files, a failing scene named."""

from __future__ import annotations

import os
import shutil

import pytest

from nidar_mi.eval.heldout import render_scenes
from nidar_mi.tasks import TasksFailed

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TINY = {"width": "48", "height": "32", "cols": "128"}


def test_render_scenes_names_the_failing_scene_and_renders_the_others(variant, tmp_path, capsys):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    shutil.copy(os.path.join(REPO, "scenes", "street.xml"), scenes / "street.xml")
    (scenes / "empty.xml").write_text('<scene version="3.0.0"/>\n', encoding="utf-8")
    files = [str(scenes / "empty.xml"), str(scenes / "street.xml")]
    cache = tmp_path / "renders"
    with pytest.raises(TasksFailed, match=r"^1 of 2 scenes failed \(empty\)"):
        render_scenes(files, str(cache), params=TINY, spp=1)
    err = capsys.readouterr().err
    assert err.startswith("error: empty: ") and "no lidar sensor" in err
    assert (cache / "street" / "manifest.json").is_file() and not (cache / "empty").exists()
    stamp = (cache / "street" / "manifest.json").stat().st_mtime
    dirs = render_scenes(files[1:], str(cache), params=TINY, spp=1)  # cached: not rendered again
    assert dirs == [str(cache / "street")]
    assert (cache / "street" / "manifest.json").stat().st_mtime == stamp
