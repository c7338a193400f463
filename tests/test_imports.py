"""The import graph of the package: no module imports itself back through others, no package
imports itself back through others, and every import points down the layers of
docs/ARCHITECTURE.md.

Every ``import`` statement counts, at module level, inside a function (a deferred import is
still a dependency) or in a module's ``if __name__ == "__main__":`` command hook, except those
under ``if TYPE_CHECKING:``. ``plugins/`` is installed as ``nidar_mi.plugins`` and is part of
the graph. Importing a submodule runs its package's ``__init__`` first; that implicit edge is
not counted, or every package re-exporting its submodules would be a cycle.

The package graph has one node per subpackage of ``nidar_mi`` (all its modules, nested
packages included), one per module directly in ``nidar_mi/`` (``errors``, ``simulate``, the
``python -m`` shims, ...) and one per ``__main__`` module (a command entry point that runs
only as ``python -m`` and that nothing imports).
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
    """Every import statement under ``node``, skipping ``if TYPE_CHECKING:`` bodies."""
    for child in ast.iter_child_nodes(node):
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


def package_of(module: str) -> str:
    """The package-graph node of a module (module docstring)."""
    parts = module.split(".")
    if len(parts) <= 2 or parts[-1] == "__main__":
        return module
    return ".".join(parts[:2])


def package_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The module graph contracted to packages (edges inside one node dropped)."""
    out: dict[str, set[str]] = {}
    for module, deps in graph.items():
        node = package_of(module)
        out.setdefault(node, set()).update(package_of(d) for d in deps)
    return {node: deps - {node} for node, deps in out.items()}


def test_the_graph_sees_deferred_and_relative_imports():
    graph = import_graph()
    assert "nidar_mi.io.points" in graph["nidar_mi.io.las"]  # module level, relative
    assert "nidar_mi.plugins" in graph["nidar_mi.backend"]  # inside a function
    assert "nidar_mi.lidar.config" in graph["nidar_mi.plugins.lidar"]  # absolute
    assert "nidar_mi.cli.render" in graph["nidar_mi.render"]  # a `__main__` command hook


def test_package_nodes():
    assert package_of("nidar_mi.eval.drive.study") == "nidar_mi.eval"
    assert package_of("nidar_mi.plugins.lidar") == "nidar_mi.plugins"
    assert package_of("nidar_mi.simulate") == "nidar_mi.simulate"
    assert package_of("nidar_mi.materials") == "nidar_mi.materials"
    assert package_of("nidar_mi.materials.__main__") == "nidar_mi.materials.__main__"
    assert package_of("nidar_mi") == "nidar_mi"
    graph = {"nidar_mi.a.x": {"nidar_mi.a.y", "nidar_mi.b"}, "nidar_mi.a.y": set()}
    assert package_graph(graph) == {"nidar_mi.a": {"nidar_mi.b"}}


def test_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles_in_the_package():
    assert cycles(import_graph()) == []


def _edges_within(graph: dict[str, set[str]], component: list[str]) -> list[str]:
    """Every module import that joins two nodes of a package cycle, ``a -> b``."""
    inside = set(component)
    return sorted(
        f"{module} -> {dep}"
        for module, deps in graph.items()
        for dep in deps
        if package_of(module) in inside
        and package_of(dep) in inside
        and package_of(dep) != package_of(module)
    )


def test_no_import_cycles_between_packages():
    graph = import_graph()
    found = cycles(package_graph(graph))
    assert [(c, _edges_within(graph, c)) for c in found] == []


#: First component below ``nidar_mi`` -> layer (0 low, 1 middle, 2 top); docs/ARCHITECTURE.md.
LAYERS = {
    **dict.fromkeys(
        ("errors", "extras", "backend", "illumination", "io", "geometry", "labels", "lidar"),
        0,
    ),
    **dict.fromkeys(("materials", "weather", "plugins", "tasks", "training_frames", "progress"), 0),
    **dict.fromkeys(
        (
            "scene",
            "camera",
            "render_folder",
            "render_session",
            "simulate",
            "sequence",
            "render_dataset",
            "datasets",
            "nidar",
            "profiles",
            "cloud_intensity",
            "cloud_weather",
            "scenegen",
        ),
        1,
    ),
    "studies": 1,
    **dict.fromkeys(("eval", "resim", "cli"), 2),
}
#: Package-level modules that only start a command (``python -m nidar_mi.<command>``).
SHIMS = {
    "render",
    "assign",
    "train",
    "evaluate",
    "pseudo_nir",
    "calibrate",
    "drive",
    "dataset",
    "reflectance_cue",
    "reconstruct",
}


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


def test_the_architecture_diagram_is_the_import_graph():
    """docs/ARCHITECTURE.md's picture of the layers is drawn from this graph
    (``scripts/layer_diagram.py --write`` redraws it)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "layer_diagram", REPO / "scripts" / "layer_diagram.py"
    )
    diagram = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(diagram)
    doc = (REPO / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    assert diagram._with_diagram(doc, diagram.mermaid()) == doc
    reduced = diagram.reduced({"a": {"b", "c"}, "b": {"c"}, "c": set()})
    assert reduced == {"a": {"b"}, "b": {"c"}, "c": set()}


def _module_level_imports(node: ast.AST):
    """Import statements run when a module is imported: not those inside functions, nor
    under ``if TYPE_CHECKING:``."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            continue
        if isinstance(child, ast.If) and ast.unparse(child.test) in (
            "TYPE_CHECKING",
            "typing.TYPE_CHECKING",
        ):
            continue
        if isinstance(child, ast.Import | ast.ImportFrom):
            yield child
        yield from _module_level_imports(child)


#: Modules a physics render imports when they are imported (the command, the plugins, the scan,
#: the materials, the writers): none may import a module of an optional extra at module level.
CORE_ROOTS = (
    "nidar_mi",
    "nidar_mi.cli.render",
    "nidar_mi.plugins",
    "nidar_mi.simulate",
    "nidar_mi.sequence",
    "nidar_mi.render_session",
    "nidar_mi.render_folder",
    "nidar_mi.lidar.scan",
    "nidar_mi.materials",
    "nidar_mi.scenegen",
    "nidar_mi.io.point_cloud",
)


def test_core_import_path_imports_no_optional_extra():
    """Importing the core modules (and every module they import at module level, package
    ``__init__`` files included) imports no module of an extra (nidar_mi.extras.EXTRAS)."""
    from nidar_mi.extras import EXTRAS

    optional = {m for mods in EXTRAS.values() for m in mods}
    mods = _modules()
    seen, todo, offences = set(), list(CORE_ROOTS), []
    while todo:
        module = todo.pop()
        if module in seen or module not in mods:
            continue
        seen.add(module)
        path, is_pkg = mods[module]
        parts = module.split(".")
        todo += [".".join(parts[:i]) for i in range(1, len(parts))]  # parent packages
        for node in _module_level_imports(ast.parse(path.read_text(), str(path))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            offences += [f"{module} imports {n}" for n in names if n.split(".")[0] in optional]
            todo += _targets(node, module, is_pkg, mods)
    assert len(seen) > 40
    assert offences == []
