"""``python -m nidar_mi.pseudo_nir``: pseudo-NIR images from colour photos (NIDAR's STN).

    python -m nidar_mi.pseudo_nir INPUT... -o OUT [--exr] [--weights DIR] [--scale S]
                                  [--max-side N] [--recursive] [--skip-bad] [--overwrite] [-q]

Each ``INPUT`` is an image file or a folder (its images: ``.png .jpg .jpeg .bmp .tif .tiff
.webp``; other files in a folder are skipped with one line saying how many; ``--recursive``
descends into sub-folders, except ``OUT`` and earlier outputs of this command). For each image
``OUT/<stem>.png`` is written: the 8-bit pseudo-NIR
at the input's full size and its own exposure (linear pseudo-NIR, sRGB-encoded like the input;
:func:`nidar_mi.nidar.infer.pseudo_nir_linear`), pixel-aligned with the stored pixels (EXIF
orientation is not applied). ``--exr`` adds ``OUT/<stem>.exr``: the linear pseudo-NIR as
float32 (channel ``Y``). ``OUT/index.json`` lists every input with its outputs, the weights and
the inference resolution.

Images whose stems clash (``x/a/0001.png`` and ``x/b/0001.jpg``) are named by the shortest tail
of their folder paths that tells all of them apart, joined with ``__`` (``a__0001``,
``b__0001``); files that differ only by extension get it appended (``0001_png``, ``0001_jpg``).

Bad input follows the package contract: every input is opened before any work (a missing,
unreadable or non-image file, or an image that is not colour, is one ``error:`` line and status
2, nothing written); ``--skip-bad`` skips such files with one ``warning:`` line each instead,
and also a file that fails to decode past its header (a truncated image). ``OUT`` must not be
or hold an input.
The outputs are written to a staging folder that replaces ``OUT`` only when every image
succeeded.
"""

from __future__ import annotations

import logging
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import NidarError
from ..extras import require
from ..io.ownership import Owner
from ._common import out_path, parser, run, show_progress

log = logging.getLogger("nidar_mi.pseudo_nir")

__all__ = ["IMAGE_EXTENSIONS", "build_parser", "collect_inputs", "main", "output_names"]

#: File extensions read as images (case-insensitive).
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
#: The index of an output folder (every input with its outputs).
INDEX = "index.json"


def _indexed(folder: Path) -> list[str]:
    """The files an output folder of nidar_mi 0.1.0 (no record) lists in its index."""
    import json

    with open(folder / INDEX, encoding="utf-8") as f:
        return [INDEX, *(o for e in json.load(f)["images"] for o in e["outputs"])]


#: Who writes a pseudo-NIR output folder (:mod:`nidar_mi.io.ownership`).
OWNER = Owner("pseudo_nir", "images", names=(INDEX,), listed=_indexed)


@dataclass(frozen=True)
class _Input:
    path: Path
    width: int
    height: int


#: Pillow image modes in words, for messages.
_MODE_NAMES = {
    "L": "greyscale",
    "LA": "greyscale+alpha",
    "1": "1-bit",
    "I": "32-bit integer",
    "F": "floating-point",
    "I;16": "16-bit greyscale",
}


def _is_image_name(p: Path) -> bool:
    return p.suffix.lower() in IMAGE_EXTENSIONS


def _probe(path: Path) -> _Input:
    """Open ``path`` as a colour image (header only); one-line NidarError if it is not one."""
    from PIL import UnidentifiedImageError

    from ..io.atomic import file_problem
    from ..io.images import open_image

    problem = file_problem(path)
    if problem:
        raise NidarError(f"{path}: {problem}")
    try:
        with open_image(path) as im:
            mode, (w, h) = im.mode, im.size
    except UnidentifiedImageError:
        raise NidarError(f"{path}: not an image (or a format Pillow cannot read)") from None
    except OSError as e:
        raise NidarError(f"{path}: cannot read ({e.strerror or e})") from None
    if mode not in ("RGB", "RGBA", "P", "CMYK", "YCbCr"):
        raise NidarError(
            f"{path}: a {_MODE_NAMES.get(mode, mode)} image; pseudo-NIR needs a colour image (RGB)"
        )
    if w < 1 or h < 1:
        raise NidarError(f"{path}: empty image")
    return _Input(path, w, h)


