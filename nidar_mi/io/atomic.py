"""Safe file access: atomic writes, and reads that fail with one clear error.

A reader never sees a half-written file: :func:`atomic_path` yields a temporary path in the
target's directory (same file system, so :func:`os.replace` is atomic), with the target's
suffix so that libraries which pick a format from the extension still do the right thing.
On success the temporary file replaces the target; on any exception it is removed and the
target is left untouched.

:func:`staged_directory` does the same for a whole output folder: everything is written into a
hidden sibling folder that takes the target's place only when the ``with`` block succeeds.
:func:`staged_entries` does it for a set of entries inside a folder that also holds other
things (a dataset's splits and ``meta.json`` beside its render cache). The first leaves the
record of what was written (:mod:`nidar_mi.io.ownership`), which decides who may replace a folder later;
both flush everything to the disk before the renames that publish it. A writer killed outright
(SIGKILL, a lost machine) cannot clean up: its staging folder stays, unlocked, and the next run
of the same output removes it and says so (:func:`remove_stale`); :func:`leftovers` finds such
temporaries for a job that resumes.

:func:`reading` is the read-side counterpart used by every reader of :mod:`nidar_mi.io`: it
checks that the file exists and turns any failure to parse it into a one-line
:class:`~nidar_mi.errors.NidarError` naming the file.
"""

from __future__ import annotations

import errno
import fcntl
import json
import logging
import os
import re
import secrets
import shutil
import stat
import tempfile
import warnings
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import NidarError
from .ownership import Owner, check_not_inside_output, check_owner, folder_files, record_dict

