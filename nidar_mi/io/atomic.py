"""Safe file access: atomic writes, and reads that fail with one clear error.

A reader never sees a half-written file: :func:`atomic_path` yields a temporary path in the
target's directory (same file system, so :func:`os.replace` is atomic), with the target's
suffix so that libraries which pick a format from the extension still do the right thing.
On success the temporary file replaces the target; on any exception it is removed and the
target is left untouched.

:func:`reading` is the read-side counterpart used by every reader of :mod:`nidar_mi.io`: it
checks that the file exists and turns any failure to parse it into a one-line
:class:`~nidar_mi.errors.NidarError` naming the file.
"""

from __future__ import annotations

import json
import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import NidarError

__all__ = ["atomic_path", "atomic_write_text", "atomic_write_json", "reading"]


def _remove_quietly(path: Path) -> None:
    try:
        path.unlink()
    except FileNotFoundError:
        pass


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path that replaces ``path`` when the ``with`` block succeeds.

    The parent directories of ``path`` are created. The temporary file is
    ``<dir>/.<name>.tmp-<random><suffix>``, e.g. ``.points.npz.tmp-1f2e3d4c.npz`` for
    ``points.npz``; the caller creates it. If the block raises, the temporary file is
    removed and the exception propagates; the target is not touched.

    Args:
        path: the final file path.

    Yields:
        The temporary path to write to.

    Raises:
        NidarError: the directory cannot be created, or the file cannot be written or
            renamed (any :class:`OSError` in the block or the rename).
    """
    target = Path(path)
    tmp = target.with_name(f".{target.name}.tmp-{secrets.token_hex(4)}{target.suffix}")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise NidarError(f"cannot write {target}: {e.strerror or e}") from None
    try:
        yield tmp
        os.replace(tmp, target)
    except OSError as e:
        _remove_quietly(tmp)
        raise NidarError(f"cannot write {target}: {e.strerror or e}") from None
    except BaseException:
        _remove_quietly(tmp)
        raise


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically (parent directories are created).

    Args:
        path: the file to write.
        text: its whole content.
        encoding: text encoding.
    """
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding=encoding)


def _json_default(obj: Any) -> Any:
    """Make numpy scalars/arrays and paths JSON-serialisable."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def atomic_write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as indented JSON (``indent=2``, trailing newline) atomically.

    numpy scalars and arrays are written as numbers and lists, paths as strings.

    Args:
        path: the file to write.
        obj: a JSON-serialisable object.

    Raises:
        NidarError: ``obj`` holds NaN or infinity (not valid JSON), or the file cannot be
            written.
        TypeError: ``obj`` holds something that is not JSON-serialisable.
    """
    try:
        text = json.dumps(obj, indent=2, allow_nan=False, default=_json_default)
    except ValueError as e:
        raise NidarError(f"cannot write {path}: {e}") from None
    atomic_write_text(path, text + "\n")


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return text or type(e).__name__


@contextmanager
def reading(path: str | os.PathLike) -> Iterator[Path]:
    """Guard the parsing of one input file.

    Args:
        path: the file to read.

    Yields:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        NidarError: ``path`` is not an existing file, or the block raised anything (a
            malformed file makes parsers fail in many ways); the message is one line,
            ``cannot read <path>: <reason>``.
    """
    p = Path(path)
    if not p.is_file():
        raise NidarError(f"cannot read {p}: no such file")
    try:
        yield p
    except NidarError:
        raise
    except Exception as e:
        raise NidarError(f"cannot read {p}: {_one_line(e)}") from e
