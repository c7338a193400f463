"""Generate a run of scenes into a folder: per-scene seeds, resumable writing, the index.

Scene ``k`` of a run with seed ``S`` is named ``scene_<S>_<k>`` and drawn from
``numpy.random.default_rng(SeedSequence(S, spawn_key=(k,)))``: independent streams per scene,
the same scene for the same (S, k) whatever ``--count`` is. Its XML is written atomically to
``DIR/scene_<S>_<k>.xml``; a scene whose file already holds it is skipped, so an interrupted run
resumes; a file holding the scene of another run (another kind) is refused unless ``--overwrite``;
a file edited by hand is kept. ``DIR/index.json`` lists every scene file of the folder (entries
of earlier runs with other seeds are kept), with its seeds, kind, materials, sha256 (of the file
as it is; ``"edited": true`` when it was changed by hand) and rig calibration. A layout that repeats one
already in the folder is an error (it would leak across a split by scene). A ``city`` or ``suburb``
scene also gets its drive (:mod:`.drives`): ``DIR/scene_<S>_<k>_drive.tum`` and the KITTI-style
pose and time files beside it, recorded under ``"drive"`` in its index entry.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from dataclasses import dataclass

import numpy as np

from ..errors import NidarError
from ..io.ownership import Owner
from .city import sample_city
from .layout import KINDS as LAYOUT_KINDS
from .layout import sample_layout
from .lighting import relight
from .objects import material_set
from .primitives import Layout
from .spectral_regimes import draw_spectra
from .streets import CITY_KINDS, DEFAULT_BLOCKS, sample_grid
from .xml import scene_xml

__all__ = [
    "INDEX_NAME",
    "KINDS",
    "MAX_SCENES",
    "OWNER",
    "SCENE_OPTIONS",
    "generate",
    "generate_scene",
    "index_entry",
    "layout_hash",
    "run_bytes",
    "scene_id",
    "scene_rng",
]

log = logging.getLogger("nidar_mi.scenegen")

INDEX_NAME = "index.json"
#: Who writes a scenegen folder (:mod:`nidar_mi.io.ownership`): it adds scenes to it.
OWNER = Owner(
    "scenegen",
    "scenes",
    names=(INDEX_NAME, "scene_*", ".scene_*.tmp-*"),
    replaces=False,
    whole=False,
)
#: Every kind of scene: the street and path layouts (:mod:`.layout`), then cities (:mod:`.city`).
KINDS = LAYOUT_KINDS + CITY_KINDS


def scene_id(seed: int, k: int) -> str:
    """``scene_<seed>_<k>``."""
    return f"scene_{seed}_{k}"


def scene_rng(seed: int, k: int) -> np.random.Generator:
    """The generator of scene ``k`` of the run seeded ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(k,)))


def generate_scene(
    seed: int,
    k: int,
    kind: str | None = None,
    blocks: tuple[int, int] | None = None,
    materials: str = "all",
    lighting: str = "default",
    spectra: str = "library",
) -> tuple[Layout, str]:
    """Layout and XML text of scene ``k`` of run ``seed`` (pure; nothing is written).

    Args:
        seed: run seed (>= 0).
        k: scene index in the run (>= 0).
        kind: one of :data:`KINDS` or None (urban or vegetated, drawn per scene).
        blocks: (nx, ny) blocks of a ``city`` or ``suburb`` layout (None: its default).
        materials: material set (:data:`nidar_mi.scenegen.objects.MATERIAL_SETS`): ``all``,
            ``train`` (no held-out material) or ``heldout`` (held-out materials wherever a part
            has one).
        lighting: lighting regime (:data:`nidar_mi.scenegen.lighting.LIGHTING_REGIMES`):
            ``default`` (the layout's sun and sky) or ``varied`` (redrawn, overcast included).
        spectra: spectral regime (:data:`nidar_mi.scenegen.spectral_regimes.SPECTRA_REGIMES`):
            ``library`` (each material's own spectrum), ``earthlib`` (measured spectra drawn
            per scene for most diffuse, road and paint materials) or ``earthlib-family`` (drawn
            within each material's family).

    Returns:
        The layout and the XML text.
    """
    layout, text, _ = _draw_scene(seed, k, kind, blocks, materials, lighting, spectra)
    return layout, text


def _draw_scene(
    seed: int, k: int, kind, blocks, materials: str, lighting: str, spectra: str
) -> tuple[Layout, str, dict]:
    """:func:`generate_scene` plus the drawn spectra (material name -> ``SurfaceSpectrum``)."""
    with material_set(materials):
        if kind in CITY_KINDS:
            layout = sample_city(scene_rng(seed, k), kind, blocks or DEFAULT_BLOCKS)[0]
        else:
            layout = sample_layout(scene_rng(seed, k), kind)
    layout = relight(layout, seed, k, lighting)
    drawn = draw_spectra(layout.materials(), seed, k, spectra)
    name = scene_id(seed, k)
    text = scene_xml(
        layout,
        name=name,
        description=f"Drawn from SeedSequence({seed}, spawn_key=({k},)); kind {layout.kind}.",
        spectra=drawn,
    )
    return layout, text, drawn


