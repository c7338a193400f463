"""Spectral translation network (STN): RGB -> pseudo-NIR.

The design is the STN of cs-stereo (Zhi et al., "Deep Material-aware Cross-spectral Stereo
Matching", CVPR 2018): an encoder-decoder predicts three per-pixel weights ``w_c`` and the
pseudo-NIR image is their combination of the colour channels,

    pseudo_nir = exposure_ratio * sum_c w_c * RGB_c,

predicted at several pyramid scales (finest first). Encoder levels are a stride-2 convolution
and a stride-1 convolution, each followed by BatchNorm and ELU (kernels 7, 5, then 3);
decoder levels up-sample bilinearly, convolve, concatenate the encoder skip (and the
up-sampled coarser weights) and convolve again. A weight output is ``ELU(conv) / 3`` with its
bias initialised to 1, so an untrained STN averages the three channels.

The NIDAR paper uses the pretrained cs-stereo weights; those cannot be obtained here, so this
package trains the STN on rendered RGB/NIR pairs (supervised, L1 + SSIM at every pyramid
scale, see :func:`nidar_mi.nidar.losses.stn_loss`) instead of cs-stereo's unsupervised
stereo-warping objective. Inputs are linear, exposure-normalised RGB
(:func:`nidar_mi.nidar.preprocess.prepare_rgb`).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["STN", "image_pyramid"]


class _Encoder(nn.Module):
    def __init__(self, in_ch: int, out_ch: int, ksize: int) -> None:
        super().__init__()
        pad = ksize // 2
        self.conv = nn.Conv2d(in_ch, out_ch, ksize, stride=2, padding=pad, bias=False)
        self.bn = nn.BatchNorm2d(out_ch)
        self.convb = nn.Conv2d(out_ch, out_ch, ksize, stride=1, padding=pad, bias=False)
        self.bnb = nn.BatchNorm2d(out_ch)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = F.elu(self.bn(self.conv(x)))
        return F.elu(self.bnb(self.convb(x)))


class _Decoder(nn.Module):
    def __init__(self, in_ch: int, out_ch: int, skip_ch: int, with_output: bool) -> None:
        super().__init__()
        self.conv = nn.Conv2d(in_ch, out_ch, 3, padding=1, bias=False)
        self.bn = nn.BatchNorm2d(out_ch)
        self.iconv = nn.Conv2d(out_ch + skip_ch, out_ch, 3, padding=1, bias=False)
        self.ibn = nn.BatchNorm2d(out_ch)
        self.out = nn.Conv2d(out_ch, 3, 3, padding=1, bias=True) if with_output else None

    def forward(
        self, x: torch.Tensor, skip: torch.Tensor | None, size: tuple[int, int]
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        up = F.interpolate(x, size=size, mode="bilinear", align_corners=False)
        up = F.elu(self.bn(self.conv(up)))
        if skip is not None:
            up = torch.cat((up, skip), 1)
        feat = F.elu(self.ibn(self.iconv(up)))
        weights = F.elu(self.out(feat)) / 3.0 if self.out is not None else None
        return feat, weights


class STN(nn.Module):
    """cs-stereo spectral translation network.

    Args:
        width: base channel count; encoder level ``i`` (1-based) has
            ``width * 2**min(i, 5)`` channels, decoder level ``i`` ``width * 2**min(i-1, 5)``.
        levels: stride-2 encoder levels; inputs must have sides divisible by
            :attr:`stride` ``= 2**levels``.
        num_outputs: pyramid scales with a weight output (``1 <= num_outputs <= levels``).

    Example:
        >>> stn = STN(width=4, levels=3, num_outputs=2)
        >>> stn(torch.rand(1, 3, 32, 32)).shape
        torch.Size([1, 1, 32, 32])
    """

    def __init__(self, width: int = 16, levels: int = 5, num_outputs: int = 4) -> None:
        super().__init__()
        if not 1 <= num_outputs <= levels:
            raise ValueError(f"num_outputs must lie in [1, {levels}], got {num_outputs}")
        self.levels = levels
        self.num_outputs = num_outputs
        enc_ch = [width * 2 ** min(i, 5) for i in range(1, levels + 1)]
        dec_ch = [width * 2 ** min(i - 1, 5) for i in range(1, levels + 1)]
        kernels = [7, 5] + [3] * max(0, levels - 2)
        self.encoders = nn.ModuleList(
            _Encoder(3 if i == 0 else enc_ch[i - 1], enc_ch[i], kernels[i]) for i in range(levels)
        )
        decoders = []
        for i in range(levels, 0, -1):  # decoder i produces scale 2**-(i-1)
            in_ch = enc_ch[-1] if i == levels else dec_ch[i]
            skip_ch = enc_ch[i - 2] if i > 1 else 0
            if i + 1 <= num_outputs:  # up-sampled weights of the next coarser output
                skip_ch += 3
            decoders.append(_Decoder(in_ch, dec_ch[i - 1], skip_ch, with_output=i <= num_outputs))
        self.decoders = nn.ModuleList(decoders)
        self.reset_parameters()

    @property
    def stride(self) -> int:
        """Input sides must be multiples of this."""
        return 2**self.levels

    def reset_parameters(self) -> None:
        """cs-stereo initialisation: Kaiming-normal weights, biases 1."""
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight)
                if m.bias is not None:
                    nn.init.constant_(m.bias, 1.0)

    def channel_weights(self, rgb: torch.Tensor) -> list[torch.Tensor]:
        """Per-pixel channel weights at every output scale.

        Args:
            rgb: ``(B, 3, H, W)`` linear, exposure-normalised RGB; ``H, W`` multiples of
                :attr:`stride`.

        Returns:
            ``num_outputs`` tensors ``(B, 3, H / 2**k, W / 2**k)``, ``k = 0, 1, ...``.
        """
        if rgb.ndim != 4 or rgb.shape[1] != 3:
            raise ValueError(f"rgb must be (B, 3, H, W), got {tuple(rgb.shape)}")
        h, w = rgb.shape[-2:]
        if h % self.stride or w % self.stride:
            raise ValueError(f"image sides {h}x{w} must be multiples of {self.stride}")
        feats = [rgb]
        for enc in self.encoders:
            feats.append(enc(feats[-1]))
        x = feats[-1]
        weights: list[torch.Tensor] = []
        coarser: torch.Tensor | None = None
        for dec, i in zip(self.decoders, range(self.levels, 0, -1), strict=True):
            size = tuple(feats[i - 1].shape[-2:])
            skips = [feats[i - 1]] if i > 1 else []
            if coarser is not None:
                skips.append(
                    F.interpolate(coarser, size=size, mode="bilinear", align_corners=False)
                )
            x, out = dec(x, torch.cat(skips, 1) if skips else None, size)
            if out is not None:
                weights.append(out)
                coarser = out
        return weights[::-1]

    def forward_pyramid(
        self, rgb: torch.Tensor, exposure_ratio: float | torch.Tensor = 1.0
    ) -> list[torch.Tensor]:
        """Pseudo-NIR at every output scale (finest first).

        Args:
            rgb: ``(B, 3, H, W)`` linear, exposure-normalised RGB.
            exposure_ratio: NIR/RGB exposure ratio, a float or ``(B,)`` tensor.

        Returns:
            ``num_outputs`` tensors ``(B, 1, H / 2**k, W / 2**k)``.
        """
        weights = self.channel_weights(rgb)
        rgbs = image_pyramid(rgb, len(weights))
        ratio = _as_ratio(exposure_ratio, rgb)
        return [(c * w).sum(1, keepdim=True) * ratio for c, w in zip(rgbs, weights, strict=True)]

    def forward(
        self, rgb: torch.Tensor, exposure_ratio: float | torch.Tensor = 1.0
    ) -> torch.Tensor:
        """Full-resolution pseudo-NIR ``(B, 1, H, W)`` from ``(B, 3, H, W)`` RGB."""
        w = self.channel_weights(rgb)[0]
        return (rgb * w).sum(1, keepdim=True) * _as_ratio(exposure_ratio, rgb)


def image_pyramid(image: torch.Tensor, n: int) -> list[torch.Tensor]:
    """Box-filtered pyramid: ``image`` and ``n - 1`` successive 2x2 average poolings.

    Args:
        image: ``(B, C, H, W)``, sides divisible by ``2**(n-1)``.
        n: number of levels.

    Returns:
        ``n`` tensors ``(B, C, H / 2**k, W / 2**k)``.
    """
    levels = [image]
    for _ in range(n - 1):
        levels.append(F.avg_pool2d(levels[-1], 2))
    return levels


def _as_ratio(ratio: float | torch.Tensor, like: torch.Tensor) -> torch.Tensor | float:
    if isinstance(ratio, torch.Tensor):
        return ratio.to(like).reshape(-1, 1, 1, 1)
    return float(ratio)
