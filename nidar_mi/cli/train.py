"""Command line: train the NIDAR networks.

    python -m nidar_mi.train DATA OUT [--config cfg.json] [--reduced] [--stage all|stn|irnet]
                             [--variant unet+deeplabv3] [--input pseudo_nir|rgb]
                             [--stn-weights stn.safetensors] [--resume] [--seed N]
                             [--device auto|cpu|cuda] [--epochs N] [--max-steps N]
                             [--batch-size N] [--crop-size N] [--crop-width N]
                             [--scale S] [--threads N] [--all-frames] [--init-irnet W]
                             [--renders DATA] [--progress | --no-progress] [-q | -v]
                             [--overwrite]

Writes ``OUT/stn.safetensors``, ``OUT/irnet.safetensors``, ``OUT/config.json``,
``OUT/train_log.json``, resumable checkpoints under ``OUT/checkpoints`` and, once IRNet is
trained, ``OUT/calibration.json``: the distance encoding and quantile map fitted on the training
split (:func:`nidar_mi.datasets.profile_fitting.fit_split_calibration`; ``--no-calibration`` skips it). Options given on
the command line override the configuration file (``--epochs``, ``--max-steps`` and
``--batch-size`` apply to both stages). ``--all-frames`` (with ``--stage irnet``) trains
IRNet on every frame of DATA, for a model to ship. See :mod:`nidar_mi.nidar.training`.

An OUT where a stage of this command has trained already is refused unless ``--resume``
(continue that run) or ``--overwrite`` (replace it: the earlier folder is moved aside, put back
when the new run fails before its first checkpoint, removed otherwise). OUT must not hold an
input (DATA, ``--config``, ``--stn-weights``, ...), nor a file ``train`` did not write (it is
never removed; :mod:`nidar_mi.io.ownership`).

A compact IRNet on real KITTI frames (quarter resolution, wide crops, one thread)::

    python -m nidar_mi.train DATA OUT --stage irnet --stn-weights stn.safetensors \
        --config irnet_kitti.json --all-frames --threads 1
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
from pathlib import Path

from ..errors import NidarError
from ..extras import require
from ..io.ownership import Owner
from ._common import out_path, parser, run, seed_arg, show_progress

#: Who writes a training run's folder (:mod:`nidar_mi.io.ownership`): weights, logs,
#: checkpoints and the frames' cache.
OWNER = Owner(
    "train",
    "weights",
    names=(
        "config.json",
        "train_log.json",
        "calibration.json",
        "*.safetensors",
        "checkpoints/*",
        "cache/*",
        "profiles/*",
        "*.tmp-*",
    ),
    whole=False,
)

__all__ = ["main", "build_config"]


def _parser() -> argparse.ArgumentParser:
    p = parser(
        "train",
        "Train the NIDAR networks (STN, then IRNet) on a dataset from nidar_mi.dataset; "
        "resumable (--resume); a run that fails before its first checkpoint leaves nothing.",
        verbose="one per epoch (losses, time)",
    )
    p.add_argument("data", type=Path, help="training-data directory (meta.json, train/, val/)")
    p.add_argument(
        "out",
        type=lambda text: Path(out_path(text)),
        help="output directory for weights, logs, checkpoints",
    )
    p.add_argument("--config", type=Path, help="JSON file with a TrainConfig (nested dict)")
    p.add_argument("--reduced", action="store_true", help="start from the tiny test config")
    p.add_argument(
        "--stage",
        choices=("all", "stn", "irnet"),
        default="all",
        help="train both networks (default), the STN only, or IRNet only",
    )
    p.add_argument("--variant", help="IRNet variant, e.g. unet+deeplabv3, deeplabv3+3conv")
    p.add_argument(
        "--input",
        choices=("pseudo_nir", "rgb", "rgb+pseudo_nir", "chroma+pseudo_nir"),
        help="IRNet input",
    )
    p.add_argument("--stn-weights", type=Path, help="use this trained STN (skips the STN stage)")
    p.add_argument(
        "--photos",
        type=Path,
        help="train the STN on the real RGB/NIR photo pairs of this folder (e.g. "
        "../shared/data/rgbnir; its train and val pairs) instead of the dataset's renders",
    )
    p.add_argument(
        "--init-irnet",
        type=Path,
        help="start IRNet from these weights (same network configuration), e.g. pretrained on "
        "renders with loss.lambda_r_true / lambda_s_true, then fine-tuned on real frames",
    )
    p.add_argument(
        "--renders",
        type=Path,
        metavar="DATA",
        help="mix the train frames of this rendered dataset into IRNet's crops to supervise R and "
        "S with their true maps (loss.lambda_r_true / lambda_s_true; their intensity is left out)",
    )
    p.add_argument("--resume", action="store_true", help="continue from the latest checkpoint")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier run in OUT; it is removed only once this run has saved its "
        "first checkpoint (a file train did not write is never removed: such an OUT is refused)",
    )
    p.add_argument(
        "--no-calibration", action="store_true", help="do not fit calibration.json after training"
    )
    p.add_argument(
        "--seed", type=seed_arg, help="seed of initialisation, batches and crops, 0 .. 2**32-1"
    )
    p.add_argument("--device", help="auto (default), cpu, cuda or cuda:N")
    p.add_argument("--epochs", type=int, help="epochs of each stage, >= 1")
    p.add_argument("--max-steps", type=int, help="optimiser steps of each stage at most, >= 1")
    p.add_argument("--batch-size", type=int, help="batch size of each stage")
    p.add_argument(
        "--crop-size", type=int, help="side of the square training crops, or their height (px)"
    )
    p.add_argument("--crop-width", type=int, help="width of the training crops (px)")
    p.add_argument(
        "--scale",
        type=float,
        help="IRNet resolution relative to the frames, in (0, 1] (also the model's default "
        "inference scale)",
    )
    p.add_argument(
        "--threads", type=int, help="torch threads while training (1 is fastest on a busy machine)"
    )
    p.add_argument(
        "--all-frames",
        action="store_true",
        help="train IRNet on every frame of DATA (train, val and test splits), without "
        "validation: the model to ship once the held-out evaluation is done",
    )
    return p


def build_config(args: argparse.Namespace):
    """The :class:`~nidar_mi.nidar.config.TrainConfig` selected by parsed arguments."""
    from ..nidar.config import TrainConfig

    for flag, value in (("--init-irnet", args.init_irnet), ("--renders", args.renders)):
        if value is not None and args.stage != "irnet":
            raise NidarError(f"{flag} applies to IRNet only: use it with --stage irnet")
    if args.all_frames and args.stage != "irnet":
        raise NidarError("--all-frames applies to IRNet only: use it with --stage irnet")
    cfg = TrainConfig.reduced() if args.reduced else TrainConfig()
    if args.config is not None:
        try:
            data = json.loads(args.config.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise NidarError(f"cannot read {args.config}: {exc}") from None
        try:
            cfg = TrainConfig.from_dict(data, base=cfg)
        except NidarError as exc:
            raise NidarError(f"{args.config}: {exc}") from None
    irnet = {}
    if args.variant is not None:
        irnet["variant"] = args.variant.strip().lower().replace("-", "")
    if args.input is not None:
        irnet["input"] = args.input
    optim = {
        k: v
        for k, v in (
            ("epochs", args.epochs),
            ("max_steps", args.max_steps),
            ("batch_size", args.batch_size),
        )
        if v is not None
    }
    top = {
        k: v
        for k, v in (
            ("seed", args.seed),
            ("device", args.device),
            ("crop_size", args.crop_size),
            ("crop_width", args.crop_width),
            ("scale", args.scale),
            ("threads", args.threads),
        )
        if v is not None
    }
    cfg = TrainConfig.from_dict(
        {"irnet": irnet, "stn_optim": optim, "irnet_optim": optim, **top}, base=cfg
    )  # checks every value, the flags' too
    return cfg


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (2 on a user error)."""
    args = _parser().parse_args(argv)

    left = {"text": "nothing written"}

    def work():
        from ..io.atomic import check_output_folder, write_record

        require("nidar", "train")
        cfg = build_config(args)
        if args.overwrite and args.resume:
            raise NidarError("--overwrite replaces the run that --resume continues: give one")
        inputs = [args.data, args.config, args.stn_weights, args.photos, args.init_irnet]
        # a link is written through: the folder it names is trained into, the link kept
        out = args.out = check_output_folder(
            args.out,
            owner=OWNER,
            overwrite=args.overwrite or args.resume,
            inputs=[*inputs, args.renders],
        )
        if not (args.resume or args.overwrite):
            _check_no_earlier_run(out, _stages(args))
        aside = _move_aside(out) if args.overwrite else None
        fresh = not out.exists() or (out.is_dir() and not any(out.iterdir()))
        try:
            out.mkdir(parents=True, exist_ok=True)
            write_record(out, OWNER)  # an interrupted run is known as this command's
            _train(args, cfg)
            write_record(out, OWNER)
        except BaseException:
            left["text"] = _after_failure(out, fresh, aside)
            raise
        if aside is not None:
            shutil.rmtree(aside, ignore_errors=True)
        logging.getLogger(__name__).info("weights written to %s", out)

    return run(
        work, on_interrupt=lambda: left["text"], flags={"render_frames": "--renders"}, args=args
    )


