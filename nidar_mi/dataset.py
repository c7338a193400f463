"""NIDAR training data: the frame format, and frames built from rendered scenes.

Layout::

    DATA/meta.json                       splits, wavelength, intensity_scale, render parameters
    DATA/renders/<scene>/                each scene's render folder (nidar_mi.render_folder)
    DATA/{train,val,test}/<frame>.npz    one frame per (scene, camera)

A frame pairs one camera's images with the LiDAR returns it sees: each return is projected with
the camera's calibration, kept when the rendered depth does not hide it, and written to its
nearest pixel (the nearest return wins). Scenes are split into train/val/test **by scene** (a
seeded permutation of the sorted names), so no layout is shared across splits. Training divides
``intensity`` by ``meta.json``'s ``intensity_scale`` and clips it to [0, 1]. Files are read with
``allow_pickle=False``.

``python -m nidar_mi.dataset --scenes DIR -o DATA`` runs :func:`build_dataset`
(:mod:`nidar_mi.cli.dataset`). The keys of a frame (``H x W`` camera pixels), from
:data:`FRAME_KEYS`:

"""

from __future__ import annotations

import glob
import json
import os
import zipfile
from functools import partial
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .errors import NidarError

__all__ = [
    "FRAME_KEYS",
    "SPLITS",
    "build_dataset",
    "find_scenes",
    "frames_of_render",
    "list_frames",
    "load_frame",
    "load_meta",
    "scene_params",
    "split_scenes",
]

SPLITS = ("train", "val", "test")


class FrameKey(NamedTuple):
    """dtype, shape (``None`` = image size) and meaning of one frame key."""

    dtype: type
    shape: tuple
    meaning: str


#: Every key of a frame file.
FRAME_KEYS: dict[str, FrameKey] = {
    "rgb": FrameKey(np.uint8, (None, None, 3), "8-bit sRGB as a camera delivers it (rgb.png)"),
    "nir": FrameKey(np.float32, (None, None), "NIR band radiance at the LiDAR wavelength, linear"),
    "intensity": FrameKey(
        np.float32, (None, None), "sparse range-compensated LiDAR intensity g·ρ·cosθ·exp(-2αd)"
    ),
    "reflectance": FrameKey(np.float32, (None, None), "sparse ρ at the LiDAR wavelength"),
    "range": FrameKey(np.float32, (None, None), "sparse LiDAR range, m"),
    "mask": FrameKey(np.bool_, (None, None), "M: pixels with a projected, unoccluded return"),
    "depth": FrameKey(np.float32, (None, None), "camera z-depth, m, 0 where no surface"),
    "K": FrameKey(np.float64, (3, 3), "OpenCV intrinsics"),
    "T_cam_lidar": FrameKey(np.float64, (4, 4), "LiDAR frame -> camera frame"),
}


def _keys_table() -> str:
    def shape(s):
        return (
            "("
            + ",".join(
                "H" if i == 0 and d is None else "W" if d is None else str(d)
                for i, d in enumerate(s)
            )
            + ")"
        )

    rows = [
        (f"``{k}``", f"{np.dtype(v.dtype).name} {shape(v.shape)}", v.meaning)
        for k, v in FRAME_KEYS.items()
    ]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    rule = "  ".join("=" * w for w in widths)
    body = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    head = "  ".join(c.ljust(w) for c, w in zip(("key", "dtype, shape", "meaning"), widths))
    return "\n".join([rule, head.rstrip(), rule, *body, rule]) + "\n"


__doc__ += _keys_table()


# --------------------------------------------------------------------------- reading frames


def load_meta(data_dir: str | Path) -> dict:
    """Read ``DATA/meta.json``; checks that ``intensity_scale`` is a positive number."""
    path = Path(data_dir) / "meta.json"
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise NidarError(f"{path} not found: not a NIDAR training-data directory") from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise NidarError(f"cannot read {path}: {exc}") from None
    scale = meta.get("intensity_scale") if isinstance(meta, dict) else None
    if not isinstance(scale, (int, float)) or isinstance(scale, bool) or not scale > 0:
        raise NidarError(f"{path}: 'intensity_scale' must be a positive number, got {scale!r}")
    return meta


def list_frames(data_dir: str | Path, split: str) -> list[Path]:
    """Sorted ``DATA/<split>/*.npz`` paths (empty when the split is absent)."""
    if split not in SPLITS:
        raise NidarError(f"unknown split {split!r}; choose one of {', '.join(SPLITS)}")
    return sorted((Path(data_dir) / split).glob("*.npz"))


