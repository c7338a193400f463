"""Tests of ``python -m nidar_mi.materials``."""

import struct
import subprocess
import sys

import numpy as np

from nidar_mi.cli.materials import main
from nidar_mi.materials import list_materials, reflectance

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def test_list_prints_every_material_with_values(capsys):
    assert main(["--list"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split()[:5] == ["name", "kind", "rho550", "rho905", "rho1550"]
    rows = {line.split()[0]: line.split() for line in out[2:]}
    assert sorted(rows) == list_materials()
    grass = rows["grass"]
    assert grass[1] == "diffuse"
    np.testing.assert_allclose(
        [float(v) for v in grass[2:5]], reflectance("grass", [550, 905, 1550]), atol=5e-4
    )
    assert grass[5].startswith("#") and grass[6].startswith("earthlib:")


def test_plot_writes_a_png(tmp_path, capsys):
    out = tmp_path / "spectra.png"
    assert main(["--plot", "grass", "asphalt_old", "aluminium", "-o", str(out)]) == 0
    data = out.read_bytes()
    assert data[:8] == PNG_SIGNATURE
    width, height = struct.unpack(">II", data[16:24])
    assert width > 600 and height > 300
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left behind


def test_bad_name_is_one_line_exit_2_and_no_file(tmp_path, capsys):
    out = tmp_path / "spectra.png"
    assert main(["--plot", "grass", "no_such_material", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: unknown material 'no_such_material'") and err.count("\n") == 1
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_missing_output_folder_is_exit_2(tmp_path, capsys):
    assert main(["--plot", "grass", "-o", str(tmp_path / "nope" / "s.png")]) == 2
    assert "output folder does not exist" in capsys.readouterr().err


def test_runs_as_a_module_without_traceback():
    proc = subprocess.run(
        [sys.executable, "-m", "nidar_mi.materials", "--plot", "nope"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and proc.stderr.strip().startswith("error:")


def test_output_without_plot_is_an_error(tmp_path, capsys):
    assert main(["-o", str(tmp_path / "s.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: -o/--output names the --plot file") and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_plot_file_mode_follows_the_umask(tmp_path, capsys):
    import os

    old = os.umask(0o022)
    try:
        assert main(["--plot", "grass", "-o", str(tmp_path / "s.png")]) == 0
    finally:
        os.umask(old)
    assert (tmp_path / "s.png").stat().st_mode & 0o777 == 0o644
