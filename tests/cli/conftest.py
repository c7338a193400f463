"""Fixtures of the command-line contract tests: a tiny scene, tiny inputs for every command, and
an in-process command call that returns (status, stdout, stderr)."""

from __future__ import annotations

import importlib
import os
import shutil

import numpy as np
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

#: A LiDAR of four rings and a 16x12 camera inside a grey dome of radius 20 m, lit by a flat sky:
#: renders in well under a second. Parameters: cols, width, height.
TINY_SCENE = """<?xml version="1.0"?>
<scene version="3.0.0">
    <default name="cols" value="32"/>
    <default name="width" value="16"/>
    <default name="height" value="12"/>
    <sensor type="lidar" id="lidar">
        <string name="elevation_angles" value="5, 0, -5, -10"/>
        <integer name="horizontal_resolution" value="$cols"/>
        <transform name="to_world"><translate z="1"/></transform>
    </sensor>
    <sensor type="perspective" id="cam">
        <float name="fov" value="90"/>
        <transform name="to_world"><lookat origin="0, 0, 1.2" target="10, 0, 1" up="0, 0, 1"/></transform>
        <film type="hdrfilm"><integer name="width" value="$width"/><integer name="height" value="$height"/></film>
    </sensor>
    <emitter type="constant"><spectrum name="radiance" value="360:1, 1700:1"/></emitter>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.3, 1700:0.6"/></bsdf>
    <shape type="sphere" id="dome"><float name="radius" value="20"/><ref id="grey"/>
        <boolean name="flip_normals" value="true"/></shape>
</scene>
"""


def _call_command(name: str, argv: list[str], capsys) -> tuple[int, str, str]:
    """Run ``python -m nidar_mi.<name> argv`` in this process: (status, stdout, stderr)."""
    main = importlib.import_module(f"nidar_mi.cli.{name}").main
    capsys.readouterr()
    try:
        status = main([str(a) for a in argv])
    except SystemExit as e:  # argparse: --help, usage errors
        status = e.code
    out, err = capsys.readouterr()
    return status, out, err


def _assert_one_error_line(status: int, err: str, needle: str = "") -> None:
    """Status 2 and exactly one ``error: ...`` line on stderr containing ``needle``."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert status == 2, err
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert needle in lines[0], err
    assert "Traceback" not in err


def _snapshot(folder) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones included) with its bytes."""
    from pathlib import Path

    root = Path(folder)
    if not root.exists():
        return {}
    if root.is_file():
        return {"": root.read_bytes()}
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    } | {str(p.relative_to(root)) + "/": b"" for p in root.rglob("*") if p.is_dir()}


# Helpers are handed out as fixtures: test modules never import conftest by name.


@pytest.fixture()
def call(capsys):
    """``call(command, argv) -> (status, stdout, stderr)``, in this process."""
    return lambda name, argv: _call_command(name, argv, capsys)


@pytest.fixture()
def one_error_line():
    """``one_error_line(status, stderr, needle="")``: status 2 and one ``error:`` line."""
    return _assert_one_error_line


@pytest.fixture()
def snapshot():
    """``snapshot(path) -> {relative path: bytes}`` of every file and folder under ``path``."""
    return _snapshot


@pytest.fixture()
def tiny_scene(tmp_path) -> str:
    """The tiny scene, alone in ``tmp_path/scenes``."""
    d = tmp_path / "scenes"
    d.mkdir()
    (d / "tiny.xml").write_text(TINY_SCENE)
    return str(d / "tiny.xml")


@pytest.fixture()
def assign_inputs(tmp_path) -> list[str]:
    """``--points --calib --image`` arguments of a 200-point cloud in front of a 32x24 camera."""
    import yaml

    from nidar_mi.io.images import write_png
    from nidar_mi.io.points import write_ply

    rng = np.random.default_rng(0)
    xyz = np.column_stack(
        [rng.uniform(4, 30, 200), rng.uniform(-8, 8, 200), rng.uniform(-1.5, 2, 200)]
    ).astype(np.float32)
    d = tmp_path / "assign_in"
    d.mkdir()
    write_ply(d / "cloud.ply", {"xyz": xyz, "intensity": rng.uniform(0, 1, 200).astype("f4")})
    write_png(d / "cam.png", (rng.uniform(0, 1, (24, 32, 3)) * 255).astype(np.uint8))
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
    cam = {"name": "front", "fx": 16, "fy": 16, "cx": 15.5, "cy": 11.5, "width": 32}
    cam |= {"height": 24, "T_cam_lidar": T.tolist()}
    (d / "calib.yaml").write_text(yaml.safe_dump({"cameras": [cam]}))
    return ["--points", d / "cloud.ply", "--calib", d / "calib.yaml", "--image", d / "cam.png"]


@pytest.fixture(scope="session")
def synthetic_data(tmp_path_factory):
    """A small synthetic training dataset (meta.json and frames, no renders)."""
    from tests.helpers.synthetic_frames import write_synthetic_dataset

    return write_synthetic_dataset(tmp_path_factory.mktemp("synthetic"), height=48, width=64)


@pytest.fixture()
def copy_of(tmp_path):
    """Copy a file or folder into ``tmp_path`` under a new name; returns the copy's path."""

    def _copy(src, name):
        dst = tmp_path / name
        (shutil.copytree if os.path.isdir(src) else shutil.copy)(src, dst)
        return dst

    return _copy
