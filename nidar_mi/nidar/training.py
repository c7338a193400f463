"""Training of the NIDAR networks: STN on RGB/NIR pairs, then IRNet on sparse LiDAR intensity.

Stages (paper Sec. III-IV):

1. ``stn``: the spectral translation network learns RGB -> NIR on the rendered pairs
   (L1 + SSIM at every pyramid scale). The paper uses the pretrained cs-stereo STN, whose
   weights are not available here; this stage replaces it.
2. ``irnet``: the STN is frozen and its pseudo-NIR images are computed once per frame (whole
   frames, cached under ``OUT/cache``); IRNet is trained on them (or on RGB for the
   diagnostic variant) with the full intrinsic objective and masked intensity supervision,
   ``lambda_int`` warmed up linearly.

Outputs in ``OUT``: ``stn.safetensors``, ``irnet.safetensors``, ``config.json`` (the
resolved configuration and the data's ``meta.json`` values), ``train_log.json`` (losses per
step, training and validation loss per epoch), and ``checkpoints/`` (resumable, see
:mod:`nidar_mi.nidar.checkpoint`). Runs are deterministic given ``cfg.seed``: weights are
initialised after ``torch.manual_seed(seed)``, batches come from a permutation seeded by
``(seed, epoch)``, crops and flips from generators seeded by ``(seed, epoch, frame)``, and
CPU runs use deterministic algorithms; a resumed run continues with the same batches.
"""

from __future__ import annotations

import contextlib
import io
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from ..errors import NidarError
from ..io.cache_key import file_sha256
from ..training_frames import list_frames, load_frame, load_meta
from .checkpoint import atomic_write
from .config import INPUT_CHANNELS, TrainConfig
from .data import IntrinsicTargets, IRNetDataset, MixedDataset, STNDataset
from .infer import pseudo_nir
from .loop import Stage, read_train_log, run_stage, write_stage_log
from .losses import irnet_objective, photo_stn_loss, stn_loss
from .model_io import build_irnet, build_stn, load_stn, resolve_device, save_irnet, save_stn
from .stn import image_pyramid

__all__ = [
    "input_identity",
    "resume_identity",
    "train",
    "train_stn",
    "train_stn_photos",
    "train_irnet",
]


#: Real RGB/NIR photo pairs for the STN: ``(fit, val)``, lists of ``(rgb (H, W, 3) uint8,
#: nir (H, W) uint8)``.
PhotoPairs = tuple[list[tuple[np.ndarray, np.ndarray]], list[tuple[np.ndarray, np.ndarray]]]

# --------------------------------------------------------------------------- public API


def train(
    cfg: TrainConfig,
    data_dir: str | Path,
    out_dir: str | Path,
    *,
    stn_weights: str | Path | None = None,
    resume: bool = False,
    progress: bool = True,
    photos: PhotoPairs | None = None,
) -> dict[str, Path]:
    """Train both stages (the STN is skipped when ``stn_weights`` is given, and for RGB-input
    IRNet without ``stn_weights``). With ``photos`` (real RGB/NIR photo pairs, ``(fit, val)`` as
    :func:`nidar_mi.datasets.rgbnir.stn_training_pairs` loads them) the STN is trained on them
    (:func:`train_stn_photos`), else on the dataset's renders.

    Returns:
        ``{"stn": path, "irnet": path}`` (``"stn"`` absent when no STN was used).
    """
    out: dict[str, Path] = {}
    if stn_weights is None and cfg.irnet.input != "rgb":
        if photos is not None:
            stn_weights = out["stn"] = train_stn_photos(
                cfg, photos, data_dir, out_dir, resume=resume, progress=progress
            )
        else:
            stn_weights = out["stn"] = train_stn(
                cfg, data_dir, out_dir, resume=resume, progress=progress
            )
    out["irnet"] = train_irnet(
        cfg, data_dir, out_dir, stn_weights, resume=resume, progress=progress
    )
    if (Path(out_dir) / "stn.safetensors").is_file():
        out["stn"] = Path(out_dir) / "stn.safetensors"
    return out


