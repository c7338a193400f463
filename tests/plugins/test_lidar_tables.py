"""The lidar sensor's parameter tables: the README's and the plugin docstring's list the same
parameters, in the same order, with the same defaults, and both match what the sensor reads."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[2] / "README.md"


def _norm(default: str) -> str:
    """A default as text: markup dropped, explanations in parentheses dropped."""
    text = default.replace("``", "").replace("`", "").strip()
    return re.split(r"\s+\(", text)[0].strip()


def _readme_table() -> list[tuple[str, str, str]]:
    text = README.read_text(encoding="utf-8")
    section = text.split("## The `lidar` sensor", 1)[1].split("\n## ", 1)[0]
    lines = section.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| parameter |"))
    table = []
    for line in lines[start:]:  # the first table of the section: the parameters
        if not line.startswith("|"):
            break
        table.append(line)
    rows = []
    for line in table:
        m = re.match(r"^\| `([a-z_0-9]+)`(?:, `([a-z_0-9]+)`)? \| (\w+) \| .* \| (.+) \|$", line)
        if m:
            for name in filter(None, (m.group(1), m.group(2))):
                rows.append((name, m.group(3), _norm(m.group(4))))
    return rows


def _docstring_table(doc: str) -> list[tuple[str, str, str]]:
    body = doc.split(".. list-table::", 1)[1].split(".. code-block::", 1)[0]
    entries = body.split("* - ")[2:]  # [0]: before the table, [1]: the header row
    rows = []
    for entry in entries:
        cells = [c.strip() for c in re.split(r"\n\s+- ", entry.strip())]
        name, kind, default = cells[0], cells[1], cells[-1].split("\n\n")[0]
        rows.append((name.strip("`"), kind, _norm(" ".join(default.split()))))
    return rows


def test_readme_and_docstring_tables_agree(variant):
    from nidar_mi.plugins import plugin_module

    from nidar_mi.lidar.config import PARAMETERS
    from nidar_mi.weather.conditions import PARAMETERS as WEATHER

    doc = plugin_module("lidar", variant).LidarSensor.__doc__
    readme = _readme_table()
    docstring = _docstring_table(doc)
    assert len(readme) >= len(PARAMETERS)
    assert readme == docstring
    assert [n for n, _, _ in readme if n != "to_world"] == [*PARAMETERS, *WEATHER]


def test_defaults_in_the_tables_are_the_resolved_defaults():
    """Every numeric default in the table is what LidarConfig resolves without the parameter."""
    from nidar_mi.lidar.config import LidarConfig

    cfg = LidarConfig.from_mapping("l", {}).to_dict()
    for name, _, default in _readme_table():
        if name in cfg and re.fullmatch(r"-?[0-9.]+", default):
            assert float(cfg[name]) == float(default), name
        elif name in cfg and default in ("true", "false"):
            assert cfg[name] == (default == "true"), name
        elif name in cfg and isinstance(cfg[name], str) and not default.endswith("'s"):
            assert cfg[name] == default, name