def layout_hash(layout: Layout) -> str:
    """sha256 of everything a layout places (shapes, light, rig), independent of its name."""
    text = repr((layout.shapes, layout.sun, layout.sky, layout.rig))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def index_entry(
    seed: int,
    k: int,
    layout: Layout,
    text: str,
    materials: str = "all",
    lighting: str = "default",
    spectra: dict | None = None,
) -> dict:
    """The ``index.json`` record of one scene (rig matrices as nested lists); ``spectra``: the
    drawn spectra (:func:`draw_spectra`), recorded by their sources."""
    rig = layout.rig
    extra = {} if lighting == "default" else {"lighting": lighting}
    if spectra:
        extra |= {"spectra": {m: s.source for m, s in sorted(spectra.items())}}
    return extra | {
        "material_set": materials,
        "id": scene_id(seed, k),
        "file": f"{scene_id(seed, k)}.xml",
        "seed": seed,
        "index": k,
        "kind": layout.kind,
        "sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
        "layout_sha256": layout_hash(layout),
        "shapes": len(layout.shapes),
        "materials": layout.materials(),
        "lidar": {
            "id": "lidar_top",
            "preset": rig.lidar_preset,
            "T_world_lidar": (np.round(rig.T_world_lidar(), 9) + 0.0).tolist(),
        },
        "camera": {
            "id": "cam_front",
            "fov_deg": rig.camera_fov_deg,
            "fov_axis": "x",
            "T_world_cam": (np.round(rig.T_world_cam(), 9) + 0.0).tolist(),
            "T_cam_lidar": (np.round(rig.T_cam_lidar(), 9) + 0.0).tolist(),
        },
        "sun": {
            "elevation_deg": layout.sun.elevation_deg,
            "azimuth_deg": layout.sun.azimuth_deg,
            "scale": layout.sun.scale,
        },
        "sky": {"scale": layout.sky.scale},
    }


def _read_index(path: str) -> list[dict]:
    if not os.path.exists(path):
        return []
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
        return list(data["scenes"])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise NidarError(f"{path}: not a scene index ({e}); move it away to regenerate") from None


def _file_sha256(path: str) -> str | None:
    """:func:`~nidar_mi.io.cache_key.file_sha256`, or None for a file that cannot be read."""
    from ..io.cache_key import file_sha256

    try:
        return file_sha256(path)
    except OSError:
        return None


#: Scenes one run may have (scene ``k`` of a run is the same whatever ``count`` is: a larger
#: set is several runs, with other seeds, into one folder).
MAX_SCENES = 100_000
#: Estimated bytes of a scene file by kind (measured, rounded up; a city or suburb per block),
#: of its index entry, and of its drive files per frame.
_SCENE_BYTES = {"urban": 256 << 10, "vegetated": 64 << 10, "city": 96 << 10, "suburb": 96 << 10}
_ENTRY_BYTES = 4 << 10
_DRIVE_FRAME_BYTES = 512


def run_bytes(count: int, kind: str | None, blocks, drive: dict | None) -> int:
    """Estimated size of a run of ``count`` scenes (files, drives and index entries), bytes."""
    from .drives import DEFAULT_FRAMES

    per_scene = _SCENE_BYTES[kind or "urban"] + _ENTRY_BYTES
    if kind in CITY_KINDS:
        nx, ny = blocks or DEFAULT_BLOCKS
        per_scene += _SCENE_BYTES[kind] * (nx * ny - 1)
        per_scene += _DRIVE_FRAME_BYTES * int((drive or {}).get("frames", DEFAULT_FRAMES))
    return count * per_scene


def _check_run(out_dir: str, count: int, seed: int, kind, blocks, drive) -> None:
    """Refuse, before anything is written, a bad argument or a run that does not fit on disk."""
    from ..errors import check_seed
    from ..io.sizes import check_disk, format_size

    if count < 1:
        raise NidarError(f"`count` must be >= 1 (got {count})")
    if count > MAX_SCENES:
        raise NidarError(
            f"`count` {count} is more than {MAX_SCENES} scenes, the most one run writes; "
            "write a larger set as several runs with other seeds into one folder"
        )
    check_seed(seed)
    if kind is not None and kind not in KINDS:
        raise NidarError(f"`kind` must be one of {', '.join(KINDS)} (got '{kind}')")
    if os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise NidarError(f"`out_dir`: {out_dir} exists and is not a directory")
    need = run_bytes(count, kind, blocks, drive)
    check_disk(need, out_dir, f"{count} scenes x {format_size(need / count)}")