def train_stn(
    cfg: TrainConfig,
    data_dir: str | Path,
    out_dir: str | Path,
    *,
    resume: bool = False,
    progress: bool = True,
) -> Path:
    """Train the STN on ``DATA/{train,val}``; returns ``OUT/stn.safetensors``."""
    data_dir, out_dir = Path(data_dir), Path(out_dir)
    _begin(cfg, data_dir, out_dir, "stn", resume)
    torch.manual_seed(cfg.seed)
    model = build_stn(cfg.stn)
    _check_crop(cfg.crop_size, model.stride, "STN")
    train_set = STNDataset(_frames(data_dir, "train"), cfg.crop_size, cfg.seed, train=True)
    val_set = STNDataset(list_frames(data_dir, "val"), cfg.crop_size, cfg.seed, train=False)
    alpha = cfg.loss.stn_ssim_alpha

    def loss_fn(net, batch, _factor):
        if not hasattr(net, "forward_pyramid"):  # a lowres STN: one output, gain-blind loss
            return photo_stn_loss(net(batch["rgb"]), batch["nir"], cfg.photos.ssim_weight), {}
        preds = net.forward_pyramid(batch["rgb"])
        loss = stn_loss(preds, image_pyramid(batch["nir"], len(preds)), alpha)
        return loss, {}

    stage = Stage("stn", model, cfg.stn_optim, train_set, val_set, loss_fn)
    return _run_stn_stage(stage, cfg, out_dir, resume, progress)


def train_stn_photos(
    cfg: TrainConfig,
    photos: PhotoPairs,
    data_dir: str | Path,
    out_dir: str | Path,
    *,
    resume: bool = False,
    progress: bool = True,
) -> Path:
    """Train the STN on real RGB/NIR photo pairs; returns ``OUT/stn.safetensors``.

    ``photos`` is ``(fit, val)``: the network is fitted on the ``fit`` pairs and ``val`` crops are
    logged; each pair is ``(rgb (H, W, 3) uint8, nir (H, W) uint8)``
    (:func:`nidar_mi.datasets.rgbnir.stn_training_pairs` loads them, by image split so that the
    photo evaluation's test pairs are never read). With ``cfg.photos.render_fraction > 0`` that share of the
    crops comes from the rendered RGB/NIR pairs of ``data_dir/train``. Loss:
    :func:`~nidar_mi.nidar.losses.photo_stn_loss`; crops: :mod:`nidar_mi.nidar.photo_data`.
    The network is ``cfg.stn`` (``kind`` ``"lowres"`` is the shipped one).
    """
    from .photo_data import PhotoCropDataset, render_pair

    data_dir, out_dir = Path(data_dir), Path(out_dir)
    fit, val = photos
    _begin(cfg, data_dir, out_dir, "stn", resume)
    torch.manual_seed(cfg.seed)
    model = build_stn(cfg.stn)
    _check_crop(cfg.crop_size, model.stride, "STN")
    pc = cfg.photos
    renders = []
    if pc.render_fraction > 0:
        renders = [render_pair(f) for f in _frames(data_dir, "train")]
    common = dict(zoom_min=pc.zoom_min, renders=renders, render_fraction=pc.render_fraction)
    train_set = PhotoCropDataset(fit, cfg.crop_size, pc.crops_per_epoch, cfg.seed, True, **common)
    val_set = PhotoCropDataset(val, cfg.crop_size, 8 * len(val), cfg.seed, False, **common)

    def loss_fn(net, batch, _factor):
        return photo_stn_loss(net(batch["rgb"]), batch["nir"], pc.ssim_weight), {}

    stage = Stage("stn", model, cfg.stn_optim, train_set, val_set, loss_fn)
    return _run_stn_stage(stage, cfg, out_dir, resume, progress)