def _photos(folder, progress: bool):
    from ..datasets.rgbnir import stn_training_pairs

    return stn_training_pairs(folder, progress=progress)


def _train(args: argparse.Namespace, cfg) -> None:
    from ..nidar import training

    progress = show_progress(args)
    if args.stage == "stn" and args.photos is not None:
        training.train_stn_photos(
            cfg,
            _photos(args.photos, progress),
            args.data,
            args.out,
            resume=args.resume,
            progress=progress,
        )
    elif args.stage == "stn":
        training.train_stn(cfg, args.data, args.out, resume=args.resume, progress=progress)
    elif args.stage == "irnet":
        training.train_irnet(
            cfg,
            args.data,
            args.out,
            args.stn_weights,
            resume=args.resume,
            progress=progress,
            frames=_all_frames(args.data) if args.all_frames else None,
            init_weights=args.init_irnet,
            render_frames=_render_frames(args.renders) if args.renders is not None else None,
        )
    else:
        training.train(
            cfg,
            args.data,
            args.out,
            stn_weights=args.stn_weights,
            resume=args.resume,
            progress=progress,
            photos=(
                _photos(args.photos, progress)
                if args.photos is not None
                and args.stn_weights is None
                and cfg.irnet.input == "pseudo_nir"
                else None
            ),
        )
    if args.stage != "stn" and not args.no_calibration:
        from ..datasets.profile_fitting import fit_split_calibration
        from ..nidar.pipeline import NidarModel

        model = NidarModel.load(args.out, device=cfg.device)
        fit_split_calibration(model, args.data, "train").mapping.save_json(
            args.out / "calibration.json"
        )