@dataclass
class _Folder:
    """The folder a run writes into: its index entries and the layouts they place.

    Attributes:
        out_dir: the folder.
        old: scene id -> its entry in ``index.json`` as the run found it.
        entries: scene id -> its entry now (files that are gone dropped, edited ones marked).
        hashes: layout sha256 -> the id of the scene that places it.
    """

    out_dir: str
    old: dict
    entries: dict
    hashes: dict

    @classmethod
    def read(cls, out_dir: str) -> _Folder:
        old = {e["id"]: e for e in _read_index(os.path.join(out_dir, INDEX_NAME))}
        entries = {}  # the index describes the files beside it: gone files drop, edited say so
        for key, e in old.items():
            sha = _file_sha256(os.path.join(out_dir, e.get("file", "")))
            if sha is not None:
                entries[key] = e if sha == e.get("sha256") else e | {"sha256": sha, "edited": True}
        # a layout repeated in the folder would leak across a split by scene
        hashes = {e["layout_sha256"]: e["id"] for e in entries.values() if "layout_sha256" in e}
        return cls(out_dir, old, entries, hashes)

    def _path(self, entry: dict) -> str:
        return os.path.join(self.out_dir, entry.get("file", ""))

    def write_index(self) -> dict:
        """Write ``index.json`` of the entries whose file is there; the index."""
        from ..io.atomic import atomic_write_json

        there = [e for e in self.entries.values() if os.path.isfile(self._path(e))]
        scenes = sorted(there, key=lambda e: (e["seed"], e["index"]))
        index = {"generator": "nidar_mi.scenegen", "scenes": scenes}
        atomic_write_json(os.path.join(self.out_dir, INDEX_NAME), index)
        return index


@dataclass
class _Scene:
    """Scene ``k`` of the run: its index entry, file and what the run does with it
    (``write``, ``skip``: the file holds it; ``keep``: a file edited by hand)."""

    k: int
    entry: dict
    path: str
    action: str
    text: str | None = None  # ``write`` only
    mount: object = None  # a city's or suburb's LiDAR mounting, for its drive


def _plan(folder: _Folder, seed: int, k: int, options: dict, overwrite: bool) -> _Scene:
    """Draw scene ``k`` and decide what to do with its file.

    Raises:
        NidarError: its layout repeats one in the folder, or its file holds the scene of another
            run (without ``overwrite``).
    """
    layout, text, drawn = _draw_scene(
        seed, k, options["kind"], options["blocks"], options["materials"], options["lighting"],
        options["spectra"],
    )  # fmt: skip
    entry = index_entry(seed, k, layout, text, options["materials"], options["lighting"], drawn)
    other = folder.hashes.get(entry["layout_sha256"], entry["id"])
    if other != entry["id"]:
        raise NidarError(f"{entry['id']} repeats the layout of {other}")
    folder.hashes[entry["layout_sha256"]] = entry["id"]
    path = os.path.join(folder.out_dir, entry["file"])
    on_disk = _file_sha256(path) if os.path.exists(path) else None
    mount = layout.rig.T_world_lidar() if layout.kind in CITY_KINDS else None
    if on_disk is None or (on_disk != entry["sha256"] and overwrite):
        return _Scene(k, entry, path, "write", text, mount)
    if on_disk == entry["sha256"]:
        return _Scene(k, entry, path, "skip", mount=mount)
    old = folder.old.get(entry["id"])
    if old is not None and old.get("sha256") == on_disk and not old.get("edited"):
        regime = ", spectra earthlib" if old.get("spectra") else ""
        raise NidarError(
            f"{path} holds scene {k} of another run (kind {old.get('kind')}, materials "
            f"{old.get('material_set', 'all')}{regime}): choose another folder or pass `overwrite`"
        )
    # edited by hand (or of unknown origin): kept, marked edited
    return _Scene(k, (old or entry) | {"sha256": on_disk, "edited": True}, path, "keep")


def _write(folder: _Folder, scene: _Scene, seed: int, options: dict) -> None:
    """Write a scene's drive (a city or suburb), then its file (``write``), and its entry."""
    from ..io.atomic import atomic_write_text

    if scene.mount is not None and scene.action != "keep":
        from .drives import write_drive

        k, kind = scene.k, scene.entry["kind"]
        grid = sample_grid(scene_rng(seed, k), kind, options["blocks"] or DEFAULT_BLOCKS)
        body_seed = int(np.random.SeedSequence(seed, spawn_key=(k,)).generate_state(1)[0])
        scene.entry["drive"] = write_drive(
            folder.out_dir, scene.entry["id"], grid, scene.mount, seed=body_seed,
            **(options["drive"] or {}),
        )  # fmt: skip
    folder.entries[scene.entry["id"]] = scene.entry  # listed once its file is there
    if scene.action == "write":
        atomic_write_text(scene.path, scene.text)


