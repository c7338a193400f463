"""Packaging: a regular (non-editable) install ships the plugins as nidar_mi.plugins, and every
imported distribution is declared."""

import os
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.slow
def test_wheel_install_ships_plugins(tmp_path):
    target = tmp_path / "site"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "--target",
            str(target),
            REPO,
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    # the metadata is clean: no deprecated license table, no data folder outside `packages`
    assert "project.license" not in r.stderr and "absent from the `packages`" not in r.stderr
    assert (target / "nidar_mi" / "plugins" / "lidar.py").is_file()
    for data in (
        "nidar/weights/irnet.safetensors",
        "nidar/weights/MODEL_CARD.md",
        "nidar/weights/profiles/sim-905.json",
    ):
        assert (target / "nidar_mi" / data).is_file(), data
    assert list((target / "nidar_mi" / "materials" / "data").glob("*.csv"))
    assert (target / "nidar_mi" / "lidar" / "data" / "hdl64e_s2_sztaki.csv").is_file()
    for table in ("water_segelstein_1981.csv", "ice_warren_brandt_2008.csv"):
        assert (target / "nidar_mi" / "weather" / "data" / table).is_file()
    code = (
        "import nidar_mi, nidar_mi.plugins as p; print(nidar_mi.__file__); print(p.__file__);"
        "from nidar_mi.backend import set_variant; set_variant('llvm_ad_spectral');"
        "import mitsuba as mi;"
        "s = mi.load_dict({'type': 'scene', 'l': {'type': 'lidar', 'preset': 'vlp16'}});"
        "print(s.sensors()[0].config.rings)"
    )
    env = dict(os.environ, PYTHONPATH=str(target))
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=str(tmp_path),
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.split()
    assert lines[0].startswith(str(target)) and lines[1].startswith(str(target))
    assert lines[2] == "16"


def test_every_imported_distribution_is_declared():
    """Each third-party module the package imports belongs to a declared dependency."""
    import ast
    import importlib.metadata
    import re
    from pathlib import Path

    tomllib = pytest.importorskip("tomllib")
    project = tomllib.loads((Path(REPO) / "pyproject.toml").read_text())["project"]
    declared = project["dependencies"] + [
        d for extra in project["optional-dependencies"].values() for d in extra
    ]

    def norm(name: str) -> str:
        return re.sub(r"[-_.]+", "-", name).lower()

    declared = {norm(re.split(r"[<>=!~\[; ]", d, maxsplit=1)[0]) for d in declared}
    imported = set()
    for root in ("nidar_mi", "plugins"):
        for path in Path(REPO, root).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Import):
                    imported |= {a.name.split(".")[0] for a in node.names}
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    imported.add(node.module.split(".")[0])
    third_party = imported - set(sys.stdlib_module_names) - {"nidar_mi"}
    assert {"PIL", "yaml", "torch"} <= third_party
    owners = importlib.metadata.packages_distributions()
    missing = {
        m for m in third_party if not ({norm(d) for d in owners.get(m, [])} | {norm(m)}) & declared
    }
    assert not missing, f"imported but not declared in pyproject.toml: {sorted(missing)}"


def test_every_package_folder_is_listed():
    """A folder of nidar_mi (code or data) missing from `packages` would be left out of wheels,
    and setuptools warns about data folders outside it."""
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    from pathlib import Path

    root = Path(REPO)
    listed = set(
        tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    )
    folders = {
        "nidar_mi." + ".".join(p.relative_to(root / "nidar_mi").parts)
        if p != root / "nidar_mi"
        else "nidar_mi"
        for p in [root / "nidar_mi", *(root / "nidar_mi").rglob("*")]
        if p.is_dir() and p.name != "__pycache__" and any(f.is_file() for f in p.iterdir())
    }
    assert folders | {"nidar_mi.plugins"} == listed


def _project() -> dict:
    tomllib = pytest.importorskip("tomllib")
    from pathlib import Path

    return tomllib.loads((Path(REPO) / "pyproject.toml").read_text())["project"]


def _name(requirement: str) -> str:
    import re

    return re.sub(r"[-_.]+", "-", re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0]).lower()


def test_extras_table_agrees_with_pyproject():
    """Every extra of nidar_mi.extras is declared, and each module it names belongs to a
    distribution that extra installs; `dev` pulls every extra the tests use."""
    import importlib.metadata

    from nidar_mi.extras import EXTRAS

    extras = _project()["optional-dependencies"]
    owners = importlib.metadata.packages_distributions()
    for extra, modules in EXTRAS.items():
        declared = {_name(r) for r in extras[extra]}
        if extra == "laz":  # laspy[lazrs]: the lazrs distribution comes with laspy's extra
            declared.add("lazrs")
        for m in modules:
            dists = {_name(d) for d in owners.get(m, [m])}
            assert dists & declared, (extra, m, dists, declared)
    dev = next(r for r in extras["dev"] if r.startswith("nidar_mi["))
    assert set(dev[len("nidar_mi[") : -1].split(",")) == set(EXTRAS) - {"lpips"}


