"""NIDAR training data built from rendered scenes: render each scene, a frame per camera.

Layout::

    DATA/meta.json                       splits, wavelength, intensity_scale, render parameters,
                                         and the request (every input) the dataset was built from
    DATA/renders/<scene>/                each scene's render folder (nidar_mi.render_folder): a
                                         cache, reused while the scene's render request holds
    DATA/{train,val,test}/<frame>.npz    one frame per (scene, camera), in the format of
                                         :mod:`nidar_mi.training_frames` (source ``"render"``)

The splits and ``meta.json`` are published together when the whole build succeeded; the renders
are a cache that an interrupted build leaves for the next one (:func:`build_dataset`).

A frame pairs one camera's images with the LiDAR returns it sees: each return is projected with
the camera's calibration, kept when the rendered depth does not hide it, and written to its
nearest pixel (the nearest return wins; :func:`nidar_mi.geometry.camera_returns`). Scenes are
split into train/val/test **by scene** (a seeded permutation of the sorted names), so no layout
is shared across splits.

``python -m nidar_mi.dataset --scenes DIR -o DATA`` runs :func:`build_dataset`
(:mod:`nidar_mi.cli.dataset`).
"""

from __future__ import annotations

import glob
import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import NidarError, check_seed
from .io.ownership import Owner
from .training_frames import R_TRUE_MIN, SPLITS, load_meta, write_frame

__all__ = [
    "OWNER",
    "DatasetOptions",
    "build_dataset",
    "find_scenes",
    "frames_of_render",
    "scene_params",
    "split_scenes",
]

log = logging.getLogger("nidar_mi.dataset")

#: Who writes a dataset folder (:mod:`nidar_mi.io.ownership`): the frames and ``meta.json``,
#: the render cache, the evaluation's default cache, and the staging of an unfinished build.
OWNER = Owner(
    "dataset",
    "scenes",
    names=(
        "meta.json",
        *(f"{s}/*" for s in SPLITS),
        "renders/*",
        "cache/*",
        ".partial-*",
        ".*.old-*",
        ".meta.json.tmp-*",
    ),
    label="dataset --scenes",
    whole=False,
)

# --------------------------------------------------------------------------- scenes and splits


def find_scenes(scene_dir: str) -> list[str]:
    """Scene XML files under ``scene_dir`` (one level of sub-folders), sorted."""
    if not os.path.isdir(scene_dir):
        raise NidarError(f"`scene_dir`: no such directory {scene_dir}")
    files = sorted(
        set(
            glob.glob(os.path.join(scene_dir, "*.xml"))
            + glob.glob(os.path.join(scene_dir, "*", "*.xml"))
        )
    )
    if not files:
        raise NidarError(f"`scene_dir`: no scene XML files in {scene_dir}")
    return files


def scene_params(scene_path: str, params: dict[str, str] | None) -> dict[str, str]:
    """The entries of ``params`` the scene uses (``$name`` in its XML): per-scene defaults.

    Raises:
        NidarError: the file is not readable as UTF-8 text.
    """
    try:
        with open(scene_path, encoding="utf-8") as f:
            text = f.read()
    except (OSError, UnicodeDecodeError) as e:
        raise NidarError(f"{scene_path}: cannot read ({e})") from None
    return {k: v for k, v in (params or {}).items() if f"${k}" in text}


def split_scenes(
    names: list[str], fractions=(0.8, 0.1, 0.1), seed: int = 0
) -> dict[str, list[str]]:
    """Assign whole scenes to splits: a seeded permutation cut by ``fractions``.

    Every split with a positive fraction gets at least one scene when there are enough scenes.
    """
    names = sorted(names)
    f = np.asarray(fractions, dtype=np.float64)
    if f.shape != (3,) or not np.isfinite(f).all() or np.any(f < 0) or f.sum() <= 0:
        raise NidarError(f"`fractions`: three non-negative fractions expected (got {fractions})")
    f = f / f.sum()
    perm = np.random.default_rng(seed).permutation(len(names))
    n = len(names)
    counts = np.floor(f * n).astype(int)
    for i in np.argsort(-(f * n - counts)):  # largest remainders
        if counts.sum() >= n:
            break
        counts[i] += 1
    for i in range(3):  # a positive fraction never yields an empty split if scenes allow
        if f[i] > 0 and counts[i] == 0 and n >= np.count_nonzero(f):
            j = int(np.argmax(counts))
            counts[j] -= 1
            counts[i] += 1
    out, start = {}, 0
    for name, c in zip(SPLITS, counts):
        out[name] = sorted(names[k] for k in perm[start : start + c])
        start += c
    return out