def _folder_files(folder: Path, recursive: bool, skip: set[Path]) -> list[Path]:
    """The files of ``folder`` (and of its sub-folders when ``recursive``), sorted; folders in
    ``skip`` (links resolved) and earlier outputs of this command (their record) left out."""
    from ..io.ownership import read_record

    out = []
    for root, dirs, files in os.walk(folder):
        dirs[:] = sorted(
            d
            for d in dirs
            if recursive
            and Path(os.path.realpath(os.path.join(root, d))) not in skip
            and (read_record(Path(root, d)) or {}).get("command") != OWNER.command
        )
        out += [Path(root, f) for f in files if Path(root, f).is_file()]
    return sorted(out)


def collect_inputs(
    inputs: list[str],
    *,
    recursive: bool = False,
    skip_bad: bool = False,
    exclude: list[str] = (),
) -> list[_Input]:
    """Image files named by ``inputs`` (files and folders), each probed, in the given order.

    Folder contents are sorted by path. Non-image files inside folders are skipped (one warning
    per folder with their count); a file given by name must be a readable colour image. A
    recursive walk leaves out the folders ``exclude`` (the output) and every earlier output of
    this command (a folder with its record): a rerun never reads its own images.

    Raises:
        NidarError: a missing input, a bad image (unless ``skip_bad``), or no image at all.
    """
    found: list[_Input] = []
    seen: set[Path] = set()
    skip = {Path(os.path.realpath(e)) for e in exclude}
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            files = _folder_files(p, recursive, skip)
            images = [q for q in files if _is_image_name(q)]
            others = len(files) - len(images)
            if others:
                warnings.warn(f"{p}: skipped {others} file(s) that are not images", stacklevel=2)
        elif p.exists():
            images = [p]
        else:
            raise NidarError(f"{p}: no such file or folder")
        for q in images:
            key = Path(os.path.realpath(q))
            if key in seen:
                continue
            seen.add(key)
            try:
                found.append(_probe(q))
            except NidarError as e:
                if not skip_bad:
                    raise
                warnings.warn(f"skipped {e}", stacklevel=2)
    if not found:
        raise NidarError("no image to convert in " + ", ".join(inputs))
    return found


def output_names(paths: list[Path]) -> list[str]:
    """Unique output stems for input files (module docstring: how clashes are resolved)."""
    folders = [p.resolve().parent.parts for p in paths]
    names = [p.stem for p in paths]
    groups: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        groups.setdefault(n, []).append(i)
    for stem, idx in groups.items():
        if len(idx) == 1:
            continue
        distinct = sorted({folders[i] for i in idx})
        if len(distinct) > 1:
            for k in range(1, max(len(f) for f in distinct) + 1):
                if len({f[-k:] for f in distinct}) == len(distinct):
                    break
            for i in idx:
                names[i] = "__".join(folders[i][-k:] + (stem,)).lstrip("/")
        for i in idx:  # same folder and stem: only the extension differs
            if sum(folders[j] == folders[i] for j in idx) > 1:
                names[i] = f"{names[i]}_{paths[i].suffix.lstrip('.').lower()}"
    counts: dict[str, int] = {}
    for i, n in enumerate(names):  # e.g. 'a.PNG' and 'a.png' on a case-sensitive disk
        counts[n] = counts.get(n, 0) + 1
        if counts[n] > 1:
            names[i] = f"{n}_{counts[n]}"
    return names


def _read_rgb(path: Path, skip_bad: bool = False) -> np.ndarray | None:
    """The image's pixels (H, W, 3) uint8; a file that fails to decode past its header (e.g.
    truncated) is an error, or with ``skip_bad`` a warning and None."""
    from ..io.atomic import reading
    from ..io.images import open_image

    try:
        with reading(path) as p, open_image(p) as im:
            return np.asarray(im.convert("RGB"), dtype=np.uint8)
    except NidarError as e:
        if not skip_bad:
            raise
        warnings.warn(f"skipped {e}", stacklevel=2)
        return None


