"""Configuration of the NIDAR networks and their training.

Plain dataclasses, one per component; every field is documented where it is declared, and its
allowed values are part of its type hint (``Literal[...]`` for a choice, an ``Annotated``
pydantic ``Field`` for an interval; a ``model_validator`` for a rule between fields).
:class:`TrainConfig` gathers them, converts to and from JSON-compatible dicts (validated by
pydantic against the type hints: unknown keys, values of the wrong type and values outside
their range are errors, one line naming each; the resolved configuration is written next to
every set of weights), checks one built in Python (:meth:`TrainConfig.validate`) and offers
:meth:`TrainConfig.reduced`, a tiny configuration that runs the real training loop in seconds on a CPU (used by the tests).

Defaults follow the paper (Sec. IV, "Implementation Details") where it states a value: Adam,
learning rate 1e-4, weight decay 1e-5, batch 8, 10 epochs, loss weights
``(lambda_recon, lambda_R, lambda_S, lambda_med, lambda_int) = (1.0, 0.01, 0, 0.01, 0.5)``,
``(w1, w2, w_ssim) = (1.0, 0.5, 0.2)``, multi-scale L1 at scales ``(1, 1/2, 1/4)``,
``m0 = 0.5``. Values the paper leaves open (network widths, edge weight ``gamma``, shading
pool size, warm-up length, crop size) are this package's choices and marked as such.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal, get_args

from pydantic import Field, model_validator

from ..errors import MAX_SEED, NidarError, validation_problem

__all__ = [
    "STNConfig",
    "IRNetConfig",
    "LossConfig",
    "OptimConfig",
    "TrainConfig",
    "IRNET_VARIANTS",
    "STN_KINDS",
    "PhotoConfig",
    "INPUT_MODES",
    "INPUT_CHANNELS",
    "dataclass_from_dict",
]

#: The two spectral translation networks (:attr:`STNConfig.kind`).
StnKind = Literal["cs_stereo", "lowres"]
STN_KINDS: tuple[str, ...] = get_args(StnKind)
#: IRNet structures of the paper's ablation (Table "IRNet structural ablation"):
#: ``backbone`` alone, or ``backbone+head``.
IRNetVariant = Literal[
    "unet",
    "deeplabv3",
    "unet+3conv",
    "unet+4conv",
    "unet+unet",
    "deeplabv3+3conv",
    "deeplabv3+4conv",
    "deeplabv3+unet",
    "deeplabv3+deeplabv3",
    "unet+deeplabv3",
]
IRNET_VARIANTS: tuple[str, ...] = get_args(IRNetVariant)

#: What IRNet receives: the STN's pseudo-NIR image, the RGB image itself (the paper's
#: pseudo-NIR-vs-RGB diagnostic), or both stacked (``rgb+pseudo_nir``: 4 channels, the colour
#: that carries the reflectance beside the pseudo-NIR that ``R · S`` explains), or the RGB's
#: chromaticity (shading-free by construction) and the pseudo-NIR (``chroma+pseudo_nir``).
InputMode = Literal["pseudo_nir", "rgb", "rgb+pseudo_nir", "chroma+pseudo_nir"]
INPUT_MODES: tuple[str, ...] = get_args(InputMode)
#: Channels of each input mode.
INPUT_CHANNELS = {"pseudo_nir": 1, "rgb": 3, "rgb+pseudo_nir": 4, "chroma+pseudo_nir": 4}

#: A whole number >= 1 (a count or a size).
Count = Annotated[int, Field(ge=1)]
#: A number >= 0 (a weight or a penalty).
NonNegative = Annotated[float, Field(ge=0)]
#: A share, in [0, 1].
Share = Annotated[float, Field(ge=0, le=1)]
#: A scale factor, in (0, 1].
Scale = Annotated[float, Field(gt=0, le=1)]

#: pydantic configuration of every config dataclass: unknown keys and non-finite numbers are
#: errors, and an instance handed to the validator is checked field by field.
_STRICT = {"extra": "forbid", "allow_inf_nan": False, "revalidate_instances": "always"}


@dataclass
class STNConfig:
    """Spectral translation network: cs-stereo's encoder-decoder or the low-resolution UNet."""

    __pydantic_config__ = _STRICT

    kind: StnKind = "cs_stereo"
    """One of :data:`STN_KINDS`: ``"cs_stereo"`` (:class:`~nidar_mi.nidar.stn.STN`, trained on
    renders) or ``"lowres"`` (:class:`~nidar_mi.nidar.stn_lowres.LowResSTN`, trained on real
    RGB/NIR photos; the shipped model's)."""
    width: Count = 16
    """Base channel count; encoder level ``i`` has ``width * 2**min(i, 5)`` channels
    (cs-stereo uses 16)."""
    levels: Count = 5
    """Number of stride-2 encoder levels; the network stride is ``2**levels`` (cs-stereo
    uses 7 on 582x429 images; 5 suits 128-256 px crops)."""
    num_outputs: Count = 4
    """Pyramid scales with a weight output (full, 1/2, 1/4, 1/8 in cs-stereo), at most
    :attr:`levels`; all are supervised during training."""
    depth: Count = 3
    """``lowres``: down-sampling steps of its UNet."""
    down: Count = 2
    """``lowres``: average-pooling factor of the image before its UNet."""

    @model_validator(mode="after")
    def _outputs_within_levels(self) -> STNConfig:
        if self.num_outputs > self.levels:
            raise ValueError(
                f"num_outputs must lie in [1, levels] = [1, {self.levels}] (got {self.num_outputs})"
            )
        return self


