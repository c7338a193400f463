"""Draw the package's layers and the imports between its parts as a Mermaid diagram.

    .venv/bin/python scripts/layer_diagram.py            # print the diagram
    .venv/bin/python scripts/layer_diagram.py --write    # replace it in docs/ARCHITECTURE.md
    .venv/bin/python scripts/layer_diagram.py --check    # exit 1 when the docs' one is stale

The graph is the one ``tests/test_imports.py`` checks (every import statement, deferred ones
included, contracted to one node per subpackage and per top-level module), drawn with:

* one box per layer of ``tests/test_imports.LAYERS`` (low, middle, top), bottom to top;
* the ``python -m`` shims and ``__main__`` modules as one node, ``entry points``;
* ``errors`` left out (every part imports it);
* only the edges no other path implies (the transitive reduction: ``a -> c`` is dropped when
  ``a -> b -> c`` exists), so an arrow means "imports directly, and not only through another
  part"; every import is still in the graph.

GitHub renders the Mermaid block of docs/ARCHITECTURE.md (between the ``layers:begin`` and
``layers:end`` comments) as a picture.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "ARCHITECTURE.md"
BEGIN, END = "<!-- layers:begin -->", "<!-- layers:end -->"
ENTRY = "entry_points"
NAMES = {0: "low", 1: "middle", 2: "top"}


def package_edges() -> dict[str, set[str]]:
    """Part -> the parts it imports, parts named below ``nidar_mi`` (entry points as one)."""
    sys.path.insert(0, str(REPO))
    from tests.test_imports import _is_entry_point, import_graph, package_graph

    def name(node: str) -> str:
        return ENTRY if _is_entry_point(node) else node.removeprefix("nidar_mi.")

    edges: dict[str, set[str]] = {}
    for node, deps in package_graph(import_graph()).items():
        if node == "nidar_mi":
            continue  # the package's __init__: the LLVM set-up only
        edges.setdefault(name(node), set()).update(
            name(d) for d in deps if d != "nidar_mi" and d != "nidar_mi.errors"
        )
    edges.pop("errors", None)
    return {k: v - {k} for k, v in edges.items()}


def reduced(edges: dict[str, set[str]]) -> dict[str, set[str]]:
    """The transitive reduction of an acyclic graph."""

    def reach(u: str, skip: str) -> set[str]:
        seen: set[str] = set()
        todo = [w for w in edges[u] if w != skip]
        while todo:
            x = todo.pop()
            if x not in seen:
                seen.add(x)
                todo.extend(edges.get(x, ()))
        return seen

    return {u: {v for v in vs if v not in reach(u, v)} for u, vs in edges.items()}


def mermaid() -> str:
    """The diagram as a fenced Mermaid block."""
    sys.path.insert(0, str(REPO))
    from tests.test_imports import LAYERS

    edges = reduced(package_edges())
    layers: dict[int, list[str]] = {}
    for node in sorted(edges):
        if node != ENTRY:
            layers.setdefault(LAYERS[node.split(".")[0]], []).append(node)
    lines = ["```mermaid", "flowchart BT"]
    for level in sorted(layers, reverse=True):
        lines.append(f'  subgraph {NAMES[level]}["{NAMES[level]} layer"]')
        lines += [f"    {_id(n)}[{n}]" for n in layers[level]]
        lines.append("  end")
    lines.append(f'  {_id(ENTRY)}(["python -m shims, __main__"])')
    for u in sorted(edges):
        lines += [f"  {_id(u)} --> {_id(v)}" for v in sorted(edges[u])]
    lines.append("```")
    return "\n".join(lines)


def _id(node: str) -> str:
    return node.replace(".", "_")


def _with_diagram(text: str, diagram: str) -> str:
    head, sep, rest = text.partition(BEGIN)
    if not sep or END not in rest:
        raise SystemExit(f"{DOC}: no {BEGIN} ... {END} block")
    return f"{head}{BEGIN}\n{diagram}\n{END}{rest.partition(END)[2]}"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--write", action="store_true", help="replace the diagram in the docs")
    mode.add_argument("--check", action="store_true", help="exit 1 when the docs' is stale")
    args = p.parse_args(argv)
    diagram = mermaid()
    if not (args.write or args.check):
        print(diagram)
        return 0
    text = DOC.read_text(encoding="utf-8")
    new = _with_diagram(text, diagram)
    if args.check:
        if new != text:
            print(f"{DOC} is stale: run scripts/layer_diagram.py --write", file=sys.stderr)
            return 1
        return 0
    DOC.write_text(new, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
