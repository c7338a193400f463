"""Every shipped scene loads and yields a scan and both camera images in a small configuration."""

import glob
import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = sorted(glob.glob(os.path.join(REPO, "scenes", "*.xml")))
#: Small values for whichever of these parameters a scene declares.
SMALL = {"width": "48", "height": "27", "cols": "256"}
#: Fraction of beams that must return. Outdoors and indoors the ground meets every beam that
#: points down (8 of a VLP-16's 16, 58 of an HDL-64E's 64) up to dropout and the odd dark
#: or glazed surface; target.xml has only its panels within range.
MIN_RETURN_FRACTION = {"target.xml": 0.01}
DEFAULT_MIN_RETURN_FRACTION = 0.4


def _declared(path: str) -> set[str]:
    return {d.get("name") for d in ET.parse(path).getroot().findall("default")}


def test_scenes_and_their_documentation_agree():
    """Every shipped scene is described in docs/SCENES.md, and every scene file named there or in
    the README exists."""
    import re

    names = {os.path.basename(p) for p in SCENES}
    docs = open(os.path.join(REPO, "docs", "SCENES.md"), encoding="utf-8").read()
    readme = open(os.path.join(REPO, "README.md"), encoding="utf-8").read()
    assert names, "no scene files"
    assert {n for n in names if n not in docs} == set()
    named = set(re.findall(r"scenes/([A-Za-z0-9_]+\.xml)", docs + readme))
    assert named and named <= names


@pytest.mark.parametrize("path", SCENES, ids=os.path.basename)
def test_scene_renders_small(path, tmp_path, variant):
    from nidar_mi.io.images import read_exr
    from nidar_mi.io.points import read_npz
    from nidar_mi.materials import list_materials
    from nidar_mi.render_session import RenderOptions
    from nidar_mi.simulate import render_scene

    params = {k: v for k, v in SMALL.items() if k in _declared(path)}
    out = tmp_path / "out"
    options = RenderOptions(
        path, formats=("npz",), seed=1, spp=2, params=params, progress=False
    )  # fmt: skip
    manifest = render_scene(options, str(out))
    assert manifest["lidars"] and manifest["cameras"]
    for name, lidar in manifest["lidars"].items():
        fraction = lidar["returns"] / lidar["rays"]
        minimum = MIN_RETURN_FRACTION.get(os.path.basename(path), DEFAULT_MIN_RETURN_FRACTION)
        assert fraction > minimum, (name, fraction)
        points = read_npz(out / name / "points.npz")
        assert np.all(np.isfinite(points["intensity"])) and np.all(points["range"] > 0)
    for name in manifest["cameras"]:
        rgb = read_exr(out / name / "rgb.exr")
        nir = read_exr(out / name / "nir.exr")["Y"]
        assert (out / name / "rgb.png").is_file() and (out / name / "nir.png").is_file()
        lum = np.stack([rgb["R"], rgb["G"], rgb["B"]]).mean(axis=0)
        assert np.all(np.isfinite(lum)) and np.all(np.isfinite(nir))
        # light reaches most of the frame in both bands (sun and sky or lamps carry NIR)
        assert np.mean(lum > 0) > 0.9 and np.mean(nir > 0) > 0.9, name
    # every nidar_material names a library material (the loader would fail otherwise)
    text = open(path, encoding="utf-8").read()
    for el in ET.fromstring(text).iter("bsdf"):
        if el.get("type") == "nidar_material":
            assert el.find("string[@name='name']").get("value") in list_materials()


def _including(folder, name: str, target: str) -> str:
    path = os.path.join(folder, name)
    with open(path, "w", encoding="utf-8") as f:
        f.write(f'<scene version="3.0.0">\n  <include filename="{target}"/>\n</scene>\n')
    return path


@pytest.mark.parametrize(
    "files, message",
    [
        ({"a.xml": "a.xml"}, "scene include cycle: a.xml -> a.xml"),
        ({"a.xml": "b.xml", "b.xml": "a.xml"}, "scene include cycle: a.xml -> b.xml -> a.xml"),
        (
            {f"s{k:02d}.xml": f"s{k + 1:02d}.xml" for k in range(17)},
            "scene includes nested deeper than 15 levels: s00.xml -> ... -> s14.xml",
        ),
    ],
    ids=["self", "pair", "deep"],
)
def test_include_cycle_or_depth_is_one_short_line(tmp_path, variant, files, message):
    """A scene that includes itself (or nests includes past Mitsuba's 15 levels) gives one short
    line naming the chain once, not Mitsuba's message repeated per level."""
    from nidar_mi.errors import NidarError
    from nidar_mi.scene import load_scene

    paths = [_including(tmp_path, name, target) for name, target in files.items()]
    with pytest.raises(NidarError) as e:
        load_scene(paths[0], variant=variant)
    assert str(e.value) == f"{paths[0]}: {message}"
    assert len(str(e.value)) < 200 + len(paths[0])


def test_error_inside_an_include_names_the_file(tmp_path, variant):
    """An error inside an included file names that file, its line and who included it."""
    from nidar_mi.errors import NidarError
    from nidar_mi.scene import load_scene

    top = _including(tmp_path, "top.xml", "bad.xml")
    (tmp_path / "bad.xml").write_text(
        '<scene version="3.0.0">\n  <shape type="sphere"><float name="radius" value="x"/>'
        "</shape>\n</scene>\n",
        encoding="utf-8",
    )
    with pytest.raises(NidarError) as e:
        load_scene(top, variant=variant)
    assert str(e.value) == (
        f"{top}: in bad.xml (included from top.xml), line 2, col 25: "
        'could not parse floating point value "x"'
    )