def test_dependencies_have_floors_and_constraints_pin_them():
    """Every dependency has a floor (or a pin); constraints.txt pins every dependency and every
    extra's (bench and lpips aside) to one version, and setup.sh installs through it."""
    project = _project()
    core = project["dependencies"]
    assert all(("==" in r or ">=" in r) for r in core), core
    assert "numpy>=2.0" in core  # colour-science 0.4.7 and plyfile 1.1.5 need numpy 2
    text = open(os.path.join(REPO, "constraints.txt"), encoding="utf-8").read()
    pins = dict(
        line.split("==", 1) for line in text.splitlines() if line and not line.startswith("#")
    )
    assert all(pins.values()) and len(pins) > 50
    wanted = list(core)
    for extra, reqs in project["optional-dependencies"].items():
        if extra not in ("bench", "lpips"):
            wanted += [r for r in reqs if not r.startswith("nidar_mi[")]
    missing = sorted({_name(r) for r in wanted} - set(pins))
    assert missing == [], f"not pinned in constraints.txt: {missing}"
    assert pins["torch"].startswith("2.13.0") and pins["mitsuba"] == "3.9.1"
    setup = open(os.path.join(REPO, "scripts", "setup.sh"), encoding="utf-8").read()
    assert "PIN=(-c constraints.txt)" in setup
    assert setup.count('"${PIN[@]}"') == 3  # pip, torch, the package: every install


_BLOCKER = """
import sys
OPTIONAL = set(sys.argv[1].split(','))
class Missing:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in OPTIONAL:
            raise ModuleNotFoundError(f'No module named {name!r}', name=name)
sys.meta_path.insert(0, Missing())
from nidar_mi.cli.render import main
status = main(sys.argv[2:])
print('loaded:', sorted({m.split('.')[0] for m in sys.modules} & OPTIONAL))
sys.exit(status)
"""


@pytest.mark.slow
def test_physics_render_needs_no_optional_extra(tmp_path):
    """The core install renders: ``render scenes/street.xml`` (physics intensity, cameras,
    every default format) with every module of every extra, and pandas, made unimportable."""
    from nidar_mi.extras import EXTRAS

    optional = sorted({m for mods in EXTRAS.values() for m in mods} | {"pandas"})
    small = ["-D", "width=32", "-D", "height=18", "-D", "cols=128", "--spp", "1"]
    scene = os.path.join(REPO, "scenes", "street.xml")
    argv = [scene, "-o", str(tmp_path / "out"), "-q", *small]
    r = subprocess.run(
        [sys.executable, "-c", _BLOCKER, ",".join(optional), *argv],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=str(tmp_path),
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip().splitlines()[-1] == "loaded: []"
    assert (tmp_path / "out" / "lidar_top" / "points.las").is_file()
    assert (tmp_path / "out" / "cam_front" / "rgb.png").is_file()


def _environment_reads() -> dict[str, set[str]]:
    """The package's own environment variables (``NIDAR*``) read by the package, the notebooks
    and the scripts: name -> the files that read it."""
    import json
    import re
    from pathlib import Path

    read = re.compile(r"""(?:environ\.get\(|environ\[|getenv\()\s*["'](NIDAR[A-Z0-9_]*)["']""")
    found: dict[str, set[str]] = {}
    root = Path(REPO)
    files = [*root.glob("nidar_mi/**/*.py"), *root.glob("scripts/*.py"), *root.glob("plugins/*.py")]
    for path in [*files, *root.glob("notebooks/*.ipynb")]:
        text = path.read_text(encoding="utf-8")
        if path.suffix == ".ipynb":
            cells = json.loads(text)["cells"]
            text = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")
        for name in read.findall(text):
            found.setdefault(name, set()).add(str(path.relative_to(root)))
    return found


def test_every_environment_variable_read_is_documented():
    """Notebook 05 used to read ``NIDAR_KITTI_DIR``, which the README never named: every
    variable of the package that code, notebooks or scripts read is in the README's table."""
    with open(os.path.join(REPO, "README.md"), encoding="utf-8") as f:
        readme = f.read()
    table = readme[readme.index("### Environment variables") :]
    reads = _environment_reads()
    assert {"NIDAR_MI_DATA", "NIDAR_MAX_MEMORY"} <= set(reads)  # the scan finds them
    missing = {name: sorted(files) for name, files in reads.items() if f"`{name}`" not in table}
    assert not missing, f"read but not in the README's environment table: {missing}"
