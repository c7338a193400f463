"""Names across the package: no module reaches into another's private names.

A name with a leading underscore belongs to its module; a module with a leading underscore
(``cli/_common.py``, ``cli/_workers.py``, ``plugins/_validate.py``) belongs to its package, whose
modules share it. Everything in ``nidar_mi/`` and ``plugins/`` (installed as
``nidar_mi.plugins``) is read.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
ROOTS = {"nidar_mi": REPO / "nidar_mi", "nidar_mi.plugins": REPO / "plugins"}


def _modules():
    """(dotted name, is a package ``__init__``, parsed tree) of every module."""
    for prefix, root in ROOTS.items():
        for path in sorted(root.rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            is_pkg = parts[-1] == "__init__"
            if is_pkg:
                parts = parts[:-1]
            yield ".".join([prefix, *parts]), is_pkg, ast.parse(path.read_text(), str(path))


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _imported_module(node: ast.ImportFrom, module: str, is_pkg: bool) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".") if is_pkg else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def private_imports() -> list[str]:
    """``module: what`` for every import of another module's private name, or of a private
    module from outside its package."""
    found = []
    for module, is_pkg, tree in _modules():
        package = module if is_pkg else module.rpartition(".")[0]
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                source = _imported_module(node, module, is_pkg)
                names = [f"{source}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for name in names:
                if not name.startswith("nidar_mi"):
                    continue  # another library's privates: tested where they are used
                parts = name.split(".")
                owner = ".".join(parts[:-1])
                if _private(parts[-1]) and owner != module:
                    # a private module may be imported by the modules of its own package
                    if not (owner == package and _is_module(name)):
                        found.append(f"{module}: {name}")
                for k, part in enumerate(parts[:-1]):
                    inside = ".".join(parts[:k])
                    if _private(part) and not package.startswith(inside):
                        found.append(f"{module}: {name}")
    return sorted(set(found))


def _is_module(dotted: str) -> bool:
    prefix = "nidar_mi.plugins" if dotted.startswith("nidar_mi.plugins") else "nidar_mi"
    rest = dotted[len(prefix) :].lstrip(".").replace(".", "/")
    root = ROOTS[prefix]
    return (root / f"{rest}.py").is_file() or (root / rest / "__init__.py").is_file()


def test_the_finder_sees_a_private_import():
    tree = ast.parse("from .points import _flatten\nfrom ._common import run\n")
    node_a, node_b = tree.body
    assert _imported_module(node_a, "nidar_mi.io.las", False) == "nidar_mi.io.points"
    assert _imported_module(node_b, "nidar_mi.cli.render", False) == "nidar_mi.cli._common"
    assert _is_module("nidar_mi.cli._common") and not _is_module("nidar_mi.io.points._flatten")


def test_no_module_imports_another_modules_private_names():
    assert private_imports() == []


# --------------------------------------------------------------------------- one name, one thing

#: Public names several modules define on purpose, and why.
SHARED_NAMES = {
    # every command module's entry point and parser: the command-line contract (cli/__init__.py)
    "main": "cli",
    "build_parser": "cli",
}

#: Module basenames several packages hold on purpose, and why.
SHARED_BASENAMES = {
    # each package's settings, read as the package's: lidar.config (the sensor's XML
    # parameters, LidarConfig) and nidar.config (the networks and their training, TrainConfig)
    "config": {"nidar_mi.lidar.config", "nidar_mi.nidar.config"},
}


def public_names() -> dict[str, list[str]]:
    """Public function and class name -> the modules that define it at module level."""
    found: dict[str, list[str]] = {}
    for module, _, tree in _modules():
        for node in tree.body:
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                if not node.name.startswith("_"):
                    found.setdefault(node.name, []).append(module)
    return found


def _allowed_name(name: str, modules: list[str]) -> bool:
    package = SHARED_NAMES.get(name)
    return package is not None and all(
        m.startswith(f"nidar_mi.{package}.") or m == f"nidar_mi.{package}" for m in modules
    )


def test_no_public_name_is_defined_by_two_modules():
    repeated = {
        name: modules
        for name, modules in public_names().items()
        if len(modules) > 1 and not _allowed_name(name, modules)
    }
    assert repeated == {}


def _is_shim_pair(modules: list[str]) -> bool:
    """``nidar_mi.<command>`` (the ``python -m`` shim) and ``nidar_mi.cli.<command>``."""
    shims = [m for m in modules if m.count(".") == 1]
    return (
        len(modules) == 2
        and len(shims) == 1
        and set(modules) == {shims[0], "nidar_mi.cli." + shims[0].rpartition(".")[2]}
    )


def test_no_module_basename_repeats():
    by_name: dict[str, list[str]] = {}
    for module, is_pkg, _ in _modules():
        if not is_pkg and not module.endswith("__main__"):
            by_name.setdefault(module.rpartition(".")[2], []).append(module)
    repeated = {
        name: modules
        for name, modules in by_name.items()
        if len(modules) > 1
        and not _is_shim_pair(modules)
        and set(modules) != SHARED_BASENAMES.get(name)
    }
    assert repeated == {}


def test_the_name_checks_see_a_repeat():
    assert _is_shim_pair(["nidar_mi.render", "nidar_mi.cli.render"])
    assert not _is_shim_pair(["nidar_mi.eval.report", "nidar_mi.materials.report"])
    assert _allowed_name("main", ["nidar_mi.cli.render", "nidar_mi.cli"])
    assert not _allowed_name("main", ["nidar_mi.cli.render", "nidar_mi.eval.image_cues"])
    assert not _allowed_name("load_frame", ["nidar_mi.training_frames", "nidar_mi.x"])
