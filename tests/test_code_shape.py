"""The simulation and profile paths stay readable: no function over 80 lines or 8 parameters.

Parameters are the named ones, ``self`` / ``cls`` aside; ``*args`` / ``**kwargs`` (options
handed on to an options dataclass) do not count. Functions whose parameters are the terms of
one formula or one record are listed in :data:`ALLOWED` with their count, so they cannot grow.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "nidar_mi"
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


def _functions():
    for pattern in PATHS:
        for path in sorted(PACKAGE.glob(pattern)):
            tree = ast.parse(path.read_text(), str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    yield f"{path.relative_to(PACKAGE).as_posix()}:{node.name}", node


def _parameters(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = node.args
    names = [p.arg for p in (*a.posonlyargs, *a.args, *a.kwonlyargs)]
    return len([n for n in names if n not in ("self", "cls")])


def test_the_paths_exist():
    assert all(any(PACKAGE.glob(p)) for p in PATHS)


def test_no_long_function():
    long = {
        name: node.end_lineno - node.lineno + 1
        for name, node in _functions()
        if node.end_lineno - node.lineno + 1 > MAX_LINES
    }
    assert long == {}


def test_no_long_signature():
    counts = {name: _parameters(node) for name, node in _functions()}
    over = {name: n for name, n in counts.items() if n > ALLOWED.get(name, MAX_PARAMETERS)}
    assert over == {}
    assert {name: counts.get(name) for name in ALLOWED} == ALLOWED
