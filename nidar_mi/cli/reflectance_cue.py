"""``python -m nidar_mi.reflectance_cue``: how well image values rank the true LiDAR-wavelength
reflectance on rendered frames, and what the image adds (:mod:`nidar_mi.eval.image_cues`).

    python -m nidar_mi.reflectance_cue --test DATA_TEST [--train DATA_TRAIN]
        [--weights NAME=DIR ...] [--stn FILE] [--no-gain] [--truth-gain KEYS]
        [-o cue.json] [--overwrite] [-q | -v]

Prints one line per cue (Spearman against ρ, per frame and pooled; against ``R_surface`` too
when the frames carry it), per image gain and per truth gain; ``-o`` writes every number as
JSON (NaN, e.g. of a flat value, as null), whole at the end. An existing ``-o`` file is replaced
when it is an earlier output of this command, any other file only with ``--overwrite``.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

from ..errors import NidarError
from ._common import parser, run, show_progress

__all__ = ["build_parser", "main"]

log = logging.getLogger("nidar_mi.reflectance_cue")


def build_parser():
    from ..eval.image_cues import TRUTH_KEYS

    p = parser(
        "reflectance_cue",
        "Score how well image values (luminance, pseudo-NIR, NIDAR's R) rank the true "
        "reflectance at the LiDAR returns of rendered frames, and what the image adds to a "
        "profile of the geometry.",
        verbose="one line per score (the cues, each image gain, each truth gain) with its time",
    )
    p.add_argument("--test", required=True, help="dataset of rendered test frames (every split)")
    p.add_argument("--train", help="dataset whose train split fits the image-gain profile")
    p.add_argument(
        "--weights",
        action="append",
        default=[],
        metavar="NAME=DIR",
        help="NIDAR weights whose R is scored (repeatable)",
    )
    p.add_argument("--stn", help="STN weights whose pseudo-NIR is scored (a .safetensors file)")
    p.add_argument("--no-gain", action="store_true", help="score the cues only")
    p.add_argument(
        "--truth-gain",
        default="",
        metavar="KEYS",
        help="the image gain's ceiling with these truth maps in R's place "
        f"({', '.join(TRUTH_KEYS)}; needs --train)",
    )
    p.add_argument("-o", "--out", help="JSON file of every number")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing -o file that is not an earlier output of this command",
    )
    return p


def _is_earlier_output(path: Path) -> bool:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return False
    return isinstance(data, dict) and {"test_frames", "cue"} <= set(data)


def _check_out(out: str, inputs: list, overwrite: bool) -> str:
    """The JSON file to write (a link's target), refused before any work when it is an input,
    holds one, would replace a file inside an input folder (a dataset's ``meta.json`` or
    frames, a weights file) or a file that is not an earlier output (without ``overwrite``),
    or cannot be written (:func:`nidar_mi.io.atomic.check_output_file`)."""
    from ..io.atomic import check_output_file

    target = Path(out).resolve()
    for item in inputs:
        if item and Path(item).is_dir() and Path(item).resolve() in target.parents:
            raise NidarError(
                f"cannot write `out` {out}: it would replace a file of the input {item}; "
                "choose another path"
            )
    checked = check_output_file(
        out,
        overwrite=overwrite,
        inputs=inputs,
        earlier=_is_earlier_output,
        kind="an earlier reflectance_cue result",
    )
    return str(checked)


def _requests(args) -> list[str]:
    """The truth maps of ``--truth-gain``, checked with the other options."""
    from ..eval.image_cues import TRUTH_KEYS

    truths = [k.strip() for k in args.truth_gain.split(",") if k.strip()]
    bad = [k for k in truths if k not in TRUTH_KEYS]
    if bad:
        raise NidarError(f"`truth_gain`: one or more of {', '.join(TRUTH_KEYS)} (got {bad[0]!r})")
    if truths and (not args.train or args.no_gain):
        raise NidarError(
            "`truth_gain` needs `train` (the frames its profiles are fitted on) and no `no_gain`"
        )
    for spec in args.weights:
        if "=" not in spec or not spec.partition("=")[0].strip():
            raise NidarError(f"`weights` expects NAME=DIR (got '{spec}')")
    return truths


def _score(args, truths: list[str]) -> dict:
    """Every number of the run (module docstring), one step of the progress bar per score
    (the cues, each image gain, each truth gain)."""
    import torch

    from ..eval import image_cues as cue
    from ..nidar.model_io import load_pipeline, load_stn
    from ..progress import progress_bar
    from ..training_frames import load_meta

    torch.set_num_threads(1)
    models = {}
    for spec in args.weights:
        name, _, folder = spec.partition("=")
        stn, irnet, _cfg = load_pipeline(folder, "cpu")
        models[name] = (stn, irnet)
    test = cue.dataset_frames(args.test)
    stn = load_stn(args.stn, "cpu") if args.stn else None
    wavelength = float(load_meta(args.test).get("wavelength_nm") or 905.0)
    gains = bool(args.train) and not args.no_gain
    steps = 1 + (len(models) + len(truths) if gains else 0)
    with progress_bar(total=steps, show=show_progress(args), desc="scores", unit="score") as bar:
        t0 = time.perf_counter()
        cues = cue.score_cues(test, models, stn, wavelength)
        log.debug("cues: %.1f s", time.perf_counter() - t0)
        bar.update(1)
        result: dict = {"test_frames": len(test), "cue": cues}
        if gains:
            train = cue.dataset_frames(args.train, ("train",))
            result["gain"], result["truth_gain"] = {}, {}
            for name, m in models.items():
                t0 = time.perf_counter()
                result["gain"][name] = cue.image_gain(train, test, *m)
                log.debug("image gain of %s: %.1f s", name, time.perf_counter() - t0)
                bar.update(1)
            for key in truths:
                t0 = time.perf_counter()
                result["truth_gain"][key] = cue.truth_gain(train, test, key)
                log.debug("truth gain of %s: %.1f s", key, time.perf_counter() - t0)
                bar.update(1)
    return result


def _table(result: dict) -> str:
    """The lines the command prints."""
    lines = []
    for k, v in result["cue"].items():
        line = f"cue  {k:40s} vs rho: per-frame {v['per_frame']:+.3f}  pooled {v['pooled']:+.3f}"
        if "surface_pooled" in v:
            line += f"  vs R_surface: {v['surface_per_frame']:+.3f} / {v['surface_pooled']:+.3f}"
        lines.append(line)
    for k, v in result.get("gain", {}).items():
        g, i = v["gain"], v["image"]
        lines.append(
            f"gain {k:40s} image {i['per_frame']:+.3f}/{i['pooled']:+.3f}  "
            f"gain {g['per_frame']:+.3f}/{g['pooled']:+.3f}"
        )
    for k, v in result.get("truth_gain", {}).items():
        g, t = v["gain"], v["truth"]
        lines.append(
            f"truth gain {k:34s} truth {t['per_frame']:+.3f}/{t['pooled']:+.3f}  "
            f"gain {g['per_frame']:+.3f}/{g['pooled']:+.3f}"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    """The command (module docstring): 0 on success; a bad request or input is one line on
    stderr and exit 2, Ctrl-C 130, SIGTERM 143, with nothing written (the JSON is written
    whole at the end)."""
    args = build_parser().parse_args(argv)

    def work():
        from ..eval.tables import write_json
        from ..extras import require

        truths = _requests(args)
        require("nidar", "reflectance_cue")
        if args.out:
            inputs = [args.test, args.train, args.stn, *(w.partition("=")[2] for w in args.weights)]
            target = _check_out(args.out, inputs, args.overwrite)
        result = _score(args, truths)
        if not args.quiet:
            print(_table(result))
        if args.out:
            write_json(target, result)  # NaN (a flat value, too few returns) as null

    return run(work, args=args)
