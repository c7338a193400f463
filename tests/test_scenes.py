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