def _render_frames(data: Path) -> list[Path]:
    from ..training_frames import list_frames

    frames = list_frames(data, "train")
    if not frames:
        raise NidarError(f"--renders: no frames in {data / 'train'}")
    return frames


def _all_frames(data: Path) -> dict[str, list[Path]]:
    from ..training_frames import SPLITS, list_frames

    return {"train": [f for split in SPLITS for f in list_frames(data, split)], "val": []}


def _stages(args: argparse.Namespace) -> tuple[str, ...]:
    """The stages this command trains."""
    if args.stage != "all":
        return (args.stage,)
    return ("irnet",) if args.stn_weights is not None else ("stn", "irnet")


def _check_no_earlier_run(out: Path, stages: tuple[str, ...]) -> None:
    """Refuse an OUT where a stage this command trains has made progress already."""
    from ..nidar.loop import read_train_log

    if not (out / "config.json").is_file():
        return
    done = [s for s in stages if read_train_log(out).get(s, {}).get("steps")]
    if done:
        raise NidarError(
            f"{out} holds an earlier {done[0]} run: pass --resume to continue it or --overwrite "
            "to replace it (or choose another folder)"
        )


def _move_aside(out: Path) -> Path | None:
    """``--overwrite``: move an existing OUT to a hidden sibling (restored if this run fails
    before its first checkpoint, removed once it succeeds)."""
    import secrets

    if not out.exists():
        return None
    aside = out.with_name(f".{out.name}.old-{secrets.token_hex(4)}")
    out.rename(aside)
    return aside


def _after_failure(out: Path, fresh: bool, aside: Path | None = None) -> str:
    """Clean up after a failed or interrupted run; says what is left.

    A run that started in a new (or empty) folder and saved no checkpoint leaves nothing; one
    that saved checkpoints keeps them for ``--resume``; an existing run's folder is left as
    it is. With ``--overwrite`` the earlier folder (moved to ``aside``) is put back unless
    this run saved a checkpoint, which then replaces it.
    """
    checkpoints = out / "checkpoints"
    if checkpoints.is_dir() and any(checkpoints.iterdir()):
        if aside is not None:
            shutil.rmtree(aside, ignore_errors=True)
        return f"checkpoints kept in {checkpoints}: --resume continues"
    if fresh:
        shutil.rmtree(out, ignore_errors=True)
        if aside is not None:
            aside.rename(out)
            return f"{out} left as it was before this run"
        return "nothing written"
    return f"{out} left as it was before this run"