# --------------------------------------------------------------------------- building frames


def frames_of_render(render_dir: str, lidar_id: str | None = None):
    """Yield ``(camera id, frame dict, lidar parameters)`` for every camera of a render folder."""
    from .geometry import camera_returns
    from .render_folder import read_render

    r = read_render(render_dir, lidar_id)
    pts = r.points
    values = {"intensity": r.compensated, "reflectance": pts["reflectance"], "range": pts["range"]}
    for cam in r.cameras:
        visible = camera_returns(pts["xyz"], cam.model, values, depth_image=cam.depth)
        maps, idx = visible.maps, visible.index
        wavelength = r.parameters["wavelength"]
        nir = cam.nir(wavelength)
        frame = {
            "rgb": cam.rgb8(),
            "nir": nir,
            "intensity": maps["intensity"],
            "reflectance": maps["reflectance"],
            "range": maps["range"],
            "mask": visible.mask,
            "depth": cam.depth,
            "K": cam.model.K.astype(np.float64),
            "T_cam_lidar": cam.model.T_cam_lidar.astype(np.float64),
            "points_xyz": pts["xyz"][idx].astype(np.float32),
            "points_intensity": r.compensated[idx].astype(np.float32),
            "points_ring": pts["ring"][idx].astype(np.int16),
        }
        if float(cam.calib.get("nir_wavelength_nm", wavelength)) == float(wavelength):
            # reflectance.exr is at the wavelength of nir.exr (the render's first LiDAR)
            r_true = cam.reflectance()
            with np.errstate(divide="ignore", invalid="ignore"):
                s_true = np.where(r_true >= R_TRUE_MIN, np.pi * nir / r_true, 0.0)
            frame["R_true"], frame["S_true"] = r_true, s_true.astype(np.float32)
            frame["A_true"], frame["R_surface"] = cam.albedo(), cam.surface_reflectance()
        yield cam.name, frame, r.parameters


def _render_request(path: str, params: dict[str, str], seed: int, spp: int):
    """The render of one scene a dataset asks for (the cache key of ``DATA/renders/<scene>``)."""
    from .render_folder import RenderRequest

    return RenderRequest.of(path, params=params, seed=seed, spp=spp, formats=("npz",))


def _read_meta(out_dir: str) -> dict | None:
    """``DATA/meta.json`` when it is readable, else None."""
    try:
        return load_meta(out_dir)
    except NidarError:
        return None


def _published(out_dir: str, meta: dict | None, request: dict, renders: dict) -> bool:
    """Whether ``out_dir`` already holds the dataset of ``request``: same request, every render
    current, every frame file present."""
    from .render_folder import is_current

    if meta is None or meta.get("request") != request:
        return False
    if not all(is_current(os.path.join(out_dir, "renders", n), r) for n, r in renders.items()):
        return False
    return all(
        os.path.isfile(os.path.join(out_dir, split, f"{fid}.npz"))
        for split, fids in meta.get("frames", {}).items()
        for fid in fids
    )