def train_irnet(
    cfg: TrainConfig,
    data_dir: str | Path,
    out_dir: str | Path,
    stn_weights: str | Path | None = None,
    *,
    resume: bool = False,
    progress: bool = True,
    frames: dict[str, Sequence[str | Path]] | None = None,
    cache_dir: str | Path | None = None,
    init_weights: str | Path | None = None,
    render_frames: Sequence[str | Path] | None = None,
) -> Path:
    """Train IRNet; returns ``OUT/irnet.safetensors``.

    Args:
        cfg: configuration (``cfg.irnet.input`` selects pseudo-NIR or RGB input;
            ``cfg.scale`` the network resolution).
        data_dir: training data (its ``meta.json`` gives the intensity scale).
        out_dir: output directory.
        stn_weights: trained STN (default ``OUT/stn.safetensors``); copied into ``OUT`` when
            it lies elsewhere. Required for pseudo-NIR input, optional for RGB input.
        resume: continue from the latest checkpoint in ``OUT/checkpoints``.
        progress: show tqdm progress bars.
        frames: ``{"train": [...], "val": [...]}`` frame files to use instead of the data's
            ``train`` and ``val`` splits (e.g. a leave-one-out fold, or every frame for a
            model to ship; an empty ``val`` list skips validation).
        cache_dir: folder of the pseudo-NIR cache (default ``OUT/cache``; runs on the same
            frames with the same STN and scale can share one).
        init_weights: IRNet weights to start from (e.g. pretrained on renders with the
            supervised intrinsic terms, then fine-tuned here on real frames); their network
            configuration must equal ``cfg.irnet``. Recorded in ``config.json``
            (``data.init``: path and SHA-256). A resumed run continues from its checkpoint.
        render_frames: rendered frames mixed into the training crops to supervise the
            decomposition only (``loss.lambda_r_true`` / ``lambda_s_true``; their intensity is
            another sensor's and is left out), at ``cfg.render_scale``; the run's own frames
            supervise the intensity (and R and S too, where they carry true maps). In a mixed
            batch every term is averaged over all of its images, those it does not apply to
            counting 0 (the SSIM part of the intensity term: 1, without gradient), so the
            effective weights scale with the share of renders and of real frames. Recorded in
            ``config.json`` (``data.renders``).
    """
    data_dir, out_dir = Path(data_dir), Path(out_dir)
    source = Path(stn_weights) if stn_weights is not None else out_dir / "stn.safetensors"
    if source.is_file():
        cfg = _with_stn_config(cfg, source)  # config.json describes the STN actually used
    cfg.validate()
    # every check of the inputs comes before anything is written into OUT
    run = _irnet_run(cfg, data_dir, frames, render_frames, init_weights)
    _begin(cfg, data_dir, out_dir, "irnet", resume, run.inputs)
    if frames is not None:
        _record_frames(out_dir, run.frames)
    device = resolve_device(cfg.device)
    local = _place_stn(stn_weights, out_dir)
    with _torch_threads(cfg.threads):
        if cfg.irnet.input != "rgb":
            cache = Path(cache_dir) if cache_dir is not None else out_dir / "cache"
            _cache_irnet_inputs(run, cfg, local, device, cache)
        torch.manual_seed(cfg.seed)
        model = build_irnet(cfg.irnet)
        if run.init_state is not None:
            model.load_state_dict(run.init_state)
        for side in cfg.crop_shape:
            _check_crop(side, model.stride, "IRNet")
        train_set, val_set = _irnet_datasets(run, cfg)
        warmup = cfg.loss.int_warmup_epochs
        loss_fn = _irnet_loss(cfg)
        stage = Stage("irnet", model, cfg.irnet_optim, train_set, val_set, loss_fn, warmup)
        run_stage(stage, cfg, out_dir, resume, progress)
    path = save_irnet(out_dir / "irnet.safetensors", model, cfg.irnet)
    _mark_done(out_dir, "irnet")
    return path