#: How ``-v`` names what happened to a scene.
_ACTION_WORDS = {
    "write": "written",
    "skip": "already there, skipped",
    "keep": "edited by hand, kept",
}


def _publish_index(folder) -> dict:
    """Write the folder's ``index.json`` and its record (:mod:`nidar_mi.io.ownership`)."""
    from ..io.atomic import write_record
    from ..io.ownership import folder_files

    index = folder.write_index()
    write_record(
        folder.out_dir, OWNER, [f for f in folder_files(folder.out_dir) if OWNER.writes(f)]
    )
    return index


#: What every scene of a run is drawn with (:func:`generate`'s scene options), and the defaults.
SCENE_OPTIONS = {
    "kind": None,
    "blocks": None,
    "materials": "all",
    "lighting": "default",
    "spectra": "library",
    "drive": None,
}


def generate(
    out_dir: str,
    count: int,
    seed: int,
    *,
    progress: bool = True,
    overwrite: bool = False,
    nested: bool = False,
    **scene,
) -> dict:
    """Write scenes ``0 .. count-1`` of run ``seed`` into ``out_dir`` (resumable).

    Each scene is written as soon as it is drawn (its drive first, then its file, atomically),
    so an interrupted run leaves complete scenes and an ``index.json`` that lists them. A scene
    whose file already holds exactly this scene is skipped (an interrupted run resumes); a file
    that holds the scene of another run (another ``kind``: its index entry says so) is refused
    unless ``overwrite``, before anything is written; a file edited by hand is kept and its
    entry marked ``"edited": true`` with the file's sha256. ``index.json`` always describes the
    files beside it: entries whose file is gone are dropped.

    Args:
        out_dir: destination folder (created).
        count: number of scenes, 1 .. :data:`MAX_SCENES`.
        seed: run seed (>= 0).
        progress: show a progress bar on stderr.
        overwrite: replace scene files that differ from this run's.
        nested: ``out_dir`` is inside an output of the caller's own (the drive study's scene).
        **scene: what every scene is drawn with (:data:`SCENE_OPTIONS`): ``kind``
            (:data:`KINDS`, None for a mix of urban and vegetated), ``blocks`` ((nx, ny) blocks
            of ``city`` and ``suburb`` layouts, None: the default), ``materials``,
            ``lighting`` and ``spectra`` (the set and regimes of :func:`generate_scene`) and
            ``drive`` (keyword arguments of :func:`.drives.write_drive`: ``frames``,
            ``rate_hz``, ``speed``, for ``city`` and ``suburb`` scenes).

    Returns:
        The index (also written to ``out_dir/index.json``) plus, under ``"run"``, the counts of
        scenes written and skipped.

    Raises:
        NidarError: bad argument, a run estimated larger than the free disk space, an unreadable
            index, a scene file of another run (without ``overwrite``): nothing is written then;
            a new scene that repeats a layout of the folder, or a file that cannot be written:
            the scenes before it are written and indexed.
    """
    from ..io.atomic import check_output_folder
    from ..progress import progress_bar

    unknown = sorted(set(scene) - set(SCENE_OPTIONS))
    if unknown:
        raise TypeError(f"generate() got unknown scene option(s) {', '.join(unknown)}")
    options = SCENE_OPTIONS | scene
    _check_run(out_dir, count, seed, options["kind"], options["blocks"], options["drive"])
    # scenes are added to it: a folder of other files is refused unless `overwrite`
    out_dir = str(check_output_folder(out_dir, owner=OWNER, overwrite=overwrite, nested=nested))
    folder = _Folder.read(out_dir)
    bar = progress_bar(total=count, show=progress, desc="scenegen", unit="scene")
    written = skipped = 0
    try:
        # the files already there first: one of another run is refused before anything is
        # written; those to skip or keep are remembered (without their text)
        there = {}
        for k in range(count):
            if os.path.exists(os.path.join(out_dir, f"{scene_id(seed, k)}.xml")):
                scene = _plan(folder, seed, k, options, overwrite)
                if scene.action != "write":
                    there[k] = scene
                    bar.update(1)
        for k in range(count):
            scene = there.pop(k, None)
            if scene is None:
                scene = _plan(folder, seed, k, options, overwrite)
                bar.update(1)
            _write(folder, scene, seed, options)
            log.debug("%s: %s", scene_id(seed, k), _ACTION_WORDS.get(scene.action, scene.action))
            written += scene.action == "write"
            skipped += scene.action != "write"
    except BaseException:  # interrupted or failed: the index lists the scenes written so far
        if written:
            _publish_index(folder)
        raise
    finally:
        bar.close()
    index = _publish_index(folder)
    return index | {"run": {"seed": seed, "count": count, "written": written, "skipped": skipped}}