@dataclass
class PhotoConfig:
    """Training of a ``lowres`` STN on real RGB/NIR photo pairs (``train --photos``)."""

    __pydantic_config__ = _STRICT

    crops_per_epoch: Count = 2000
    """Random crops drawn per epoch (epochs are a bookkeeping unit: crops are drawn anew)."""
    zoom_min: Scale = 0.5
    """Crops cover ``crop_size / z`` pixels of the photo, ``z`` uniform in ``[zoom_min, 1]``,
    resized to ``crop_size``."""
    render_fraction: Share = 0.0
    """Share of crops drawn from the rendered RGB/NIR pairs of the dataset (0: photos only)."""
    ssim_weight: float = 0.5
    """Loss ``(1 - r) + ssim_weight · (1 - SSIM)`` after the per-crop gain and offset."""


@dataclass
class IRNetConfig:
    """Intrinsic reflectance network: decomposition backbone and intensity head."""

    __pydantic_config__ = _STRICT

    variant: IRNetVariant = "unet+deeplabv3"
    """One of :data:`IRNET_VARIANTS`; the paper's model is ``unet+deeplabv3``."""
    input: InputMode = "pseudo_nir"
    """One of :data:`INPUT_MODES`."""
    width: Count = 16
    """Base channel count of every sub-network (package choice, sized for CPU training)."""
    unet_depth: Count = 4
    """Number of down-sampling steps of a UNet (its stride is ``2**unet_depth``)."""
    output_stride: Literal[2, 4, 8, 16, 32] = 8
    """Output stride of a DeepLabV3 network (dilated convolutions replace striding beyond
    it)."""
    aspp_rates: tuple[int, ...] = (6, 12, 18)
    """Atrous rates of the ASPP branches (DeepLabV3's rates; with output stride 8 on 256 px
    crops they cover the same fraction of the feature map as on DeepLabV3's 513 px crops at
    stride 16)."""


#: What the supervised reflectance term compares R with (``LossConfig.r_target``).
RTarget = Literal["monostatic", "surface", "colour"]
R_TARGETS: tuple[str, ...] = get_args(RTarget)


@dataclass
class LossConfig:
    """Weights and constants of the STN and IRNet objectives."""

    __pydantic_config__ = _STRICT

    lambda_recon: float = 1.0
    """Weight of L_recon = ||R*S - I||_1."""
    lambda_r: float = 0.01
    """Weight of the edge-aware reflectance smoothness L_R."""
    lambda_s: float = 0.0
    """Weight of the shading prior L_S = ||S - AvgPool(S)||_1."""
    lambda_med: float = 0.01
    """Weight of the mean regulariser |mean(R) - m0|."""
    lambda_int: float = 0.5
    """Weight of the masked intensity loss L_int (after warm-up)."""
    w1: float = 1.0
    """Weight of the masked multi-scale L1 inside L_int."""
    w2: float = 0.5
    """Weight of the masked L2 inside L_int."""
    w_ssim: float = 0.2
    """Weight of the masked SSIM term inside L_int."""
    scales: tuple[Scale, ...] = (1.0, 0.5, 0.25)
    """Scales of the masked multi-scale L1, each in (0, 1]."""
    gamma: float = 10.0
    """Edge sensitivity of the smoothness weights exp(-gamma |grad I|) (package choice)."""
    shading_pool: int = 5
    """Kernel size of the AvgPool in the shading prior (package choice)."""
    m0: float = 0.5
    """Target mean of R."""
    lambda_r_true: NonNegative = 0.0
    """Weight of the supervised reflectance term ``mean |R - R_true|`` over the pixels with a
    surface (``R_true >= 1e-3``): rendered frames only, which know the true reflectance at the
    LiDAR wavelength (package addition; :func:`~nidar_mi.nidar.losses.reflectance_supervision_loss`)."""
    r_target: RTarget = "monostatic"
    """What ``lambda_r_true`` supervises R with, on rendered frames (:data:`R_TARGETS`):
    ``"monostatic"`` the frame's ``R_true`` (π·f_r(ω, ω) along the camera ray: gloss, opposition
    surge and incidence included); ``"surface"`` its ``R_surface`` (the surface's own diffuse
    reflectance at λ); ``"colour"`` the ρ(λ) its visible albedo colour ``A_true`` predicts
    (:func:`~nidar_mi.materials.visible_albedo.colour_reflectance_map`, fitted on the earthlib
    library): a target the image fixes once the shading is removed (package addition)."""
    lambda_s_true: NonNegative = 0.0
    """Weight of the supervised shading term, scale-invariant in log space (the network
    input's exposure normalisation leaves the scale of ``S`` free): rendered frames only
    (package addition; :func:`~nidar_mi.nidar.losses.shading_supervision_loss`)."""
    int_warmup_epochs: float = 2.0
    """Epochs over which lambda_int rises linearly from 0 to its value (package choice;
    the paper warms it up "during the initial training epochs")."""
    stn_ssim_alpha: float = 0.85
    """STN photometric loss: alpha * (1 - SSIM) / 2 + (1 - alpha) * L1 (cs-stereo's 0.85)."""
    eps: float = 1e-6
    """Epsilon of the masked normalisations."""


