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
import os

import numpy as np

from ..errors import NidarError
from .city import CITY_KINDS, DEFAULT_BLOCKS, sample_city, sample_grid
from .layout import KINDS as LAYOUT_KINDS
from .layout import sample_layout
from .lighting import relight
from .objects import material_set
from .primitives import Layout
from .xml import scene_xml

__all__ = [
    "INDEX_NAME",
    "KINDS",
    "generate",
    "generate_scene",
    "index_entry",
    "layout_hash",
    "scene_id",
    "scene_rng",
]

INDEX_NAME = "index.json"
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
    """
    with material_set(materials):
        if kind in CITY_KINDS:
            layout = sample_city(scene_rng(seed, k), kind, blocks or DEFAULT_BLOCKS)[0]
        else:
            layout = sample_layout(scene_rng(seed, k), kind)
    layout = relight(layout, seed, k, lighting)
    name = scene_id(seed, k)
    text = scene_xml(
        layout,
        name=name,
        description=f"Drawn from SeedSequence({seed}, spawn_key=({k},)); kind {layout.kind}.",
    )
    return layout, text


def layout_hash(layout: Layout) -> str:
    """sha256 of everything a layout places (shapes, light, rig), independent of its name."""
    text = repr((layout.shapes, layout.sun, layout.sky, layout.rig))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def index_entry(
    seed: int, k: int, layout: Layout, text: str, materials: str = "all", lighting: str = "default"
) -> dict:
    """The ``index.json`` record of one scene (rig matrices as nested lists)."""
    rig = layout.rig
    extra = {} if lighting == "default" else {"lighting": lighting}
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
    try:
        with open(path, "rb") as f:
            return hashlib.sha256(f.read()).hexdigest()
    except OSError:
        return None


def generate(
    out_dir: str,
    count: int,
    seed: int,
    *,
    kind: str | None = None,
    progress: bool = True,
    overwrite: bool = False,
    blocks: tuple[int, int] | None = None,
    drive: dict | None = None,
    materials: str = "all",
    lighting: str = "default",
) -> dict:
    """Write scenes ``0 .. count-1`` of run ``seed`` into ``out_dir`` (resumable).

    Every scene is generated before anything is written. A scene whose file already holds
    exactly this scene is skipped (an interrupted run resumes); a file that holds the scene of
    another run (another ``kind``: its index entry says so) is refused unless ``overwrite``;
    a file edited by hand is kept and its entry marked ``"edited": true`` with the file's
    sha256. ``index.json`` always describes the files beside it: entries whose file is gone
    are dropped.

    Args:
        out_dir: destination folder (created).
        count: number of scenes (>= 1).
        seed: run seed (>= 0).
        kind: ``urban``, ``vegetated`` or None for a mix.
        progress: show a progress bar on stderr.
        overwrite: replace scene files that differ from this run's.
        blocks: (nx, ny) blocks of ``city`` and ``suburb`` layouts (None: the default).
        drive: keyword arguments of :func:`.drives.write_drive` (``frames``, ``rate_hz``,
            ``speed``) for ``city`` and ``suburb`` scenes.
        materials: material set of every scene (:func:`generate_scene`).
        lighting: lighting regime of every scene (:func:`generate_scene`).

    Returns:
        The index (also written to ``out_dir/index.json``) plus, under ``"run"``, the counts of
        scenes written and skipped.

    Raises:
        NidarError: bad argument, an unreadable index, a scene file of another run (without
            ``overwrite``), or a file that cannot be written; nothing is written then.
    """
    from ..errors import check_seed
    from ..io.atomic import atomic_write_json, atomic_write_text, check_output_folder
    from ..progress import progress_bar

    if count < 1:
        raise NidarError(f"`count` must be >= 1 (got {count})")
    check_seed(seed)
    if kind is not None and kind not in KINDS:
        raise NidarError(f"`kind` must be one of {', '.join(KINDS)} (got '{kind}')")
    if os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise NidarError(f"`out_dir`: {out_dir} exists and is not a directory")
    check_output_folder(out_dir, overwrite=True)  # a writable place; scenes are added to it
    index_path = os.path.join(out_dir, INDEX_NAME)
    old_entries = {e["id"]: e for e in _read_index(index_path)}
    entries = {}  # the index describes the files beside it: gone files drop, edited ones say so
    for key, e in old_entries.items():
        sha = _file_sha256(os.path.join(out_dir, e.get("file", "")))
        if sha is not None:
            entries[key] = e if sha == e.get("sha256") else e | {"sha256": sha, "edited": True}
    # a layout repeated in the folder would leak across a split by scene
    hashes = {e["layout_sha256"]: e["id"] for e in entries.values() if "layout_sha256" in e}
    todo = []
    drives = []  # (k, layout, entry) of the cities, whose drive files are written with them
    for k in progress_bar(range(count), show=progress, desc="scenegen", unit="scene"):
        layout, text = generate_scene(seed, k, kind, blocks, materials, lighting)
        entry = index_entry(seed, k, layout, text, materials, lighting)
        other = hashes.get(entry["layout_sha256"], entry["id"])
        if other != entry["id"]:
            raise NidarError(f"{entry['id']} repeats the layout of {other}")
        hashes[entry["layout_sha256"]] = entry["id"]
        path = os.path.join(out_dir, entry["file"])
        on_disk = _file_sha256(path) if os.path.exists(path) else None
        action = "write"
        if on_disk == entry["sha256"]:
            action = "skip"
        elif on_disk is not None and not overwrite:
            old = old_entries.get(entry["id"])
            if old is not None and old.get("sha256") == on_disk and not old.get("edited"):
                raise NidarError(
                    f"{path} holds scene {k} of another run (kind {old.get('kind')}, materials "
                    f"{old.get('material_set', 'all')}): choose "
                    "another folder or pass `overwrite`"
                )
            action = "keep"  # edited by hand (or of unknown origin): kept, marked edited
            entry = (old or entry) | {"sha256": on_disk, "edited": True}
        todo.append((path, text, entry, action))
        if layout.kind in CITY_KINDS and action != "keep":
            drives.append((k, layout, entry))
    written = skipped = 0
    for k, layout, entry in drives:
        from .drives import write_drive

        grid = sample_grid(scene_rng(seed, k), layout.kind, blocks or DEFAULT_BLOCKS)
        body_seed = int(np.random.SeedSequence(seed, spawn_key=(k,)).generate_state(1)[0])
        mount = layout.rig.T_world_lidar()
        entry["drive"] = write_drive(
            out_dir, entry["id"], grid, mount, seed=body_seed, **(drive or {})
        )
    for path, text, entry, action in todo:
        if action == "write":
            atomic_write_text(path, text)
            written += 1
        else:
            skipped += 1
        entries[entry["id"]] = entry
    scenes = sorted(entries.values(), key=lambda e: (e["seed"], e["index"]))
    index = {"generator": "nidar_mi.scenegen", "scenes": scenes}
    atomic_write_json(index_path, index)
    return index | {"run": {"seed": seed, "count": count, "written": written, "skipped": skipped}}