@dataclass
class _IRNetRun:
    """The checked inputs of an IRNet run (:func:`train_irnet`).

    Attributes:
        meta: the data folder's ``meta.json``.
        frames: ``{"train": [...], "val": [...]}`` frame files.
        renders: rendered frames mixed in (empty: none).
        inputs: what ``config.json`` records of them (``renders``, ``init``).
        init_state: the initial weights' state dict, or None.
        input_dirs: per split the folder of its cached pseudo-NIR inputs (None: RGB input).
        render_input: the folder of the renders' cached pseudo-NIR inputs.
    """

    meta: dict
    frames: dict[str, list[Path]]
    renders: list[Path]
    inputs: dict[str, Any]
    init_state: dict | None = None
    input_dirs: dict[str, Path | None] = field(default_factory=lambda: {"train": None, "val": None})
    render_input: Path | None = None


def _irnet_run(cfg: TrainConfig, data_dir: Path, frames, render_frames, init_weights) -> _IRNetRun:
    """Check the frames, the renders mixed in and the initial weights of an IRNet run."""
    meta = load_meta(data_dir)
    if frames is None:
        split_frames = {"train": _frames(data_dir, "train"), "val": list_frames(data_dir, "val")}
    else:
        split_frames = {k: [Path(f) for f in frames.get(k, ())] for k in ("train", "val")}
        if not split_frames["train"]:
            raise NidarError("no training frames given")
    renders = [Path(f) for f in render_frames or ()]
    inputs: dict[str, Any] = {}
    if render_frames is not None:
        if not renders:
            raise NidarError("no rendered frames given to mix in")
        if not cfg.intrinsic_supervision:
            raise NidarError(
                "rendered frames mixed in supervise the decomposition only: set "
                "loss.lambda_r_true and/or loss.lambda_s_true above 0"
            )
        _check_intrinsic_frames(renders, cfg.loss.r_target)
        _check_render_sizes(renders, cfg)
        inputs["renders"] = sorted(str(f) for f in renders)
    elif cfg.intrinsic_supervision:
        _check_intrinsic_frames(split_frames["train"] + split_frames["val"], cfg.loss.r_target)
    init_state = None
    if init_weights is not None:
        init_state = _init_state(cfg, Path(init_weights))
        inputs["init"] = {"irnet": str(init_weights), "sha256": file_sha256(init_weights)}
    return _IRNetRun(meta, split_frames, renders, inputs, init_state)


def _place_stn(stn_weights, out_dir: Path) -> Path | None:
    """``OUT/stn.safetensors``, copied there from ``stn_weights`` when that lies elsewhere
    (checked to be an STN first); None when there is neither."""
    local = out_dir / "stn.safetensors"
    if stn_weights is None:
        return local if local.is_file() else None
    stn_weights = Path(stn_weights)
    if not stn_weights.is_file():
        raise NidarError(f"STN weights {stn_weights} not found")
    if stn_weights.resolve() != local.resolve():
        if local.is_file() and local.read_bytes() != stn_weights.read_bytes():
            raise NidarError(f"{local} exists and differs from {stn_weights}")
        load_stn(stn_weights, "cpu")  # a file that is no STN fails here, before the copy
        atomic_write(local, stn_weights.read_bytes())
    return local


def _cache_irnet_inputs(run: _IRNetRun, cfg: TrainConfig, stn_path, device, cache: Path) -> None:
    """The STN's pseudo-NIR of every frame (and render), cached under ``cache`` per STN and
    scale; the folders go to ``run.input_dirs`` and ``run.render_input``."""
    if stn_path is None:
        raise NidarError("IRNet with pseudo-NIR input needs STN weights (train the STN first)")
    stn = load_stn(stn_path, device)
    digest = file_sha256(stn_path)[:16]
    tag = f"pseudo_nir_{digest}" + (f"_x{cfg.scale:g}" if cfg.scale != 1.0 else "")
    for split, fs in run.frames.items():
        run.input_dirs[split] = _cache_pseudo_nir(stn, fs, cache / tag, cfg.scale)
    if run.renders:
        rtag = f"pseudo_nir_{digest}_renders" + (
            f"_x{cfg.render_scale:g}" if cfg.render_scale != 1.0 else ""
        )
        run.render_input = _cache_pseudo_nir(stn, run.renders, cache / rtag, cfg.render_scale)