def _check_lidar(path: str, name: str, lidar_id: str) -> None:
    """Refuse, before any render, a ``lidar_id`` that the scene file does not declare (a scene
    with ``<include>`` elements or one that does not parse is left to the render)."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError):
        return
    if any(el.tag == "include" for el in root.iter()):
        return
    ids = sorted(el.get("id", "") for el in root.iter("sensor") if el.get("type") == "lidar")
    if lidar_id not in ids:
        have = ", ".join(ids) if ids else "none"
        raise NidarError(f"`lidar_id` '{lidar_id}': scene {name} has no such lidar (has {have})")


def _withdraw(out_dir: str) -> None:
    """Remove a published dataset (``meta.json`` first, then the splits); the renders stay."""
    import shutil

    meta = Path(out_dir) / "meta.json"
    if meta.is_file():
        meta.unlink()
    for split in SPLITS:
        shutil.rmtree(Path(out_dir) / split, ignore_errors=True)


def _scene_frames(
    scene_path: str, name: str, render_dir: str, frame_dir: str, lidar_id, options: dict
) -> None:
    """One scene's task: render it unless ``render_dir`` holds its render already, then write a
    frame per camera into ``frame_dir`` (the staged split folder)."""
    from .render_session import RenderOptions
    from .simulate import ensure_rendered

    ensure_rendered(RenderOptions(scene_path, **options), render_dir)
    for cam_id, frame, _ in frames_of_render(render_dir, lidar_id):
        write_frame(os.path.join(frame_dir, f"{name}__{cam_id}.npz"), frame)


def _scene_entry(render_dir: str, lidar_id: str | None) -> tuple[list[str], float]:
    """The camera ids of a render folder and the supervising LiDAR's wavelength, nm."""
    from .render_folder import read_manifest

    manifest = read_manifest(render_dir)
    lidars = manifest.get("lidars") or {}
    lid = lidar_id or (min(lidars) if lidars else None)
    if lid not in lidars:
        raise NidarError(f"{render_dir}: no lidar '{lid}' (has {', '.join(sorted(lidars))})")
    return sorted(manifest.get("cameras", {})), lidars[lid]["parameters"]["wavelength"]


def _build_frames(files, names, out_dir, stage, split_of, used, lidar_id, opts, parallel):
    """Run every scene's task (:func:`_scene_frames`) on :mod:`nidar_mi.tasks` (``parallel``:
    its ``workers``, ``address``, ``progress``); the frame ids per split and the wavelength."""
    from .backend import worker_setup
    from .io.atomic import leftovers
    from .tasks import Task, run_tasks

    tasks = []
    for path, name in zip(files, names):
        rdir = os.path.join(out_dir, "renders", name)
        fdir = os.path.join(stage, split_of[name])
        options = dict(opts, params=used[path])
        args = (path, name, rdir, fdir, lidar_id, options)
        tasks.append(Task(name, _scene_frames, args, output=rdir))
    report = run_tasks(
        tasks,
        workers=parallel["workers"],
        address=parallel["address"],
        setup=worker_setup(),
        progress=parallel["progress"],
        desc="dataset",
        unit="scene",
        started=parallel["started"],
    )
    report.raise_on_failure("scenes")
    frames: dict[str, list[str]] = {s: [] for s in SPLITS}
    wavelength = None
    for name in names:
        cameras, wavelength = _scene_entry(os.path.join(out_dir, "renders", name), lidar_id)
        frames[split_of[name]] += [f"{name}__{c}" for c in cameras]
        log.debug("%s: %d frame(s) in %s", name, len(cameras), split_of[name])
    for split in SPLITS:  # what a worker killed while writing a frame left
        for _, path in leftovers(os.path.join(stage, split)):
            path.unlink(missing_ok=True)
    return frames, wavelength


def _remove_leftovers(out_dir: str, names: list[str]) -> None:
    """Drop cached renders of scenes no longer in the dataset."""
    import shutil

    renders = Path(out_dir) / "renders"
    keep = set(names)
    for d in renders.iterdir() if renders.is_dir() else ():
        if d.is_dir() and not d.name.startswith(".") and d.name not in keep:
            shutil.rmtree(d, ignore_errors=True)


