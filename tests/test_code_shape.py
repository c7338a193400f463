"""Functions stay readable: in the whole package (``nidar_mi/`` and ``plugins/``) no function
over 90 lines or 10 parameters; on the simulation and profile paths (:data:`PATHS`) none over
80 lines or 8 parameters.

Parameters are the named ones, ``self`` / ``cls`` aside; ``*args`` / ``**kwargs`` (options
handed on to an options dataclass) do not count. Functions of the stricter paths whose
parameters are the terms of one formula or one record are listed in :data:`ALLOWED` with their
count, so they cannot grow. Tests and benchmarks are not read.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PACKAGE = REPO / "nidar_mi"
#: Every module of the package, ``plugins/`` (installed as ``nidar_mi.plugins``) included.
ROOTS = (PACKAGE, REPO / "plugins")
PACKAGE_MAX_LINES = 90
PACKAGE_MAX_PARAMETERS = 10
PATHS = (
    "simulate.py",
    "sequence.py",
    "render_session.py",
    "scene.py",
    "camera.py",
    "lidar/*.py",
    "profiles/*.py",
    "datasets/sensor_profiles.py",
    "datasets/profile_fitting.py",
    "nidar/pipeline.py",
    "cloud_intensity.py",
)
MAX_LINES = 80
MAX_PARAMETERS = 8
#: ``module:function`` -> its parameter count: each parameter is one term of the return model,
#: one per-laser column, one input of the point sampling, or one column of the returns a
#: profile is fitted on (the forms' ``fit``, the ``context`` form's named inputs besides).
ALLOWED = {
    "lidar/return_model.py:detect": 10,
    "lidar/layouts.py:_sorted_table": 9,
    "nidar/pipeline.py:point_intensity": 10,
    "profiles/forms.py:fit": 9,
    "profiles/context.py:fit": 9,
}


def _functions_in(paths, root: Path):
    for path in paths:
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                yield f"{path.relative_to(root).as_posix()}:{node.name}", node


def _functions():
    """The functions of the stricter :data:`PATHS`."""
    for pattern in PATHS:
        yield from _functions_in(sorted(PACKAGE.glob(pattern)), PACKAGE)


def _package_functions():
    """Every function of the package."""
    for root in ROOTS:
        yield from _functions_in(sorted(root.rglob("*.py")), REPO)


def _parameters(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = node.args
    names = [p.arg for p in (*a.posonlyargs, *a.args, *a.kwonlyargs)]
    return len([n for n in names if n not in ("self", "cls")])


def test_the_paths_exist():
    assert all(any(PACKAGE.glob(p)) for p in PATHS)


def _longer_than(functions, max_lines: int) -> dict[str, int]:
    """Name -> length in lines of every function longer than ``max_lines``."""
    lengths = {name: node.end_lineno - node.lineno + 1 for name, node in functions}
    return {name: n for name, n in lengths.items() if n > max_lines}


def test_no_long_function():
    assert _longer_than(_functions(), MAX_LINES) == {}


def test_no_long_signature():
    counts = {name: _parameters(node) for name, node in _functions()}
    over = {name: n for name, n in counts.items() if n > ALLOWED.get(name, MAX_PARAMETERS)}
    assert over == {}
    assert {name: counts.get(name) for name in ALLOWED} == ALLOWED


def test_no_long_function_in_the_package():
    assert _longer_than(_package_functions(), PACKAGE_MAX_LINES) == {}


def test_no_long_signature_in_the_package():
    counts = {name: _parameters(node) for name, node in _package_functions()}
    assert {name: n for name, n in counts.items() if n > PACKAGE_MAX_PARAMETERS} == {}


def test_the_package_guard_reads_every_module():
    names = {name.partition(":")[0] for name, _ in _package_functions()}
    assert {"nidar_mi/nidar/training.py", "plugins/lidar.py", "nidar_mi/cli/render.py"} <= names
