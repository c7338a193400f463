"""``python -m nidar_mi.dataset --scenes DIR -o DATA``: training frames from rendered scenes.

Every scene XML under ``DIR`` (``DIR/*.xml`` and ``DIR/*/*.xml``) is rendered once with
:func:`nidar_mi.render.render_scene` into ``DATA/renders/<scene>/`` (skipped when its manifest
exists, so the command resumes), then every camera becomes one frame
``DATA/<split>/<scene>__<camera>.npz`` with

==============  ===============  =============================================================
key             dtype, shape     meaning
==============  ===============  =============================================================
rgb             uint8 (H,W,3)    8-bit sRGB as a camera delivers it (rgb.png, auto exposure)
nir             float32 (H,W)    NIR band radiance at the LiDAR wavelength (linear)
intensity       float32 (H,W)    sparse range-compensated LiDAR intensity g·ρ·cosθ·exp(-2αd)
reflectance     float32 (H,W)    sparse ρ at the LiDAR wavelength
range           float32 (H,W)    sparse LiDAR range, m
mask            bool (H,W)       M: pixels with a projected, unoccluded return
depth           float32 (H,W)    camera z-depth, m, 0 where no surface
K               float64 (3,3)    OpenCV intrinsics
T_cam_lidar     float64 (4,4)    LiDAR frame -> camera frame
==============  ===============  =============================================================

Scenes are split into train/val/test **by scene** (a seeded permutation of the sorted scene
names), so no layout is shared across splits. ``DATA/meta.json`` records the splits, the
wavelength and ``intensity_scale`` (training divides intensity by it and clips to [0, 1]).
"""

from __future__ import annotations

import argparse
import glob
import os
import sys

import numpy as np

from .errors import NidarError

__all__ = ["main", "build_dataset", "split_scenes", "find_scenes"]

SPLITS = ("train", "val", "test")


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


def _frames_of_scene(render_dir: str, lidar_id: str | None):
    from .geometry import splat_points
    from .rendered import read_render

    r = read_render(render_dir, lidar_id)
    pts = r.points
    for cam in r.cameras:
        maps, mask = splat_points(
            pts["xyz"],
            {"intensity": r.compensated, "reflectance": pts["reflectance"], "range": pts["range"]},
            cam.model,
            depth_image=cam.depth,
        )
        yield (
            cam.name,
            {
                "rgb": cam.rgb8(),
                "nir": cam.nir(),
                "intensity": maps["intensity"],
                "reflectance": maps["reflectance"],
                "range": maps["range"],
                "mask": mask,
                "depth": cam.depth,
                "K": cam.model.K.astype(np.float64),
                "T_cam_lidar": cam.model.T_cam_lidar.astype(np.float64),
            },
            r.parameters,
        )


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
) -> dict:
    """Render every scene (cached) and write the frames and ``meta.json``; returns the meta."""
    from tqdm.auto import tqdm

    from .io.atomic import atomic_path, atomic_write_json
    from .render import render_scene

    if not intensity_scale > 0:
        raise NidarError(f"--intensity-scale must be > 0 (got {intensity_scale})")
    files = find_scenes(scene_dir)
    names = [os.path.splitext(os.path.basename(f))[0] for f in files]
    if len(set(names)) != len(names):
        raise NidarError(f"{scene_dir}: scene file names must be unique")
    splits = split_scenes(names, fractions, seed)
    split_of = {n: s for s, ns in splits.items() for n in ns}
    frames: dict[str, list[str]] = {s: [] for s in SPLITS}
    wavelength = None
    for path, name in tqdm(
        list(zip(files, names)), desc="dataset", unit="scene", disable=not progress
    ):
        rdir = os.path.join(out_dir, "renders", name)
        if not os.path.isfile(os.path.join(rdir, "manifest.json")):
            with open(path, encoding="utf-8") as f:
                text = f.read()
            used = {
                k: v for k, v in (params or {}).items() if f"${k}" in text
            }  # per-scene defaults
            render_scene(
                path, rdir, formats=("npz",), seed=seed, spp=spp, params=used, progress=False
            )
        for cam_id, frame, lparams in _frames_of_scene(rdir, lidar_id):
            wavelength = lparams["wavelength"]
            split = split_of[name]
            fid = f"{name}__{cam_id}"
            target = os.path.join(out_dir, split, fid + ".npz")
            if not os.path.isfile(target):
                os.makedirs(os.path.dirname(target), exist_ok=True)
                with atomic_path(target) as tmp:
                    with open(tmp, "wb") as f:
                        np.savez(f, **frame)
            frames[split].append(fid)
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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m nidar_mi.dataset", description=__doc__.split("\n")[0]
    )
    p.add_argument(
        "--scenes", required=True, help="folder of scene XML files (e.g. from nidar_mi.scenegen)"
    )
    p.add_argument("-o", "--out", required=True, help="dataset folder")
    p.add_argument("--split", default="0.8,0.1,0.1", help="train,val,test fractions of the scenes")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--lidar", default=None, help="lidar id (default: the first by id)")
    p.add_argument("--intensity-scale", type=float, default=1.0)
    p.add_argument("-D", dest="params", action="append", default=[], metavar="NAME=VALUE")
    p.add_argument("-q", "--quiet", action="store_true")
    args = p.parse_args(argv)
    try:
        from .render import _parse_params

        try:
            fractions = tuple(float(x) for x in args.split.split(","))
        except ValueError:
            raise NidarError(f"--split: expected three numbers (got '{args.split}')") from None
        meta = build_dataset(
            args.scenes,
            args.out,
            fractions=fractions,
            seed=args.seed,
            spp=args.spp,
            params=_parse_params(args.params),
            lidar_id=args.lidar,
            intensity_scale=args.intensity_scale,
            progress=not args.quiet,
        )
    except NidarError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if not args.quiet:
        for s in SPLITS:
            print(f"{s:5s}  {len(meta['scenes'][s]):4d} scenes  {len(meta['frames'][s]):5d} frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