def load_frame(path: str | Path, keys=tuple(FRAME_KEYS)) -> dict[str, np.ndarray]:
    """Load and check the given keys of one frame file.

    Raises:
        NidarError: missing key, wrong dtype or shape, or an unreadable file.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in keys if k not in npz.files]
            if missing:
                raise NidarError(f"{path}: missing key(s) {', '.join(missing)}")
            arrays = {k: npz[k] for k in keys}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise NidarError(f"cannot read frame {path}: {exc}") from None
    size = None
    for key, arr in arrays.items():
        dtype, shape, _ = FRAME_KEYS[key]
        if arr.dtype != dtype:
            raise NidarError(f"{path}: {key} has dtype {arr.dtype}, expected {np.dtype(dtype)}")
        if len(shape) >= 2 and shape[0] is None:
            hw = arr.shape[:2]
            size = size or hw
            if arr.ndim != len(shape) or hw != size or arr.shape[2:] != shape[2:]:
                raise NidarError(f"{path}: {key} has shape {arr.shape}, image size is {size}")
        elif arr.shape != shape:
            raise NidarError(f"{path}: {key} has shape {arr.shape}, expected {shape}")
    return arrays


# --------------------------------------------------------------------------- scenes and splits


def find_scenes(scene_dir: str) -> list[str]:
    """Scene XML files under ``scene_dir`` (one level of sub-folders), sorted."""
    if not os.path.isdir(scene_dir):
        raise NidarError(f"--scenes: no such directory {scene_dir}")
    files = sorted(
        set(
            glob.glob(os.path.join(scene_dir, "*.xml"))
            + glob.glob(os.path.join(scene_dir, "*", "*.xml"))
        )
    )
    if not files:
        raise NidarError(f"--scenes: no scene XML files in {scene_dir}")
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
    if f.shape != (3,) or np.any(f < 0) or f.sum() <= 0:
        raise NidarError(f"--split: three non-negative fractions expected (got {fractions})")
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
    from .geometry import splat_points
    from .render_folder import read_render

    r = read_render(render_dir, lidar_id)
    pts = r.points
    for cam in r.cameras:
        maps, mask = splat_points(
            pts["xyz"],
            {"intensity": r.compensated, "reflectance": pts["reflectance"], "range": pts["range"]},
            cam.model,
            depth_image=cam.depth,
        )
        frame = {
            "rgb": cam.rgb8(),
            "nir": cam.nir(),
            "intensity": maps["intensity"],
            "reflectance": maps["reflectance"],
            "range": maps["range"],
            "mask": mask,
            "depth": cam.depth,
            "K": cam.model.K.astype(np.float64),
            "T_cam_lidar": cam.model.T_cam_lidar.astype(np.float64),
        }
        yield cam.name, frame, r.parameters


def _write_frame(path: str, frame: dict) -> None:
    from .io.atomic import atomic_path

    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, **frame)


def _frame_current(path: str, rendered_at: float) -> bool:
    """Whether a frame file exists and was written after its render."""
    return os.path.isfile(path) and os.path.getmtime(path) >= rendered_at


def _scene_frames(
    scene_path: str, name: str, render_dir: str, frame_dir: str, lidar_id, options: dict
) -> None:
    """One scene's task: render it (cached) and write a frame per camera into ``frame_dir``."""
    from .simulate import ensure_rendered

    ensure_rendered(scene_path, render_dir, **options)
    rendered_at = os.path.getmtime(os.path.join(render_dir, "manifest.json"))
    for cam_id, frame, _ in frames_of_render(render_dir, lidar_id):
        target = os.path.join(frame_dir, f"{name}__{cam_id}.npz")
        if not _frame_current(target, rendered_at):
            _write_frame(target, frame)


def _scene_done(scene_path: str, name: str, render_dir: str, frame_dir: str, options: dict) -> bool:
    """Skip test of :func:`_scene_frames`: the render is current and so is every frame."""
    from .render_folder import MANIFEST, is_current, read_manifest
    from .simulate import render_request

    if not is_current(render_dir, render_request(scene_path, **options)):
        return False
    rendered_at = os.path.getmtime(os.path.join(render_dir, MANIFEST))
    cameras = read_manifest(render_dir).get("cameras", {})
    return all(
        _frame_current(os.path.join(frame_dir, f"{name}__{c}.npz"), rendered_at) for c in cameras
    )


def _scene_entry(render_dir: str, lidar_id: str | None) -> tuple[list[str], float]:
    """The camera ids of a render folder and the supervising LiDAR's wavelength, nm."""
    from .render_folder import read_manifest

    manifest = read_manifest(render_dir)
    lidars = manifest.get("lidars") or {}
    lid = lidar_id or (min(lidars) if lidars else None)
    if lid not in lidars:
        raise NidarError(f"{render_dir}: no lidar '{lid}' (has {', '.join(sorted(lidars))})")
    return sorted(manifest.get("cameras", {})), lidars[lid]["parameters"]["wavelength"]


