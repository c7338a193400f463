"""Optional extras: a command that needs a module that is not installed says which extra to
install, in one line, with status 2, before any work. A missing module is simulated by setting
it to None in ``sys.modules`` (Python's import then fails, and ``find_spec`` finds nothing)."""

from __future__ import annotations

import sys

import pytest

from nidar_mi.cli._common import EXIT_USER_ERROR, run
from nidar_mi.errors import NidarError
from nidar_mi.extras import EXTRAS, extra_of, missing_extra, require


def _hide(monkeypatch, *modules: str) -> None:
    for m in modules:
        monkeypatch.setitem(sys.modules, m, None)


def test_require_names_the_missing_module_and_the_extra(monkeypatch):
    require("nidar", "train")  # everything is installed here (.[dev])
    _hide(monkeypatch, "safetensors")
    with pytest.raises(NidarError) as e:
        require("nidar", "train")
    assert str(e.value) == (
        "train needs the optional 'nidar' dependencies (safetensors not installed): "
        "pip install 'nidar_mi[nidar]'"
    )


def test_every_module_belongs_to_one_extra():
    modules = [m for mods in EXTRAS.values() for m in mods]
    assert len(modules) == len(set(modules))
    assert extra_of("torch.nn.functional") == "nidar" and extra_of("gtsam") == "drive"
    assert extra_of("numpy") is None


@pytest.mark.parametrize(
    "command, argv, extra, module",
    [
        ("train", ["data", "out"], "nidar", "torch"),
        ("assign", ["--kitti", "x", "-o", "out"], "nidar", "torch"),
        ("pseudo_nir", ["a.png", "-o", "out"], "nidar", "safetensors"),
        ("calibrate", ["scans", "-o", "p.json"], "nidar", "lightgbm"),
        ("drive", ["-o", "out"], "drive", "kiss_icp"),
        ("render", ["scenes/street.xml", "-o", "OUT", "--intensity", "nidar"], "nidar", "torch"),
        ("render", ["scenes/street.xml", "-o", "OUT", "--formats", "npz,laz"], "laz", "lazrs"),
        ("render", ["scenes/street.xml", "-o", "OUT", "--fog", "50"], "weather", "miepython"),
        ("weather", ["scenes", "-o", "OUT", "--rain", "10"], "weather", "miepython"),
        ("evaluate", ["--data", "data", "-o", "out"], "nidar", "torch"),
        ("reflectance_cue", ["--test", "data", "-o", "out/cue.json"], "nidar", "torch"),
    ],
)
def test_a_command_without_its_extra_fails_in_one_line(
    monkeypatch, tmp_path, capsys, command, argv, extra, module
):
    import importlib

    _hide(monkeypatch, module)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "scenes").symlink_to(_repo_scenes())
    main = importlib.import_module(f"nidar_mi.cli.{command}").main
    assert main(argv) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: "), err
    assert f"({module} not installed): pip install 'nidar_mi[{extra}]'" in err
    assert "this command" not in err  # checked up front, naming what needs it
    assert not (tmp_path / "OUT").exists() and not (tmp_path / "out").exists()


def test_a_profile_without_nidar_intensity_is_a_usage_error_first(monkeypatch, tmp_path, capsys):
    """``--profile`` without ``--intensity nidar`` has no effect: that is the error, whether or
    not the extra that ``--intensity nidar`` would need is installed."""
    from nidar_mi.cli.render import main

    _hide(monkeypatch, "torch")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "scenes").symlink_to(_repo_scenes())
    assert main(["scenes/street.xml", "-o", "OUT", "--profile", "kitti-hdl64e"]) == 2
    assert capsys.readouterr().err == "error: --profile applies to --intensity nidar\n"
    assert not (tmp_path / "OUT").exists()


def _repo_scenes() -> str:
    import os

    return os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes")


def test_run_turns_a_missing_extra_module_into_one_line(capsys):
    def work():
        raise ModuleNotFoundError("No module named 'gtsam'", name="gtsam")

    assert run(work) == EXIT_USER_ERROR
    assert capsys.readouterr().err == (
        "error: " + missing_extra("drive", "this command", ("gtsam",)) + "\n"
    )

    def other():
        raise ModuleNotFoundError("No module named 'not_an_extra'", name="not_an_extra")

    with pytest.raises(ModuleNotFoundError):  # a bug, not a missing extra: a traceback
        run(other)


def test_a_scene_whose_lidar_has_weather_needs_the_extra_before_any_scan(
    monkeypatch, tmp_path, capsys
):
    """Only the scene's XML says that its lidar scans in fog: the extra is checked when the scene
    loads, in one line, before anything is scanned or written."""
    from nidar_mi.cli.render import main

    text = open(f"{_repo_scenes()}/target.xml", encoding="utf-8").read()
    cut = '<float name="range_max" value="40"/>'
    assert cut in text
    scene = tmp_path / "foggy.xml"
    scene.write_text(text.replace(cut, cut + '<float name="fog" value="50"/>'), encoding="utf-8")
    _hide(monkeypatch, "miepython")
    monkeypatch.chdir(tmp_path)
    assert main([str(scene), "-o", "OUT", "--no-cameras"]) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: "), err
    assert "lidar 'lidar' with fog, rain or snow needs the optional 'weather'" in err
    assert "(miepython not installed): pip install 'nidar_mi[weather]'" in err
    assert not (tmp_path / "OUT").exists()