def _irnet_datasets(run: _IRNetRun, cfg: TrainConfig):
    """``(train_set, val_set)``: the run's frames, the renders mixed into the training set."""
    scale = float(run.meta["intensity_scale"])
    common = dict(
        crop_size=cfg.crop_shape,
        seed=cfg.seed,
        scale=cfg.scale,
        intrinsic=IntrinsicTargets(
            r_target=cfg.loss.r_target,
            wavelength_nm=float(run.meta.get("wavelength_nm") or 905.0),
            missing_zero=bool(run.renders),
        )
        if cfg.intrinsic_supervision
        else None,
        colour=cfg.irnet.input if INPUT_CHANNELS[cfg.irnet.input] == 4 else None,
    )
    dirs = run.input_dirs
    train_set = IRNetDataset(
        run.frames["train"], scale, train=True, input_dir=dirs["train"], **common
    )
    if run.renders:
        render_set = IRNetDataset(
            run.renders,
            1.0,
            train=True,
            input_dir=run.render_input if cfg.irnet.input != "rgb" else None,
            **(common | {"scale": cfg.render_scale}),
            supervise_intensity=False,
        )
        train_set = MixedDataset(train_set, render_set)
    val_set = IRNetDataset(run.frames["val"], scale, train=False, input_dir=dirs["val"], **common)
    return train_set, val_set


def _irnet_loss(cfg: TrainConfig):
    """The IRNet stage's loss of a batch (:func:`~nidar_mi.nidar.losses.irnet_objective`)."""

    def loss_fn(net, batch, factor):
        x = batch["x"]
        loss, terms = irnet_objective(
            net(x),
            net.intrinsic_target(x),
            batch["intensity"],
            batch["mask"],
            cfg.loss,
            factor,
            batch.get("R_true"),
            batch.get("S_true"),
        )
        return loss, {**terms, "int_factor": factor}

    return loss_fn


# --------------------------------------------------------------------------- run bookkeeping


def _frames(data_dir: Path, split: str) -> list[Path]:
    frames = list_frames(data_dir, split)
    if not frames:
        raise NidarError(f"no frames in {data_dir / split}")
    return frames


def _check_crop(crop: int, stride: int, name: str) -> None:
    if crop % stride:
        raise NidarError(f"crop_size {crop} is not a multiple of the {name} stride {stride}")


def _run_stn_stage(
    stage: Stage, cfg: TrainConfig, out_dir: Path, resume: bool, progress: bool
) -> Path:
    """Train an STN stage, save its weights as ``out_dir/stn.safetensors`` and mark it done."""
    with _torch_threads(cfg.threads):
        run_stage(stage, cfg, out_dir, resume, progress)
    path = save_stn(out_dir / "stn.safetensors", stage.model, cfg.stn)
    _mark_done(out_dir, "stn")
    return path


def _mark_done(out_dir: Path, stage: str) -> None:
    stage_log = read_train_log(out_dir).get(stage, {"steps": [], "epochs": []})
    write_stage_log(out_dir, stage, {**stage_log, "done": True})


#: Inputs of a run besides its configuration, recorded under ``data`` in ``config.json``.
_INPUT_KEYS = ("init", "renders")
_INPUT_WORDS = {"init": "initial IRNet weights", "renders": "rendered frames mixed in"}


