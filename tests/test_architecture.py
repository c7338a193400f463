"""The package's layers (docs/ARCHITECTURE.md): no module imports from a layer above its own,
not even lazily inside a function."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "nidar_mi"

#: First component below ``nidar_mi`` -> layer (0 low, 1 middle, 2 top).
LAYERS = {
    "errors": 0,
    "backend": 0,
    "illumination": 0,
    "io": 0,
    "geometry": 0,
    "lidar": 0,
    "materials": 0,
    "datasets": 0,
    "plugins": 0,
    "scene": 1,
    "camera": 1,
    "render_folder": 1,
    "simulate": 1,
    "dataset": 1,
    "nidar": 1,
    "scenegen": 1,
    "studies": 1,
    "eval": 2,
    "cli": 2,
}
#: Package-level modules that only start a command (``python -m nidar_mi.<command>``).
SHIMS = {"__main__", "render", "assign", "train", "evaluate", "pseudo_nir", "calibrate"}


def _modules():
    yield from ((p, p.relative_to(PACKAGE).with_suffix("").parts) for p in PACKAGE.rglob("*.py"))
    yield from ((p, ("plugins", p.stem)) for p in (ROOT / "plugins").glob("*.py"))


def _imported(path: Path, parts: tuple[str, ...]) -> set[str]:
    """First components (below nidar_mi) of everything a module imports from the package."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    pkg = parts[:-1]
    out = set()
    for node in _walk_outside_main_guard(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(pkg[: len(pkg) - node.level + 1])
                names = (node.module.split(".") if node.module else []) or [
                    a.name for a in node.names
                ]
                target = base + names
            elif node.module and node.module.startswith("nidar_mi"):
                target = node.module.split(".")[1:] or [a.name for a in node.names]
            else:
                continue
            if target:
                out.add(target[0])
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("nidar_mi."):
                    out.add(a.name.split(".")[1])
    return out


def _is_main_guard(node: ast.AST) -> bool:
    return (
        isinstance(node, ast.If)
        and isinstance(node.test, ast.Compare)
        and isinstance(node.test.left, ast.Name)
        and node.test.left.id == "__name__"
    )


def _walk_outside_main_guard(tree: ast.AST):
    """Every node except those under ``if __name__ == "__main__":`` (a module's command hook)."""
    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        todo.extend(c for c in ast.iter_child_nodes(node) if not _is_main_guard(c))


def _is_shim(parts: tuple[str, ...]) -> bool:
    return parts[0] in SHIMS or parts[-1] == "__main__"


def test_every_package_module_has_a_layer():
    tops = {parts[0] for _, parts in _modules() if not _is_shim(parts) and parts[0] != "__init__"}
    assert tops - set(LAYERS) == set()


def test_imports_point_down():
    offences = []
    for path, parts in _modules():
        if _is_shim(parts) or parts == ("__init__",):
            continue
        own = LAYERS[parts[0]]
        for target in _imported(path, parts):
            if target in SHIMS:
                offences.append(f"{'/'.join(parts)} imports the command shim {target}")
            elif target == "cli" and parts[0] != "cli":
                offences.append(f"{'/'.join(parts)} imports the command line (cli)")
            elif LAYERS.get(target, 0) > own:
                offences.append(
                    f"{'/'.join(parts)} (layer {own}) imports {target} (layer {LAYERS[target]})"
                )
    assert offences == []
