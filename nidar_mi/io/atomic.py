"""Safe file access: atomic writes, and reads that fail with one clear error.

A reader never sees a half-written file: :func:`atomic_path` yields a temporary path in the
target's directory (same file system, so :func:`os.replace` is atomic), with the target's
suffix so that libraries which pick a format from the extension still do the right thing.
On success the temporary file replaces the target; on any exception it is removed and the
target is left untouched.

:func:`staged_directory` does the same for a whole output folder: everything is written into a
hidden sibling folder that takes the target's place only when the ``with`` block succeeds.
:func:`staged_entries` does it for a set of entries inside a folder that also holds other
things (a dataset's splits and ``meta.json`` beside its render cache). A writer killed outright
(SIGKILL, a lost machine) cannot clean up: :func:`leftovers` finds what it left, for a job that
resumes.

:func:`reading` is the read-side counterpart used by every reader of :mod:`nidar_mi.io`: it
checks that the file exists and turns any failure to parse it into a one-line
:class:`~nidar_mi.errors.NidarError` naming the file.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import NidarError

__all__ = [
    "atomic_path",
    "check_output_folder",
    "check_outside_inputs",
    "staged_entries",
    "atomic_write_text",
    "atomic_write_json",
    "leftovers",
    "reading",
    "staged_directory",
]


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


def check_outside_inputs(
    out: str | os.PathLike, inputs: Iterable[str | os.PathLike | None] = ()
) -> None:
    """Refuse an output path that is one of the inputs or holds one (a folder above it).

    Replacing such an output would delete the input, ``overwrite`` or not. Paths are compared
    once symbolic links are resolved; an output inside an input folder is allowed.

    Args:
        out: the output file or folder.
        inputs: the files and folders the command reads (None entries and paths that do not
            exist, e.g. a profile given by name, are ignored: nothing of them can be lost).

    Raises:
        NidarError: ``out`` is, or holds, an input (one line naming both).
    """
    target = Path(out).resolve()
    for item in inputs:
        if item is None or not os.fspath(item) or not os.path.lexists(item):
            continue
        path = Path(item).resolve()
        if path == target:
            raise NidarError(f"cannot write {out}: it is the input {item}; choose another output")
        if target in path.parents:
            raise NidarError(
                f"cannot write {out}: it holds the input {item}; choose another output"
            )


def check_output_folder(
    out_dir: str | os.PathLike,
    *,
    overwrite: bool = False,
    marker: str | None = None,
    inputs: Iterable[str | os.PathLike | None] = (),
) -> Path:
    """Check, before any work, that a command can publish its output folder ``out_dir``.

    Args:
        out_dir: the folder.
        overwrite: a non-empty folder may be replaced.
        marker: name of a file marking an earlier output of the same kind (replaced without
            ``overwrite``); see :func:`staged_directory`.
        inputs: the files and folders the command reads; ``out_dir`` must not be or hold one
            (:func:`check_outside_inputs`).

    Returns:
        ``out_dir`` as an absolute path.

    Raises:
        NidarError: ``out_dir`` is or holds an input; it is a file; it is a non-empty folder
            that is not an earlier output without ``overwrite``; or the nearest existing folder
            above it is not a writable folder (checked by creating and removing an empty folder
            there; one line naming the path).
    """
    check_outside_inputs(out_dir, inputs)
    target = Path(out_dir).absolute()
    if target.exists() and not target.is_dir():
        raise NidarError(f"cannot write {target}: it exists and is not a folder")
    if target.is_dir() and not (overwrite or (marker and (target / marker).is_file())):
        if any(target.iterdir()):
            raise NidarError(f"{target} is not empty: choose another folder or pass `overwrite`")
    parent = target.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise NidarError(f"cannot write {target}: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise NidarError(f"cannot write {target}: {parent} is not writable")
    try:  # a real write: permission bits do not stop root, a read-only or virtual file system does
        tempfile.TemporaryDirectory(dir=parent, prefix=".nidar_mi-probe-").cleanup()
    except OSError as e:
        raise NidarError(f"cannot write {target}: {e.strerror or e}") from None
    return target


@contextmanager
def staged_directory(
    out_dir: str | os.PathLike,
    *,
    overwrite: bool = False,
    marker: str | None = None,
    inputs: Iterable[str | os.PathLike | None] = (),
) -> Iterator[Path]:
    """Yield a hidden staging folder that replaces ``out_dir`` whole when the block succeeds.

    The staging folder is ``<parent>/.<name>.partial-<random>`` (same file system, so the final
    renames are atomic). On success the previous content of ``out_dir`` (if any) is moved aside
    and deleted and the staging folder is renamed to ``out_dir``: the result never mixes two runs.
    On any exception (Ctrl-C and SIGTERM included) the staging folder is removed and ``out_dir``
    is left as it was.

    Args:
        out_dir: the final folder.
        overwrite: allow replacing a non-empty ``out_dir``; without it such a folder is refused
            before anything is written.
        marker: name of a file that marks ``out_dir`` as an earlier output of the same kind
            (e.g. ``manifest.json``); such a folder is replaced without ``overwrite``.
        inputs: the files and folders the command reads (:func:`check_outside_inputs`).

    Yields:
        The staging folder to write into.

    Raises:
        NidarError: ``out_dir`` is or holds an input, is a file, is non-empty without
            ``overwrite``, or its parent cannot be created or written.
    """
    target = check_output_folder(out_dir, overwrite=overwrite, marker=marker, inputs=inputs)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=f".{target.name}.partial-", dir=target.parent))
        umask = os.umask(0)
        os.umask(umask)
        stage.chmod(0o777 & ~umask)  # mkdtemp makes it private; the result should not be
    except OSError as e:
        raise NidarError(f"cannot write {target}: {e.strerror or e}") from None
    try:
        yield stage
        # another process may have filled it meanwhile
        check_output_folder(target, overwrite=overwrite, marker=marker)
        old = None
        if target.exists():
            old = target.with_name(f".{target.name}.old-{secrets.token_hex(4)}")
            os.replace(target, old)
        os.replace(stage, target)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except OSError as e:
        shutil.rmtree(stage, ignore_errors=True)
        raise NidarError(f"cannot write {target}: {e.strerror or e}") from None
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise


@contextmanager
def staged_entries(
    folder: str | os.PathLike, names: list[str], *, last: str | None = None
) -> Iterator[Path]:
    """Yield a hidden staging folder inside ``folder``; its entries ``names`` replace those of
    ``folder`` together when the block succeeds.

    An entry of ``names`` that the block did not create is removed from ``folder`` (the result
    never mixes two runs). ``last`` (one of ``names``, typically the file that marks the set
    complete) is removed from ``folder`` before the other entries are swapped and put in place
    after them, so that even an interruption between the renames never leaves a mixed set
    marked complete. On any exception (Ctrl-C and SIGTERM included) the staging folder is
    removed and ``folder`` is left as it was.

    Args:
        folder: the folder holding the entries (created).
        names: entry names (files or folders) published together.
        last: the entry published last.

    Yields:
        The staging folder to write the entries into.

    Raises:
        NidarError: the folder cannot be created or written.
    """
    folder = Path(folder).absolute()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=".partial-", dir=folder))
    except OSError as e:
        raise NidarError(f"cannot write {folder}: {e.strerror or e}") from None
    order = [n for n in names if n != last] + ([last] if last in names else [])
    try:
        yield stage
        aside = []
        if last is not None and (folder / last).exists():
            old = folder / f".{last}.old-{secrets.token_hex(4)}"
            os.replace(folder / last, old)
            aside.append(old)
        for name in order:
            if (folder / name).exists():
                old = folder / f".{name}.old-{secrets.token_hex(4)}"
                os.replace(folder / name, old)
                aside.append(old)
            if (stage / name).exists():
                os.replace(stage / name, folder / name)
        for old in aside:
            if old.is_dir():
                shutil.rmtree(old, ignore_errors=True)
            else:
                _remove_quietly(old)
    except OSError as e:
        raise NidarError(f"cannot write {folder}: {e.strerror or e}") from None
    finally:
        shutil.rmtree(stage, ignore_errors=True)


#: Hidden names of the temporaries above: ``.<name>.tmp-<hex8><suffix>`` (atomic_path),
#: ``.<name>.partial-<random>`` (the staging folder), ``.<name>.old-<hex8>`` (the replaced folder).
_LEFTOVER = re.compile(
    r"^\.(?P<name>.+)\.(?:tmp-[0-9a-f]{8}.*|partial-[A-Za-z0-9_]+|old-[0-9a-f]{8})$"
)


def leftovers(directory: str | os.PathLike) -> list[tuple[str, Path]]:
    """The temporaries of :func:`atomic_path` and :func:`staged_directory` in ``directory``.

    Only a writer that was killed outright leaves them; removing those of a writer that still
    runs makes it fail, so a caller removes only the leftovers of outputs it alone writes.

    Args:
        directory: the folder to list (missing: none).

    Returns:
        ``(target name, path)`` per leftover, e.g. ``("scene_0001", .../.scene_0001.partial-x1y2)``.
    """
    try:
        entries = list(os.scandir(directory))
    except (FileNotFoundError, NotADirectoryError):
        return []
    out = []
    for entry in entries:
        m = _LEFTOVER.match(entry.name)
        if m:
            out.append((m.group("name"), Path(entry.path)))
    return sorted(out)