def input_identity(value: Any) -> Any:
    """What must match for a run to continue: the initial weights' hash, the renders' list."""
    if isinstance(value, dict):
        return value.get("sha256")
    return value


#: Settings that may change when a run is resumed (they do not change what a step computes).
_RESUMABLE_CHANGES = ("device", "num_workers", "checkpoint_every", "keep_checkpoints", "threads")
_SCHEDULE_KEYS = ("epochs", "max_steps")


def resume_identity(train_cfg: dict[str, Any]) -> dict[str, Any]:
    """The settings of a run that a resumed run must share: ``train_cfg`` without those a run
    may change when it resumes (devices, workers, checkpoints, the schedule's length)."""
    d = json.loads(json.dumps(train_cfg))
    for key in _RESUMABLE_CHANGES:
        d.pop(key, None)
    for optim in ("stn_optim", "irnet_optim"):
        for key in _SCHEDULE_KEYS:
            d.get(optim, {}).pop(key, None)
    return d


def _begin(
    cfg: TrainConfig,
    data_dir: Path,
    out_dir: Path,
    stage: str,
    resume: bool,
    inputs: dict[str, Any] | None = None,
) -> None:
    """Validate the configuration and write ``OUT/config.json``.

    A directory may hold one run: its configuration may only differ in the schedule
    (epochs, max_steps) and in settings that do not change the computation, its further
    inputs (``inputs``: initial weights, rendered frames mixed in; recorded under ``data``)
    may not differ once the stage has made progress, and a stage that has made progress
    continues only with ``resume``.
    """
    cfg.validate()
    meta = load_meta(data_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    record = {
        "train": cfg.to_dict(),
        "data": {
            "dir": str(data_dir),
            "intensity_scale": meta["intensity_scale"],
            "wavelength_nm": meta.get("wavelength_nm"),
        },
    }
    record["data"] |= dict(inputs or {})
    cfg_path = out_dir / "config.json"
    if cfg_path.is_file():
        try:
            previous = json.loads(cfg_path.read_text())
            old = previous["train"]
            old_data = previous.get("data", {})
        except (OSError, json.JSONDecodeError, KeyError, TypeError, AttributeError) as exc:
            raise NidarError(f"cannot read {cfg_path}: {exc}") from None
        if resume_identity(old) != resume_identity(record["train"]):
            raise NidarError(f"{out_dir} holds a run with a different configuration")
        if read_train_log(out_dir).get(stage, {}).get("steps"):  # a stage to continue
            for key in _INPUT_KEYS:
                if input_identity(old_data.get(key)) != input_identity(record["data"].get(key)):
                    raise NidarError(f"{out_dir} holds a run with other {_INPUT_WORDS[key]}")
    if read_train_log(out_dir).get(stage, {}).get("steps") and not resume:
        raise NidarError(f"{out_dir} already holds a {stage} run; resume it or use a new directory")
    atomic_write(cfg_path, json.dumps(record, indent=2))


def _cache_pseudo_nir(stn: nn.Module, frames: list[Path], cache_dir: Path, scale: float) -> Path:
    """Write ``<frame>.npy`` pseudo-NIR images ``(1, H, W)`` (the STN run at ``scale``, as at
    inference) that are not cached yet."""
    for path in frames:
        target = cache_dir / f"{path.stem}.npy"
        if target.is_file():
            continue
        image = pseudo_nir(stn, load_frame(path, ("rgb",))["rgb"], scale=scale)
        buf = io.BytesIO()
        np.save(buf, image[None].astype(np.float32), allow_pickle=False)
        atomic_write(target, buf.getvalue())
    return cache_dir


@contextlib.contextmanager
def _torch_threads(threads: int | None):
    """torch's intra-op thread count set to ``threads`` (None: unchanged), then restored."""
    if threads is None:
        yield
        return
    previous = torch.get_num_threads()
    torch.set_num_threads(int(threads))
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def _with_stn_config(cfg: TrainConfig, stn_path: Path) -> TrainConfig:
    """``cfg`` with the network configuration stored in the STN weights file ``stn_path``."""
    import dataclasses

    from .config import STNConfig

    return dataclasses.replace(cfg, stn=_stored_config(stn_path, "stn", STNConfig))


def _stored_config(path: Path, kind: str, config_cls):
    """The network configuration stored in the weights file ``path`` of ``kind`` (``"stn"`` or
    ``"irnet"``), as a ``config_cls``; one-line errors for another file or a bad configuration."""
    from .checkpoint import read_weights_metadata
    from .config import dataclass_from_dict

    meta = read_weights_metadata(path)
    if meta.get("format") != f"nidar_mi.{kind}" or "config" not in meta:
        raise NidarError(f"{path} does not hold {'STN' if kind == 'stn' else 'IRNet'} weights")
    try:
        return dataclass_from_dict(config_cls, json.loads(meta["config"]), f"{path} config")
    except json.JSONDecodeError:
        raise NidarError(f"{path}: invalid network configuration") from None


def _check_intrinsic_frames(frames: list[Path], r_target: str = "monostatic") -> None:
    """Every frame must carry ``R_true`` and ``S_true`` (rendered frames do, real ones not), and
    the map ``r_target`` reads (``R_surface`` or ``A_true``: frames rendered by this version)."""
    from ..training_frames import frame_has
    from .data import R_TARGET_KEYS

    extra = R_TARGET_KEYS[r_target]
    for path in frames:
        if not frame_has(path, ("R_true", "S_true")):
            raise NidarError(
                f"loss.lambda_r_true / lambda_s_true need rendered frames with R_true and "
                f"S_true; {path} has none (real frames carry no true reflectance: mix rendered "
                f"frames in with `render_frames`)"
            )
        if extra and not frame_has(path, extra):
            raise NidarError(
                f"loss.r_target {r_target!r} needs rendered frames with {extra[0]}; {path} has "
                "none (render the dataset again with this version)"
            )


def _init_state(cfg: TrainConfig, path: Path) -> dict[str, torch.Tensor]:
    """State dict of the IRNet weights ``path``, checked against ``cfg.irnet``."""
    import dataclasses

    from .config import IRNetConfig
    from .model_io import load_irnet

    if not path.is_file():
        raise NidarError(f"initial IRNet weights {path} not found")
    given = _stored_config(path, "irnet", IRNetConfig)
    if dataclasses.asdict(given) != dataclasses.asdict(cfg.irnet):
        raise NidarError(
            f"initial IRNet weights {path} are a different network "
            f"({given.variant}, width {given.width}, depth {given.unet_depth}, input "
            f"{given.input}) than the configuration's ({cfg.irnet.variant}, width "
            f"{cfg.irnet.width}, depth {cfg.irnet.unet_depth}, input {cfg.irnet.input})"
        )
    return load_irnet(path, "cpu").state_dict()


def _check_render_sizes(renders: list[Path], cfg: TrainConfig) -> None:
    """Every render, at ``cfg.render_scale``, must hold a training crop."""
    from .infer import reduced_size

    ch, cw = cfg.crop_shape
    for path in renders:
        h, w = load_frame(path, ("mask",))["mask"].shape
        rh, rw = reduced_size(h, w, cfg.render_scale)
        if rh < ch or rw < cw:
            raise NidarError(
                f"{path}: {rh}x{rw} pixels at render_scale {cfg.render_scale:g}, smaller than "
                f"the {ch}x{cw} training crops"
            )


def _record_frames(out_dir: Path, split_frames: dict[str, list[Path]]) -> None:
    """Add the frames a run was given to ``OUT/config.json`` (``data.frames``)."""
    path = out_dir / "config.json"
    record = json.loads(path.read_text())
    record["data"]["frames"] = {k: sorted(f.stem for f in v) for k, v in split_frames.items()}
    atomic_write(path, json.dumps(record, indent=2))
