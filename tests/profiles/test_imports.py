"""The profiles package stands apart: it imports neither the networks nor any data."""

from __future__ import annotations

from tests.test_imports import import_graph

#: What ``nidar_mi.profiles`` may not import (docs/ARCHITECTURE.md).
FORBIDDEN = ("nidar", "eval", "datasets", "dataset", "simulate", "sequence", "cli")


def test_profiles_import_no_model_and_no_data():
    graph = import_graph()
    offences = [
        f"{module} imports {dep}"
        for module, deps in graph.items()
        if module.startswith("nidar_mi.profiles")
        for dep in deps
        if dep.split(".")[1:2] and dep.split(".")[1] in FORBIDDEN
    ]
    assert offences == []


def test_inference_imports_no_data_access():
    graph = import_graph()
    assert all(
        not dep.startswith("nidar_mi.datasets.")
        for module, deps in graph.items()
        if module.startswith("nidar_mi.nidar.pipeline")
        for dep in deps
    )
