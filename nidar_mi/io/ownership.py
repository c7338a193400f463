"""Who wrote an output folder: the record every command leaves in the folders it writes.

A command that writes a folder leaves :data:`RECORD` (``.nidar_mi-output.json``) in it: the
command, the kind of run (``render``: ``scene`` or ``sequence``; ``dataset``: ``scenes`` or
``kitti``; one kind for the others), the package version and every file it wrote (POSIX paths
relative to the folder; :func:`nidar_mi.io.atomic.write_record` writes it). :func:`check_owner` decides, before any work, whether a command may
write a folder ``OUT``:

=============================================  ===============================================
``OUT``                                        the command
=============================================  ===============================================
missing or empty                               writes it
recorded as its own (same command and kind)    replaces it (or adds to it)
recorded as its own, another kind of run       replaces it only with ``overwrite``
recorded as another command's                  refuses (``overwrite`` or not)
not recorded, every file one the command       replaces it only with ``overwrite`` (nidar_mi
writes by name (:attr:`Owner.names`)           0.1.0 wrote no record; the message says so)
=============================================  ===============================================

A file that neither the record lists nor the command writes by name (a file the user put
there) is never deleted: a command that replaces its folder whole (:attr:`Owner.replaces`)
refuses, naming a few of them and their count, ``overwrite`` or not; one that only adds to its
folder (``scenegen``, ``drive``) leaves them where they are, and writes into a folder of such
files that holds no record of its own only with ``overwrite``. A folder inside another
command's output is refused (:func:`check_not_inside_output`), except where a command writes
its own caches there.
"""

from __future__ import annotations

import fnmatch
import json
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import NidarError

__all__ = [
    "RECORD",
    "Owner",
    "check_not_inside_output",
    "check_owner",
    "folder_files",
    "read_record",
    "record_dict",
]

#: The record's file name, inside the output folder.
RECORD = ".nidar_mi-output.json"
#: The record's schema name.
SCHEMA = "nidar_mi.output/1"
#: How many names a message lists before it gives the count of the rest.
_SHOWN = 3


@dataclass(frozen=True)
class Owner:
    """A command and a kind of run: what may write an output folder, and what it writes.

    Attributes:
        command: the command (``render``, ``assign``, ...).
        kind: the kind of run (``scene``, ``sequence``, ...; the command's name when it has one).
        names: ``fnmatch`` patterns of the relative paths the command writes (``points.*``,
            ``figures/*``): the files of a folder written before records existed, and those a
            command that adds to its folder may find there after an interrupted run.
        replaces: the command replaces its folder whole (else it adds to it).
        listed: a function giving the relative paths an unrecorded earlier output lists in its
            own index (a render's ``manifest.json``), or None.
        whole: the command publishes its folder whole (staged): its record lists every file
            it wrote, and any other file is not its own. A command that writes in place
            (``train``, ``dataset``) may have been stopped before it recorded what it wrote:
            its files by name (:attr:`names`) are its own too.
        label: how messages name the command (default its name, quoted: ``'render'``).
    """

    command: str
    kind: str
    names: tuple[str, ...] = ()
    replaces: bool = True
    listed: Callable[[Path], Iterable[str]] | None = field(default=None, compare=False)
    label: str = ""
    whole: bool = True

    def __str__(self) -> str:
        return f"'{self.label or self.command}'"

    def writes(self, rel: str) -> bool:
        """Whether ``rel`` is a path the command writes by name."""
        return rel == RECORD or any(fnmatch.fnmatchcase(rel, p) for p in self.names)


def folder_files(folder: str | os.PathLike) -> list[str]:
    """Every entry of ``folder`` that is not a folder (files, links, pipes ...), as sorted POSIX
    paths relative to it; folders are walked without following links."""
    root = os.fspath(folder)
    out = []
    stack = [""]
    while stack:
        rel = stack.pop()
        with os.scandir(os.path.join(root, rel)) as it:
            for entry in it:
                path = f"{rel}/{entry.name}" if rel else entry.name
                if entry.is_dir(follow_symlinks=False):
                    stack.append(path)
                else:
                    out.append(path)
    return sorted(out)