def _record(out_dir: str) -> None:
    """The dataset folder's record: what the dataset wrote there, by name."""
    from .io.atomic import write_record
    from .io.ownership import folder_files

    os.makedirs(out_dir, exist_ok=True)
    write_record(out_dir, OWNER, [f for f in folder_files(out_dir) if OWNER.writes(f)])


@dataclass(frozen=True)
class DatasetOptions:
    """How :func:`build_dataset` builds a dataset from rendered scenes.

    Attributes:
        fractions: train/val/test fractions of the scenes.
        seed: split seed, scan seed and sampler seed, in [0, 2**32).
        spp: camera samples per pixel (>= 1).
        params: scene parameters (``-D``); each scene gets those it uses; a name no scene uses
            is an error.
        lidar_id: the LiDAR whose returns supervise (None: the first by id).
        intensity_scale: recorded in ``meta.json`` (training divides intensity by it).
        progress: show a progress bar.
        overwrite: the user passed ``overwrite`` (an unrecorded dataset of nidar_mi 0.1.0, a
            dataset of KITTI frames: :func:`~nidar_mi.io.ownership.check_owner`).
        workers: scenes at once on a local Ray runtime (None: one after the other, in this
            process); see :mod:`nidar_mi.tasks`.
        ray_address: run the scenes on this Ray cluster instead.
    """

    fractions: tuple[float, ...] = (0.8, 0.1, 0.1)
    seed: int = 0
    spp: int = 16
    params: dict[str, str] | None = None
    lidar_id: str | None = None
    intensity_scale: float = 1.0
    progress: bool = True
    overwrite: bool = False
    workers: int | None = None
    ray_address: str | None = None


def build_dataset(scene_dir: str, out_dir: str, **options) -> dict:
    """Render every scene (cached per request) and publish the frames and ``meta.json``.

    ``DATA`` holds a render cache (``renders/``, one complete render folder per scene, reused
    while its request is unchanged) and the published dataset (``meta.json`` and the split
    folders). The dataset is built in a staging folder and published whole at the end
    (``meta.json`` last); a build with other inputs withdraws the published dataset before its
    first render (every check of the inputs, the options and the Ray cluster has passed), so
    a failed or interrupted build never leaves frames that mix two builds, only the completed
    renders for the next run to reuse. A build with the same inputs as the published dataset
    (:data:`meta.json`'s ``request``) does nothing.

    Args:
        scene_dir: folder of scene XML files.
        out_dir: the dataset folder; an earlier dataset of rendered scenes is updated, any
            other folder as :func:`nidar_mi.io.ownership.check_owner` says (a file the dataset
            did not write is never removed: such a folder is refused).
        **options: the fields of :class:`DatasetOptions`.

    Each scene is one task: render (unless cached), then write its frames into the staging
    folder. A scene that fails is reported by name while the others complete; then
    :class:`~nidar_mi.tasks.TasksFailed` is raised and nothing is published (the completed
    renders stay for the next run).

    Returns:
        The meta dict (also written to ``DATA/meta.json``).
    """
    from .io.atomic import check_output_folder

    o = DatasetOptions(**options)
    _check_dataset_options(o)
    scenes = _scene_set(scene_dir, o)
    out_dir = str(
        check_output_folder(
            out_dir, owner=OWNER, overwrite=o.overwrite, inputs=[scene_dir, *scenes.files]
        )
    )
    old = _read_meta(out_dir)
    request = _dataset_request(scenes, o)
    renders = {
        n: _render_request(f, scenes.used[f], o.seed, o.spp)
        for f, n in zip(scenes.files, scenes.names)
    }
    _record(out_dir)  # known as a dataset from here on, interrupted or not
    if _published(out_dir, old, request, renders):
        return old
    out_dir = os.path.abspath(out_dir)
    meta = _publish(out_dir, scenes, o, request, withdraw=old is not None)
    _remove_leftovers(out_dir, scenes.names)
    _record(out_dir)
    return meta