def _to_png8(nir_linear: np.ndarray) -> np.ndarray:
    from ..io.images import linear_to_srgb

    enc = linear_to_srgb(np.clip(nir_linear, 0.0, 1.0))
    return np.round(enc * 255.0).astype(np.uint8)


def build_parser():
    p = parser(
        "pseudo_nir",
        "Pseudo-NIR images from colour photos with NIDAR's STN.",
        verbose="one per image (its size and inference scale)",
    )
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="image files or folders")
    p.add_argument("-o", "--out", required=True, type=out_path, help="output folder")
    p.add_argument("--exr", action="store_true", help="also write float32 linear EXR")
    p.add_argument("--weights", help="NIDAR weights folder (default: the shipped model)")
    p.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="inference resolution relative to the image, (0, 1] (default 1)",
    )
    p.add_argument(
        "--max-side",
        type=int,
        default=2048,
        help="infer at most at this many pixels on the long side (bounds memory; the output "
        "keeps the full size; default 2048)",
    )
    p.add_argument("-r", "--recursive", action="store_true", help="descend into sub-folders")
    p.add_argument("--skip-bad", action="store_true", help="skip unreadable files with a warning")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an OUT written by nidar_mi 0.1.0 (no record of its files); a file "
        "pseudo_nir did not write is never removed",
    )
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    def work():
        require("nidar", "pseudo_nir")
        _convert(args)

    return run(work, args=args)


def _convert(args) -> None:

    from ..io.atomic import atomic_write_json, check_output_folder, staged_directory
    from ..io.images import write_exr, write_png
    from ..nidar.infer import pseudo_nir_linear, reduced_size
    from ..nidar.pipeline import NidarModel
    from ..progress import progress_bar

    publish = dict(owner=OWNER, overwrite=args.overwrite, inputs=[*args.inputs, args.weights])
    check_output_folder(args.out, **publish)
    reduced_size(1, 1, args.scale)
    if args.max_side < 16:
        raise NidarError(f"--max-side must be >= 16 (got {args.max_side})")
    items = collect_inputs(
        args.inputs, recursive=args.recursive, skip_bad=args.skip_bad, exclude=[args.out]
    )
    names = output_names([it.path for it in items])
    model = NidarModel.load(args.weights)
    if model.stn is None:
        raise NidarError(f"{model.weights_dir}: these weights have no STN (pseudo-NIR network)")
    index = {
        "weights": str(model.weights_dir),
        "output": "8-bit sRGB-encoded linear pseudo-NIR at the input's exposure"
        + ("; float32 linear EXR (channel Y)" if args.exr else ""),
        "images": [],
    }
    with staged_directory(args.out, **publish) as stage:
        bar = progress_bar(items, show=show_progress(args), desc="pseudo-NIR", unit="image")
        for it, name in zip(bar, names):
            rgb = _read_rgb(it.path, args.skip_bad)
            if rgb is None:
                continue
            scale = min(args.scale, args.max_side / max(rgb.shape[:2]))
            log.debug(
                "%s: %dx%d, inferred at scale %.3g", it.path, rgb.shape[1], rgb.shape[0], scale
            )
            nir = pseudo_nir_linear(model.stn, rgb, scale=scale)
            if not np.all(np.isfinite(nir)):
                raise NidarError(f"{it.path}: the network gave non-finite values")
            write_png(os.path.join(stage, f"{name}.png"), _to_png8(nir))
            outputs = [f"{name}.png"]
            if args.exr:
                write_exr(os.path.join(stage, f"{name}.exr"), {"Y": nir})
                outputs.append(f"{name}.exr")
            index["images"].append(
                {
                    "input": str(it.path.resolve()),
                    "outputs": outputs,
                    "size": [rgb.shape[1], rgb.shape[0]],
                    "inference_scale": round(scale, 6),
                }
            )
        if not index["images"]:
            raise NidarError("no image to convert: every input was skipped")
        atomic_write_json(os.path.join(stage, INDEX), index)
    if not args.quiet:
        print(f"wrote {len(index['images'])} pseudo-NIR image(s) to {args.out}")