def read_record(folder: str | os.PathLike) -> dict | None:
    """The record of ``folder`` (:data:`RECORD`), or None when it has none or an unreadable
    one (then the folder counts as unrecorded)."""
    path = Path(folder) / RECORD
    try:
        with open(path, encoding="utf-8") as f:
            rec = json.load(f)
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if not isinstance(rec, dict) or rec.get("schema") != SCHEMA:
        return None
    if not isinstance(rec.get("command"), str) or not isinstance(rec.get("files"), list):
        return None
    return rec


def record_dict(owner: Owner, files: Iterable[str]) -> dict:
    """The record of a folder ``owner`` wrote with ``files`` (relative paths)."""
    from importlib.metadata import PackageNotFoundError, version

    try:  # the installed distribution's (the package itself sits above this layer)
        release = version("nidar_mi")
    except PackageNotFoundError:
        release = "unknown"
    return {
        "schema": SCHEMA,
        "command": owner.command,
        "kind": owner.kind,
        "version": release,
        "files": sorted(f for f in files if f != RECORD),
    }


def _names(paths: list[str]) -> str:
    shown = ", ".join(paths[:_SHOWN])
    more = len(paths) - _SHOWN
    return shown + (f" and {more} more" if more > 0 else "")


def _recorded_as(rec: dict) -> str:
    kind = rec.get("kind")
    return f"'{rec['command']}'" + (f" ({kind})" if kind and kind != rec["command"] else "")


def _listed(owner: Owner, target: Path) -> set[str]:
    if owner.listed is None:
        return set()
    try:
        return {str(p) for p in owner.listed(target)}
    except (NidarError, OSError, ValueError, TypeError, KeyError, AttributeError):
        return set()  # no index of the command's: nothing there is its own by name


def check_owner(target: Path, owner: Owner, *, overwrite: bool) -> dict | None:
    """Refuse to write the existing folder ``target`` unless ``owner`` may (module docstring).

    Args:
        target: an existing folder (links resolved).
        owner: the command writing it.
        overwrite: the user passed ``overwrite``.

    Returns:
        The folder's record (None: it has none).

    Raises:
        NidarError: one line naming the folder, what holds it and, for files the command did
            not write, a few of them and their count.
    """
    files = folder_files(target)
    rec = read_record(target)
    if not files:
        return rec
    if rec is not None and rec["command"] != owner.command:
        raise NidarError(
            f"{target} is the output of {_recorded_as(rec)}: {owner} does not write into another "
            "command's output; choose another folder"
        )
    listed = set(rec["files"]) if rec is not None else _listed(owner, target)
    # an unrecorded folder is the command's by name only if its own index, when the command
    # writes one, reads as one (a web app's manifest.json is no render's)
    by_name = (rec is None and (owner.listed is None or bool(listed))) or not owner.whole
    foreign = [
        f for f in files if f not in listed and f != RECORD and not (by_name and owner.writes(f))
    ]
    if foreign and (owner.replaces or (rec is None and not overwrite)):
        why = (
            "never deleted: move them or choose another folder"
            if owner.replaces
            else "kept; pass `overwrite` to add to this folder anyway"
        )
        raise NidarError(
            f"{target} holds {len(foreign)} file(s) that {owner} did not write "
            f"({_names(foreign)}): they are {why}"
        )
    if rec is None and owner.replaces and not overwrite:
        raise NidarError(
            f"{target} holds no record of what wrote it (nidar_mi 0.1.0 wrote none); its files "
            f"are those {owner} writes: pass `overwrite` to replace it"
        )
    if rec is not None and rec.get("kind") != owner.kind and not overwrite:
        raise NidarError(
            f"{target} is the output of {_recorded_as(rec)}, another kind of run: pass "
            "`overwrite` to replace it"
        )
    return rec


def check_not_inside_output(target: Path) -> None:
    """Refuse a file or folder inside an output folder of a command (a folder above it holds a
    record).

    Raises:
        NidarError: one line naming the folder above and its command.
    """
    for parent in target.parents:
        rec = read_record(parent)
        if rec is not None:
            raise NidarError(
                f"{target} is inside {parent}, the output of {_recorded_as(rec)}: nothing is "
                "written into another output; choose a place outside it"
            )
