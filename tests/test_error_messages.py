"""Library errors name parameters, not command-line flags: a message writes a parameter in
backticks and the command shows its flag (:func:`nidar_mi.errors.flag_message`)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

#: Modules whose messages still name flags (their parameters move to request objects).
_NOT_YET: set[str] = set()
#: Messages that name another command to run, with its flags.
_COMMAND_HINTS = ("--profile FILE", "calibrate --branch")


def _flag_messages(path: Path) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(node, ast.Call):
            continue
        name = getattr(node.func, "id", getattr(node.func, "attr", None))
        text = ast.unparse(node)
        if name == "NidarError" and re.search(r"(?<![\w-])--[a-z]", text):
            if not any(h in text for h in _COMMAND_HINTS):
                found.append(f"{path.relative_to(REPO)}:{node.lineno}")
    return found


def test_library_errors_name_parameters_not_flags():
    offences = []
    for root in (REPO / "nidar_mi", REPO / "plugins"):
        for path in sorted(root.rglob("*.py")):
            rel = path.relative_to(root).parts
            if rel[0] == "cli" or path.name in _NOT_YET and len(rel) == 1:
                continue
            offences += _flag_messages(path)
    assert offences == []