def _check_dataset_options(o: DatasetOptions) -> None:
    """Refuse a bad intensity scale, seed or spp, or workers without Ray (before any work)."""
    from .tasks import check_parallel

    scale = o.intensity_scale
    if not (isinstance(scale, (int, float)) and np.isfinite(scale)):
        raise NidarError(f"`intensity_scale` must be a positive number (got {scale})")
    if not scale > 0:
        raise NidarError(f"`intensity_scale` must be > 0 (got {scale})")
    check_seed(o.seed)
    if o.spp < 1:
        raise NidarError(f"`spp` must be >= 1 (got {o.spp})")
    check_parallel(o.workers, o.ray_address)


@dataclass
class _Scenes:
    """The scenes of a dataset: files (absolute: workers may run elsewhere), names, the
    parameters each uses, the split of the names."""

    files: list[str]
    names: list[str]
    used: dict[str, dict[str, str]]
    splits: dict[str, list[str]]


def _scene_set(scene_dir: str, o: DatasetOptions) -> _Scenes:
    """The scenes of ``scene_dir``, checked: unique names, every ``-D`` parameter used by some
    scene, the LiDAR asked for in every scene."""
    from .scene import read_scene_xml

    files = [os.path.abspath(f) for f in find_scenes(scene_dir)]
    names = [os.path.splitext(os.path.basename(f))[0] for f in files]
    if len(set(names)) != len(names):
        raise NidarError(f"{scene_dir}: scene file names must be unique")
    for path in files:  # every scene file is checked before any is rendered
        read_scene_xml(path)
    used = {path: scene_params(path, o.params) for path in files}
    unused = sorted(set(o.params or {}) - {k for u in used.values() for k in u})
    if unused:
        raise NidarError(f"-D {', '.join(unused)}: no scene in {scene_dir} has such a parameter")
    splits = split_scenes(names, o.fractions, o.seed)
    if o.lidar_id is not None:
        for path, name in zip(files, names):
            _check_lidar(path, name, o.lidar_id)
    return _Scenes(files, names, used, splits)


def _dataset_request(scenes: _Scenes, o: DatasetOptions) -> dict:
    """Every input that decides the dataset (``meta.json``'s ``request``)."""
    from .io.cache_key import file_sha256

    return {
        "scenes": {n: file_sha256(f) for f, n in zip(scenes.files, scenes.names)},
        "params": dict(sorted((o.params or {}).items())),
        "seed": o.seed,
        "spp": o.spp,
        "lidar": o.lidar_id,
        "split": [float(f) for f in o.fractions],
        "intensity_scale": float(o.intensity_scale),
    }


def _publish(out_dir: str, scenes: _Scenes, o: DatasetOptions, request: dict, withdraw: bool):
    """Build the frames of every scene in a staging area and publish them with ``meta.json``
    (last); the published dataset is withdrawn (``withdraw``) only once the tasks can run (a
    Ray cluster answered). The meta dict."""
    from .io.atomic import atomic_write_json, staged_entries

    split_of = {n: s for s, ns in scenes.splits.items() for n in ns}
    opts = dict(formats=("npz",), seed=o.seed, spp=o.spp, progress=False)
    parallel = dict(workers=o.workers, address=o.ray_address, progress=o.progress)
    parallel["started"] = (lambda: _withdraw(out_dir)) if withdraw else None
    with staged_entries(out_dir, [*SPLITS, "meta.json"], last="meta.json") as stage:
        frames, wavelength = _build_frames(
            scenes.files,
            scenes.names,
            out_dir,
            str(stage),
            split_of,
            scenes.used,
            o.lidar_id,
            opts,
            parallel,
        )
        meta = {
            "source": "render",
            "scenes": scenes.splits,
            "frames": frames,
            "wavelength_nm": wavelength,
            "intensity": "range-compensated g·rho·cos(theta)·exp(-2 alpha d)",
            "intensity_scale": float(o.intensity_scale),
            "seed": o.seed,
            "spp": o.spp,
            "params": dict(o.params or {}),
            "request": request,
        }
        atomic_write_json(os.path.join(stage, "meta.json"), meta)
    return meta
