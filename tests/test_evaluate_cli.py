"""``python -m nidar_mi.evaluate``: user errors are one line, exit 2, and write nothing."""

from __future__ import annotations

import json

import pytest

from nidar_mi.evaluate import main


def _dataset(root, scenes):
    root.mkdir()
    (root / "meta.json").write_text(json.dumps({"intensity_scale": 1.0, "scenes": scenes}))
    return root


@pytest.mark.parametrize(
    "case, message",
    [
        ("no_data", "meta.json"),
        ("no_test", "has no 'test' scenes"),
        ("not_rendered", "scene b is not rendered"),
    ],
)
def test_user_errors(tmp_path, capsys, case, message):
    data = tmp_path / "data"
    if case == "no_test":
        _dataset(data, {"train": ["a"], "test": []})
    elif case == "not_rendered":
        _dataset(data, {"train": ["a"], "test": ["b"]})
    out = tmp_path / "out"
    assert main(["--data", str(data), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err
    assert not out.exists()