@dataclass
class OptimConfig:
    """Adam optimiser and schedule of one training stage."""

    __pydantic_config__ = _STRICT

    lr: Annotated[float, Field(gt=0)] = 1e-4
    """Learning rate."""
    weight_decay: NonNegative = 1e-5
    """Adam weight decay (L2 penalty)."""
    batch_size: Count = 8
    """Frames per step (incomplete last batches of an epoch are dropped)."""
    epochs: Count = 10
    """Passes over the training split."""
    max_steps: Count | None = None
    """Stop after this many optimiser steps in total (None: run all epochs)."""
    schedule: Literal["constant", "onecycle"] = "constant"
    """Learning rate over the run: ``"constant"`` or ``"onecycle"`` (a cosine rise from
    ``lr / 25`` to ``lr`` over the first 10 % of the steps, then a cosine fall to
    ``lr / 25 / 1e4``; :func:`nidar_mi.nidar.loop.learning_rate`)."""


@dataclass
class TrainConfig:
    """Everything that determines a NIDAR training run."""

    __pydantic_config__ = _STRICT

    stn: STNConfig = field(default_factory=STNConfig)
    """Spectral translation network."""
    irnet: IRNetConfig = field(default_factory=IRNetConfig)
    """Intrinsic reflectance network."""
    loss: LossConfig = field(default_factory=LossConfig)
    """Loss weights and constants."""
    stn_optim: OptimConfig = field(default_factory=OptimConfig)
    """Optimiser of the STN stage (package choice: the IRNet settings of the paper)."""
    irnet_optim: OptimConfig = field(default_factory=OptimConfig)
    """Optimiser of the IRNet stage (paper: Adam 1e-4, wd 1e-5, batch 8, 10 epochs)."""
    photos: PhotoConfig = field(default_factory=PhotoConfig)
    """Training of a ``lowres`` STN on real RGB/NIR photos (``train --photos``)."""
    crop_size: Count = 256
    """Side of the square random training crops (centre crops for validation), in pixels at
    the network resolution (:attr:`scale`); a multiple of every network stride. With
    :attr:`crop_width` it is the crops' height."""
    crop_width: Count | None = None
    """Width of the training crops in pixels at the network resolution (None: square crops of
    :attr:`crop_size`); a multiple of every network stride (package choice: wide crops suit
    the wide, short band of a camera image that LiDAR returns cover)."""
    scale: Scale = 1.0
    """Network resolution relative to the frames, in (0, 1]. IRNet trains on frames resized to
    ``round(scale · H) x round(scale · W)`` (the input area-averaged as at inference, the
    sparse intensity re-projected with the nearest return winning each pixel), and
    :class:`~nidar_mi.nidar.pipeline.NidarModel` runs at this scale by default. The STN stage
    trains at full resolution."""
    render_scale: Scale = 1.0
    """Network resolution of rendered frames mixed into an IRNet run on real frames
    (``train --renders``), relative to the renders, in (0, 1] (package choice: renders are
    smaller than camera frames; 1.0 on 320 x 192 renders matches KITTI at 0.25 in pixels per
    degree)."""
    threads: Count | None = None
    """torch intra-op threads while training (None: torch's default). On a loaded machine one
    thread can be several times faster than more (OpenMP threads spin-wait for busy cores);
    the result does not depend on it beyond floating-point summation order."""
    seed: Annotated[int, Field(ge=0, le=MAX_SEED)] = 0
    """Seed of weight initialisation, shuffling, crops and flips."""
    device: Annotated[str, Field(pattern=r"^(auto|cpu|cuda(:\d+)?)$")] = "auto"
    """``"auto"`` (CUDA when available, else CPU), ``"cpu"``, ``"cuda"`` or ``"cuda:N"``."""
    checkpoint_every: Count = 500
    """Write a resumable checkpoint every this many steps (and at the end of every epoch)."""
    keep_checkpoints: Count = 3
    """Checkpoints kept per stage (older ones are deleted)."""
    num_workers: int = 0
    """DataLoader worker processes."""

    @classmethod
    def reduced(cls) -> TrainConfig:
        """Tiny networks, 32 px crops, batch 2, two steps per stage: the test configuration."""
        steps = OptimConfig(lr=1e-3, weight_decay=1e-5, batch_size=2, epochs=1, max_steps=2)
        return cls(
            stn=STNConfig(width=4, levels=3, num_outputs=2),
            irnet=IRNetConfig(width=4, unet_depth=2, output_stride=4, aspp_rates=(1, 2, 3)),
            loss=LossConfig(int_warmup_epochs=1.0),
            stn_optim=steps,
            irnet_optim=dataclasses.replace(steps),
            crop_size=32,
            checkpoint_every=1,
        )

    @property
    def intrinsic_supervision(self) -> bool:
        """True when IRNet's R or S is supervised with a rendered frame's true maps."""
        return self.loss.lambda_r_true > 0 or self.loss.lambda_s_true > 0

    @property
    def crop_shape(self) -> tuple[int, int]:
        """``(height, width)`` of the training crops, pixels at the network resolution."""
        return int(self.crop_size), int(self.crop_width or self.crop_size)

    def validate(self) -> None:
        """Check a configuration built in Python (:meth:`from_dict` checks its input itself).

        Raises:
            NidarError: one line naming each field whose value is outside its type, range or
                choices, with what it allows and the value given.
        """
        _validated(type(self), "config", lambda adapter: adapter.validate_python(self, strict=True))

    def to_dict(self) -> dict[str, Any]:
        """JSON-compatible nested dict (tuples become lists)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Any, base: TrainConfig | None = None) -> TrainConfig:
        """Inverse of :meth:`to_dict`: a configuration from a JSON-compatible nested dict.

        Args:
            data: nested dict; keys it leaves out keep their value in ``base``.
            base: the configuration ``data`` changes (nested objects are merged key by key);
                default: the class defaults.

        Raises:
            NidarError: on unknown keys or a value of the wrong JSON type (one line naming
                every offending key).
        """
        if base is not None:
            if not isinstance(data, dict):
                raise NidarError(f"config must be a JSON object, got {type(data).__name__}")
            data = _merged(base.to_dict(), data)
        return dataclass_from_dict(cls, data, "config")


def _merged(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """``base`` updated by ``override``, nested dicts merged key by key."""
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merged(out[key], value)
        else:
            out[key] = value
    return out


@functools.cache
def _adapter(kind: type):
    from pydantic import TypeAdapter

    return TypeAdapter(kind)


def dataclass_from_dict(kind: type, data: Any, where: str = "config") -> Any:
    """Build config dataclass ``kind`` (nested dataclasses too) from a JSON-compatible dict.

    Validated by pydantic against the dataclass's type hints, with JSON's types taken strictly
    (an int field takes no ``2.5``, ``"2"`` or ``true``; a float field takes an int; a tuple
    field takes a list), and against the ranges and choices the hints set. Missing fields take
    their defaults.

    Raises:
        NidarError: ``data`` is not a dict, has keys ``kind`` does not know, values of the
            wrong type or out of range; one line naming each offending key under ``where``.
    """
    if not isinstance(data, dict):
        raise NidarError(f"{where} must be a JSON object, got {type(data).__name__}")
    try:
        text = json.dumps(data, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise NidarError(f"{where} is not JSON data: {exc}") from None
    return _validated(kind, where, lambda adapter: adapter.validate_json(text, strict=True))


def _validated(kind: type, where: str, validate) -> Any:
    """``validate(adapter)`` with the pydantic adapter of ``kind``; a validation error as one
    line, ``<where>.<key>: <problem>`` for each offending key (:func:`validation_problem`)."""
    from pydantic import ValidationError

    try:
        return validate(_adapter(kind))
    except ValidationError as exc:
        problems = [
            f"{'.'.join([where, *map(str, e['loc'])])}: {validation_problem(kind, e)}"
            for e in exc.errors()
        ]
        raise NidarError("; ".join(problems)) from None
