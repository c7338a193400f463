"""The import graph of the package: no module imports itself back through others, and every
import points down the layers of docs/ARCHITECTURE.md.

Every ``import`` statement counts, at module level or inside a function (a deferred import is
still a dependency), except those under ``if TYPE_CHECKING:`` and a module's
``if __name__ == "__main__":`` command hook. ``plugins/`` is installed as
``nidar_mi.plugins`` and is part of the graph. Importing a submodule runs its package's
``__init__`` first; that implicit edge is not counted, or every package re-exporting its
submodules would be a cycle.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
ROOTS = {"nidar_mi": REPO / "nidar_mi", "nidar_mi.plugins": REPO / "plugins"}


def _modules() -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package ``__init__``)."""
    mods = {}
    for prefix, root in ROOTS.items():
        for path in root.rglob("*.py"):
            parts = list(path.relative_to(root).with_suffix("").parts)
            is_pkg = parts[-1] == "__init__"
            if is_pkg:
                parts = parts[:-1]
            mods[".".join([prefix, *parts])] = (path, is_pkg)
    return mods


def _import_nodes(node: ast.AST):
    """Every import statement under ``node``, skipping ``if TYPE_CHECKING:`` bodies and a
    module's ``if __name__ == "__main__":`` command hook (it runs only as ``python -m``)."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.If) and ast.unparse(child.test) == "__name__ == '__main__'":
            continue
        if isinstance(child, ast.If) and ast.unparse(child.test) in (
            "TYPE_CHECKING",
            "typing.TYPE_CHECKING",
        ):
            yield from _import_nodes(ast.Module(body=child.orelse, type_ignores=[]))
            continue
        if isinstance(child, ast.Import | ast.ImportFrom):
            yield child
        yield from _import_nodes(child)


def _targets(node: ast.Import | ast.ImportFrom, module: str, is_pkg: bool, mods) -> set[str]:
    """The package modules an import statement loads (the most specific one per name)."""
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    else:
        if node.level:
            base = module.split(".") if is_pkg else module.split(".")[:-1]
            base = base[: len(base) - (node.level - 1)]
            prefix = ".".join(base + ([node.module] if node.module else []))
        else:
            prefix = node.module or ""
        names = [
            f"{prefix}.{a.name}" if f"{prefix}.{a.name}" in mods else prefix for a in node.names
        ]
    out = set()
    for name in names:
        while name and name not in mods:  # `import a.b.c` of a non-module attribute path
            name = name.rpartition(".")[0]
        if name:
            out.add(name)
    return out


def import_graph() -> dict[str, set[str]]:
    mods = _modules()
    graph = {}
    for module, (path, is_pkg) in mods.items():
        tree = ast.parse(path.read_text(), str(path))
        deps = set()
        for node in _import_nodes(tree):
            deps |= _targets(node, module, is_pkg, mods)
        graph[module] = deps - {module}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_graph_sees_deferred_and_relative_imports():
    graph = import_graph()
    assert "nidar_mi.io.points" in graph["nidar_mi.io.las"]  # module level, relative
    assert "nidar_mi.plugins" in graph["nidar_mi.backend"]  # inside a function
    assert "nidar_mi.lidar.config" in graph["nidar_mi.plugins.lidar"]  # absolute


def test_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles_in_the_package():
    assert cycles(import_graph()) == []


#: First component below ``nidar_mi`` -> layer (0 low, 1 middle, 2 top); docs/ARCHITECTURE.md.
LAYERS = {
    **dict.fromkeys(
        ("errors", "backend", "illumination", "io", "geometry", "labels", "lidar", "materials"),
        0,
    ),
    **dict.fromkeys(("plugins", "tasks"), 0),
    **dict.fromkeys(
        (
            "scene",
            "camera",
            "render_folder",
            "simulate",
            "sequence",
            "dataset",
            "datasets",
            "nidar",
            "cloud_intensity",
            "scenegen",
        ),
        1,
    ),
    "studies": 1,
    **dict.fromkeys(("eval", "cli"), 2),
}
#: Package-level modules that only start a command (``python -m nidar_mi.<command>``).
SHIMS = {"render", "assign", "train", "evaluate", "pseudo_nir", "calibrate", "drive"}


def _component(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _is_entry_point(module: str) -> bool:
    return _component(module) in SHIMS or module.endswith("__main__") or module == "nidar_mi"


def test_every_module_has_a_layer():
    graph = import_graph()
    assert {_component(m) for m in graph if not _is_entry_point(m)} - set(LAYERS) == set()


def test_imports_point_down_the_layers():
    offences = []
    for module, deps in import_graph().items():
        if _is_entry_point(module):
            continue
        own = LAYERS[_component(module)]
        for dep in deps:
            if dep == "nidar_mi" or not _component(dep):
                continue
            if _is_entry_point(dep):
                offences.append(f"{module} imports the entry point {dep}")
            elif _component(dep) == "cli" and _component(module) != "cli":
                offences.append(f"{module} imports the command line ({dep})")
            elif LAYERS[_component(dep)] > own:
                offences.append(f"{module} (layer {own}) imports {dep}")
    assert offences == []