__all__ = [
    "atomic_path",
    "check_output_file",
    "check_output_folder",
    "check_outside_inputs",
    "check_writable",
    "file_problem",
    "folder_lock",
    "staged_entries",
    "atomic_write_text",
    "atomic_write_json",
    "leftovers",
    "reading",
    "remove_stale",
    "staged_directory",
    "write_record",
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


def write_record(folder: str | os.PathLike, owner: Owner, files: Iterable[str] | None = None):
    """Write the record of what ``owner`` wrote in ``folder`` (:mod:`nidar_mi.io.ownership`):
    ``files`` (relative paths; default: every file in it now)."""
    from .ownership import RECORD

    listed = folder_files(folder) if files is None else files
    atomic_write_json(Path(folder) / RECORD, record_dict(owner, listed))


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return text or type(e).__name__


def file_problem(path: str | os.PathLike, what: str = "file") -> str | None:
    """Why ``path`` cannot be read as a regular file, in words, or None when it can.

    A named pipe would block a reader for ever and a device such as ``/dev/zero`` never ends,
    so only regular files (or links to one) are read.

    Args:
        path: the path.
        what: what the file should be, for the words (``scene file``).

    Returns:
        e.g. ``no such scene file``, ``a named pipe (FIFO), not a scene file``,
        ``a symbolic link loop``, or None.
    """
    try:
        mode = os.stat(path).st_mode
    except OSError as e:
        if e.errno == errno.ELOOP:
            return "a symbolic link loop"
        if os.path.islink(path):
            return f"a symbolic link to {os.readlink(path)}, which does not exist"
        if e.errno == errno.EACCES:
            return "permission denied"
        return f"no such {what}"
    kinds = (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a named pipe (FIFO)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    )
    for test, kind in kinds:
        if test(mode):
            return f"{kind}, not a {what}"
    return None if stat.S_ISREG(mode) else f"not a regular {what}"


@contextmanager
def reading(path: str | os.PathLike) -> Iterator[Path]:
    """Guard the parsing of one input file.

    Args:
        path: the file to read.

    Yields:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        NidarError: ``path`` is not an existing regular file (:func:`file_problem`), or the
            block raised anything (a malformed file makes parsers fail in many ways); the
            message is one line, ``cannot read <path>: <reason>``.
    """
    p = Path(path)
    problem = file_problem(p)
    if problem:
        raise NidarError(f"cannot read {p}: {problem}")
    try:
        yield p
    except NidarError:
        raise
    except Exception as e:
        raise NidarError(f"cannot read {p}: {_one_line(e)}") from e


def _real(path: str | os.PathLike, what: str = "") -> Path:
    """``path`` with every symbolic link resolved (absolute).

    Raises:
        NidarError: the path runs into a symbolic link loop.
    """
    try:
        os.stat(path)
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise NidarError(f"{what or path}: {path} is a symbolic link loop") from None
    return Path(os.path.realpath(path))


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
        NidarError: ``out`` is, or holds, an input (one line naming both); ``out`` or an input
            is a symbolic link loop.
    """
    target = _real(out, f"cannot write {out}")
    for item in inputs:
        if item is None or not os.fspath(item) or not os.path.lexists(item):
            continue
        path = _real(item, f"cannot read {item}")
        if path == target:
            raise NidarError(f"cannot write {out}: it is the input {item}; choose another output")
        if target in path.parents:
            raise NidarError(
                f"cannot write {out}: it holds the input {item}; choose another output"
            )


def _output_target(out_dir: str | os.PathLike) -> Path:
    """The folder a command writes for ``out_dir``: the path itself, or the folder a symbolic
    link names (the link is kept; its target is written).

    Raises:
        NidarError: an empty path, a symbolic link loop, a link to nothing, a mount point.
    """
    if not os.fspath(out_dir):
        raise NidarError("the output path is empty: name an output folder")
    if os.path.islink(out_dir) and not os.path.exists(out_dir):
        _real(out_dir, f"cannot write {out_dir}")  # a loop is named as one
        raise NidarError(
            f"cannot write {out_dir}: it is a symbolic link to {os.readlink(out_dir)}, which does "
            "not exist; create that folder or choose another output"
        )
    target = _real(out_dir, f"cannot write {out_dir}")
    if target.is_dir() and os.path.ismount(target):
        raise NidarError(
            f"cannot write {out_dir}: it is a mount point, which cannot be replaced whole; "
            "choose a folder inside it"
        )
    return target


def check_output_folder(
    out_dir: str | os.PathLike,
    *,
    owner: Owner,
    overwrite: bool = False,
    inputs: Iterable[str | os.PathLike | None] = (),
    nested: bool = False,
) -> Path:
    """Check, before any work, that ``owner`` can publish its output folder ``out_dir``.

    A symbolic link is written through: the folder it names is checked (and later replaced),
    the link is kept. Who may write an existing folder is :func:`~nidar_mi.io.ownership.check_owner`'s
    rule (the folder's record of what wrote it).

    Args:
        out_dir: the folder.
        owner: the command writing it and the kind of run
            (:class:`~nidar_mi.io.ownership.Owner`).
        overwrite: the user passed ``overwrite`` (:func:`~nidar_mi.io.ownership.check_owner`).
        inputs: the files and folders the command reads; ``out_dir`` must not be or hold one
            (:func:`check_outside_inputs`).
        nested: ``out_dir`` is a cache inside an output of the caller's own; without it a
            folder inside any command's output is refused.

    Returns:
        The folder written, absolute, links resolved.

    Raises:
        NidarError: ``out_dir`` is empty, a symbolic link loop or a link to nothing, a mount
            point, a file, or is or holds an input; it may not be written by ``owner``; it is
            inside another output; or the nearest existing folder above it is not a writable
            folder (checked by creating and removing an empty folder there; one line naming
            the path).
    """
    target = _output_target(out_dir)
    check_outside_inputs(out_dir, inputs)
    if target.exists() and not target.is_dir():
        raise NidarError(f"cannot write {target}: it exists and is not a folder")
    if not nested:
        check_not_inside_output(target)
    if target.is_dir():
        check_owner(target, owner, overwrite=overwrite)
    check_writable(target)
    return target


def check_writable(target: str | os.PathLike) -> None:
    """Check that ``target`` (a file or folder, existing or not) can be created: the nearest
    existing folder above it is a folder where a new entry can be made (checked by creating
    and removing an empty folder there: permission bits do not stop root, a read-only or
    virtual file system does).

    Raises:
        NidarError: one line naming the path.
    """
    target = Path(target).absolute()
    parent = target.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise NidarError(f"cannot write {target}: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise NidarError(f"cannot write {target}: {parent} is not writable")
    try:
        tempfile.TemporaryDirectory(dir=parent, prefix=".nidar_mi-probe-").cleanup()
    except OSError as e:
        raise NidarError(f"cannot write {target}: {e.strerror or e}") from None


def check_output_file(
    path: str | os.PathLike,
    *,
    overwrite: bool = False,
    inputs: Iterable[str | os.PathLike | None] = (),
    earlier: Callable[[Path], bool] | None = None,
    kind: str = "",
) -> Path:
    """Check, before any work, that a command can write the file ``path`` (atomically, with
    :func:`atomic_path`, to the path returned).

    A symbolic link is written through: the file it names is replaced (or made), the link is
    kept.

    Args:
        path: the file.
        overwrite: an existing file may be replaced.
        inputs: the files and folders the command reads (:func:`check_outside_inputs`).
        earlier: tells an earlier output of the same command (replaced without ``overwrite``).
        kind: what such an output is, for the message (``a sensor profile``).

    Returns:
        The file to write, absolute, links resolved.

    Raises:
        NidarError: an empty path, a symbolic link loop, a folder, an existing file that is not
            an earlier output without ``overwrite``, a file inside another command's output
            folder, or a place that cannot be written.
    """
    if not os.fspath(path):
        raise NidarError("the output path is empty: name an output file")
    target = _real(path, f"cannot write {path}")  # a link to nothing yet: its target is made
    check_outside_inputs(path, inputs)
    if target.is_dir():
        raise NidarError(f"cannot write {path}: it is a folder; name a file")
    if target.exists() and not overwrite and not (earlier is not None and earlier(target)):
        what = f" and is not {kind}" if kind else ""
        raise NidarError(f"{path} exists{what}: pass `overwrite` to replace it")
    check_not_inside_output(target)
    check_writable(target)
    return target


# ------------------------------------------------------------------ staging, locks, fsync


def _lock(path: Path) -> int:
    """An open descriptor of the folder ``path`` holding an exclusive ``flock`` (released when
    the descriptor is closed, or the process ends however it ends)."""
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise
    return fd


def _unlock(fd: int | None) -> None:
    if fd is not None:
        os.close(fd)


@contextmanager
def folder_lock(path: str | os.PathLike, what: str = "") -> Iterator[Path]:
    """Hold the folder ``path`` (made if missing) locked against other processes, waiting for
    one that holds it (logged at INFO: what it waits for); released when the block ends or
    the process ends however it ends (``flock``). For shared caches that two runs may build
    at once: the second waits and then finds the first one's work done. Where the file system
    has no ``flock`` the block runs unlocked.

    Raises:
        NidarError: the folder cannot be made.
    """
    folder = Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError as e:
        raise NidarError(f"cannot write {folder}: {e.strerror or e}") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            logging.getLogger("nidar_mi").info(
                "waiting for another process writing %s", what or str(folder)
            )
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:  # no flock here (some network file systems): unlocked
            pass
        yield folder
    finally:
        os.close(fd)


def _tree_bytes(path: Path) -> int:
    total = 0
    for root, _, files in os.walk(path):
        for name in files:
            try:
                total += os.lstat(os.path.join(root, name)).st_size
            except OSError:
                pass
    return total


def remove_stale(path: Path, what: str) -> bool:
    """Remove the staging folder ``path`` a stopped run left, unless a run still holds it.

    A run holds its staging folder locked (``flock``) for its whole life: the lock goes with
    the process however it ends, so a folder nobody holds is stale. One ``warning:`` line says
    what was removed (and its size) or why not.

    Args:
        path: a staging folder (``.<name>.partial-*``, ``.<name>.old-*``, ``.partial-*``).
        what: what it was the staging of, for the message.

    Returns:
        Whether it was removed.
    """
    from .sizes import format_size

    try:
        fd = _lock(path)
    except BlockingIOError:
        warnings.warn(
            f"{path} left in place: a run writing {what} holds it (in progress)", stacklevel=3
        )
        return False
    except OSError:  # gone meanwhile, or not a folder
        return False
    try:
        size = _tree_bytes(path)
        shutil.rmtree(path)
    except OSError as e:
        warnings.warn(f"{path}: cannot remove it ({e.strerror or e})", stacklevel=3)
        return False
    finally:
        _unlock(fd)
    warnings.warn(
        f"removed {path} ({format_size(size)}), the staging of {what} that a stopped run left",
        stacklevel=3,
    )
    return True


def _clear_stale(target: Path) -> None:
    """Remove the staging folders of ``target`` that stopped runs left beside it."""
    for name, path in leftovers(target.parent):
        if name == target.name and path.is_dir() and not path.is_symlink():
            if not path.name.startswith(f".{name}.tmp-"):
                remove_stale(path, str(target))


def _fsync_tree(folder: Path) -> None:
    """Flush every file and folder under ``folder`` (itself included) to the disk."""
    for root, _, files in os.walk(folder):
        for name in files:
            path = os.path.join(root, name)
            if os.path.islink(path):
                continue
            fd = os.open(path, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        _fsync_dir(Path(root))


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    except OSError:  # some file systems cannot flush a folder
        pass
    finally:
        os.close(fd)


def _missing_folders(folder: Path) -> list[Path]:
    """``folder`` and its ancestors that do not exist yet, deepest first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def _remove_empty(folders: list[Path]) -> None:
    """Remove ``folders`` (deepest first) that a failed run created, as long as they are empty."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return


def _new_stage(parent: Path, prefix: str) -> tuple[Path, int]:
    """A new hidden staging folder in ``parent``, world-readable like any output, and the lock
    that marks it in use."""
    parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
    umask = os.umask(0)
    os.umask(umask)
    stage.chmod(0o777 & ~umask)  # mkdtemp makes it private; the result should not be
    return stage, _lock(stage)


@contextmanager
def staged_directory(
    out_dir: str | os.PathLike,
    *,
    owner: Owner,
    overwrite: bool = False,
    inputs: Iterable[str | os.PathLike | None] = (),
    nested: bool = False,
) -> Iterator[Path]:
    """Yield a hidden staging folder that replaces ``out_dir`` whole when the block succeeds.

    The staging folder is ``<parent>/.<name>.partial-<random>`` (same file system, so the final
    renames are atomic), locked for the run's life (``flock``); the staging folders of
    ``out_dir`` that stopped runs left (nobody holds them) are removed first, each with one
    ``warning:`` line (:func:`remove_stale`). On success the record of what was written
    (:func:`~nidar_mi.io.ownership.write_record`) is added, every file and folder is flushed
    to the disk, the previous content of ``out_dir`` (if any) is moved aside and deleted and
    the staging folder is renamed to ``out_dir``: the result never mixes two runs. On any
    exception (Ctrl-C and SIGTERM included) the staging folder is removed and ``out_dir`` is
    left as it was. A symbolic link ``out_dir`` is kept: the folder it names is replaced.

    Args:
        out_dir: the final folder.
        owner: the command and kind of run writing it (:func:`check_output_folder`).
        overwrite: the user passed ``overwrite`` (:func:`~nidar_mi.io.ownership.check_owner`).
        inputs: the files and folders the command reads (:func:`check_outside_inputs`).
        nested: ``out_dir`` is a cache inside an output of the caller's own.

    Yields:
        The staging folder to write into.

    Raises:
        NidarError: :func:`check_output_folder` refuses ``out_dir``, or its parent cannot be
            created or written.
    """
    publish = dict(owner=owner, overwrite=overwrite, inputs=inputs, nested=nested)
    target = check_output_folder(out_dir, **publish)
    _clear_stale(target)
    # the folders made for it go again if the run fails (a cache keeps its caller's)
    made = [] if nested else _missing_folders(target.parent)
    try:
        stage, lock = _new_stage(target.parent, f".{target.name}.partial-")
    except OSError as e:
        _remove_empty(made)
        raise NidarError(f"cannot write {target}: {e.strerror or e}") from None
    old_lock = None
    try:
        yield stage
        write_record(stage, owner)
        _fsync_tree(stage)
        check_output_folder(out_dir, **publish)  # another process may have filled it meanwhile
        old = None
        if target.exists():
            old = target.with_name(f".{target.name}.old-{secrets.token_hex(4)}")
            old_lock = _lock(target)  # a run that finds it knows it is in use
            os.replace(target, old)
        os.replace(stage, target)
        _fsync_dir(target.parent)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except OSError as e:
        shutil.rmtree(stage, ignore_errors=True)
        _remove_empty(made)
        raise NidarError(f"cannot write {target}: {e.strerror or e}") from None
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        _remove_empty(made)
        raise
    finally:
        _unlock(lock)
        _unlock(old_lock)


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
    marked complete. The staging folder (``.partial-*``) is locked for the run's life; those a
    stopped run left are removed first (:func:`remove_stale`), and the entries are flushed to
    the disk before they are put in place. On any exception (Ctrl-C and SIGTERM included) the
    staging folder is removed and ``folder`` is left as it was.

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
    for entry in folder.glob(".partial-*") if folder.is_dir() else ():
        if entry.is_dir() and not entry.is_symlink():
            remove_stale(entry, str(folder))
    try:
        stage, lock = _new_stage(folder, ".partial-")
    except OSError as e:
        raise NidarError(f"cannot write {folder}: {e.strerror or e}") from None
    order = [n for n in names if n != last] + ([last] if last in names else [])
    try:
        yield stage
        _fsync_tree(stage)
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
        _fsync_dir(folder)
        for old in aside:
            if old.is_dir():
                shutil.rmtree(old, ignore_errors=True)
            else:
                _remove_quietly(old)
    except OSError as e:
        raise NidarError(f"cannot write {folder}: {e.strerror or e}") from None
    finally:
        _unlock(lock)
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
