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