def _remove_stale_frames(out_dir: str, frames: dict[str, list[str]]) -> None:
    """Delete frame files an earlier run left in a split they no longer belong to, and the
    temporaries of a writer that was killed."""
    from .io.atomic import leftovers

    for split in SPLITS:
        keep = set(frames[split])
        for path in list_frames(out_dir, split):
            if path.stem not in keep:
                path.unlink()
        for _, path in leftovers(os.path.join(out_dir, split)):
            path.unlink(missing_ok=True)


def build_dataset(
    scene_dir: str,
    out_dir: str,
    *,
    fractions=(0.8, 0.1, 0.1),
    seed: int = 0,
    spp: int = 16,
    params: dict[str, str] | None = None,
    lidar_id: str | None = None,
    intensity_scale: float = 1.0,
    progress: bool = True,
    workers: int | None = None,
    ray_address: str | None = None,
) -> dict:
    """Render every scene (cached per request) and write the frames and ``meta.json``.

    One task per scene (:mod:`nidar_mi.tasks`): render it unless its render folder holds the
    same request, then write the frames older than the render. A scene that fails is reported
    and the others complete; ``meta.json`` is written only when every scene succeeded.

    Args:
        scene_dir: folder of scene XML files.
        out_dir: the dataset folder.
        fractions: train/val/test fractions of the scenes.
        seed: split seed, scan seed and sampler seed.
        spp: camera samples per pixel.
        params: scene parameters (``-D``); each scene gets those it uses; a name no scene uses
            is an error.
        lidar_id: the LiDAR whose returns supervise (None: the first by id).
        intensity_scale: recorded in ``meta.json`` (training divides intensity by it).
        progress: show a progress bar.
        workers: scenes at once on a local Ray runtime (None: one after the other, in this
            process).
        ray_address: run on this Ray cluster instead.

    Returns:
        The meta dict (also written to ``DATA/meta.json``).

    Raises:
        NidarError: bad arguments; :class:`~nidar_mi.tasks.TasksFailed` when scenes failed.
    """
    from .backend import prepare_worker
    from .io.atomic import atomic_write_json
    from .tasks import Task, run_tasks

    if not intensity_scale > 0:
        raise NidarError(f"--intensity-scale must be > 0 (got {intensity_scale})")
    if seed < 0:
        raise NidarError(f"--seed must be >= 0 (got {seed})")
    files = [os.path.abspath(f) for f in find_scenes(scene_dir)]
    names = [os.path.splitext(os.path.basename(f))[0] for f in files]
    if len(set(names)) != len(names):
        raise NidarError(f"{scene_dir}: scene file names must be unique")
    used = {path: scene_params(path, params) for path in files}
    unused = sorted(set(params or {}) - {k for u in used.values() for k in u})
    if unused:
        raise NidarError(f"-D {', '.join(unused)}: no scene in {scene_dir} has such a parameter")
    splits = split_scenes(names, fractions, seed)
    split_of = {n: s for s, ns in splits.items() for n in ns}
    out_dir = os.path.abspath(out_dir)
    tasks = []
    for path, name in zip(files, names):
        rdir = os.path.join(out_dir, "renders", name)
        fdir = os.path.join(out_dir, split_of[name])
        opts = dict(formats=("npz",), seed=seed, spp=spp, params=used[path], progress=False)
        tasks.append(
            Task(
                name,
                _scene_frames,
                (path, name, rdir, fdir, lidar_id, opts),
                output=rdir,
                skip=partial(_scene_done, path, name, rdir, fdir, opts),
            )
        )
    report = run_tasks(
        tasks,
        workers=workers,
        address=ray_address,
        setup=prepare_worker,
        progress=progress,
        desc="dataset",
        unit="scene",
    )
    report.raise_on_failure("scenes")
    frames: dict[str, list[str]] = {s: [] for s in SPLITS}
    wavelength = None
    for name in names:
        cameras, wavelength = _scene_entry(os.path.join(out_dir, "renders", name), lidar_id)
        frames[split_of[name]] += [f"{name}__{c}" for c in cameras]
    _remove_stale_frames(out_dir, frames)
    meta = {
        "scenes": splits,
        "frames": frames,
        "wavelength_nm": wavelength,
        "intensity": "range-compensated g·rho·cos(theta)·exp(-2 alpha d)",
        "intensity_scale": float(intensity_scale),
        "seed": seed,
        "spp": spp,
        "params": dict(params or {}),
    }
    atomic_write_json(os.path.join(out_dir, "meta.json"), meta)
    return meta


if __name__ == "__main__":  # ``python -m nidar_mi.dataset``
    import sys

    from nidar_mi.cli.dataset import main

    sys.exit(main())
