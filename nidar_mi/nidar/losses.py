"""Losses of NIDAR (paper Sec. III-D) and of the STN; pure functions.

All images are ``(B, C, H, W)`` tensors; masks are ``(B, 1, H, W)`` bool or {0, 1} float.
"Mean" means the mean over every element unless stated otherwise.

Masked losses (L_int): per image, spatial sums are divided by the number of valid pixels
plus ``eps`` and the per-image values are averaged over the batch. Before any spatial
operation (down-sampling, SSIM windows) prediction and target are multiplied by the mask,
so values at unsupervised pixels never reach the loss. The target is zero there by the data
format, so this only removes the dense prediction's off-mask values, which would otherwise
leak into the bilinear pyramid and the SSIM windows.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = [
    "gain_offset_fit",
    "pearson_r",
    "photo_stn_loss",
    "SSIM_K1",
    "SSIM_K2",
    "SSIM_SIGMA",
    "SSIM_WINDOW",
    "gaussian_window",
    "ssim_map_torch",
    "stn_loss",
    "reconstruction_loss",
    "reflectance_smoothness_loss",
    "shading_prior_loss",
    "mean_reflectance_loss",
    "reflectance_supervision_loss",
    "shading_supervision_loss",
    "TRUE_REFLECTANCE_MIN",
    "masked_multiscale_l1",
    "masked_l2",
    "masked_ssim_loss",
    "intensity_loss",
    "linear_warmup",
    "irnet_objective",
]


SSIM_WINDOW = 11
"""Side of the Gaussian SSIM window (pixels)."""
SSIM_SIGMA = 1.5
"""Standard deviation of the Gaussian SSIM window (pixels)."""
SSIM_K1 = 0.01
"""SSIM luminance constant: ``C1 = (K1 L)^2``."""
SSIM_K2 = 0.03
"""SSIM contrast constant: ``C2 = (K2 L)^2``."""


def gaussian_window(
    size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA, dtype=torch.float32, device=None
):
    """Normalised 2-D Gaussian window ``(size, size)`` (sums to 1)."""
    g = _gaussian_1d(size, sigma, dtype, device)
    return g[:, None] * g[None, :]


def _gaussian_1d(size: int, sigma: float, dtype, device) -> torch.Tensor:
    x = torch.arange(size, dtype=dtype, device=device) - (size - 1) / 2
    g = torch.exp(-(x**2) / (2 * sigma**2))
    return g / g.sum()


def ssim_map_torch(
    x: torch.Tensor,
    y: torch.Tensor,
    window_size: int = SSIM_WINDOW,
    sigma: float = SSIM_SIGMA,
    data_range: float = 1.0,
    k1: float = SSIM_K1,
    k2: float = SSIM_K2,
) -> torch.Tensor:
    """Per-pixel SSIM (Wang et al., 2004): Gaussian window, renormalised at the image edge.

    The local means, variances and covariance are Gaussian-weighted population statistics.
    Near the border the window is cut at the image edge and its weights are renormalised to
    sum to 1, so the statistics use only pixels inside the image and the map keeps the
    input's size; where the window fits (``window_size // 2`` pixels and more from the edge)
    this is the reference formulation exactly. This is the one SSIM of the package: the
    training losses use it, and :func:`nidar_mi.eval.metrics.ssim_map` evaluates it in
    float64, so the loss and the reported metric agree at every pixel. The renormalised
    border (rather than padding the image with reflected or constant values) invents no
    image content, and works for any image size. Differentiable in ``x`` and ``y``.

    Args:
        x, y: ``(B, C, H, W)`` images, any ``H, W >= 1``.
        window_size, sigma: Gaussian window (odd side, pixels).
        data_range: dynamic range ``L``; ``C1 = (k1 L)^2``, ``C2 = (k2 L)^2``.

    Returns:
        ``(B, C, H, W)`` SSIM map in [-1, 1], 1 where the windows agree exactly.
    """
    if x.shape != y.shape or x.ndim != 4:
        raise ValueError(f"x and y must be equal (B, C, H, W), got {x.shape} and {y.shape}")
    if window_size < 1 or window_size % 2 == 0:
        raise ValueError(f"window_size must be a positive odd number, got {window_size}")
    c, (h, w) = x.shape[1], x.shape[-2:]
    g = _gaussian_1d(window_size, sigma, x.dtype, x.device)
    pad = window_size // 2
    # window weight inside the image, per row and per column (the window is separable)
    norm_h = F.conv1d(x.new_ones(1, 1, h), g.view(1, 1, -1), padding=pad).view(h, 1)
    norm_w = F.conv1d(x.new_ones(1, 1, w), g.view(1, 1, -1), padding=pad).view(1, w)
    norm = norm_h * norm_w

    def local_mean(*maps: torch.Tensor) -> list[torch.Tensor]:
        t = torch.cat(maps, 1)  # zero padding: the weights outside the image are dropped
        k = t.shape[1]
        t = F.conv2d(t, g.view(1, 1, 1, -1).expand(k, 1, 1, -1), padding=(0, pad), groups=k)
        t = F.conv2d(t, g.view(1, 1, -1, 1).expand(k, 1, -1, 1), padding=(pad, 0), groups=k)
        return list((t / norm).split(c, 1))

    mu_x, mu_y, exx, eyy, exy = local_mean(x, y, x * x, y * y, x * y)
    sxx = exx - mu_x**2
    syy = eyy - mu_y**2
    sxy = exy - mu_x * mu_y
    c1, c2 = (k1 * data_range) ** 2, (k2 * data_range) ** 2
    num = (2 * mu_x * mu_y + c1) * (2 * sxy + c2)
    den = (mu_x**2 + mu_y**2 + c1) * (sxx + syy + c2)
    return num / den


def stn_loss(
    preds: list[torch.Tensor], targets: list[torch.Tensor], alpha: float = 0.85
) -> torch.Tensor:
    """Photometric loss of the STN, summed over pyramid scales.

    Per scale: ``alpha * mean((1 - SSIM) / 2) + (1 - alpha) * mean|pred - target|`` (the
    photometric term of cs-stereo; the SSIM term is skipped at scales smaller than its
    window).

    Args:
        preds, targets: equally long lists of ``(B, 1, h, w)`` tensors.
    """
    total = preds[0].new_zeros(())
    for p, t in zip(preds, targets, strict=True):
        l1 = (p - t).abs().mean()
        if min(p.shape[-2:]) > 5:
            total = total + alpha * ((1 - ssim_map_torch(p, t)) / 2).mean() + (1 - alpha) * l1
        else:
            total = total + l1
    return total


def gain_offset_fit(pred: torch.Tensor, target: torch.Tensor, eps: float = 1e-8) -> torch.Tensor:
    """``a · pred + b`` with the per-image least-squares ``a, b`` against ``target``.

    Args:
        pred, target: ``(B, 1, H, W)``.

    Returns:
        ``(B, 1, H, W)``: ``pred`` mapped onto ``target``'s gain and offset.
    """
    pm, tm = pred.mean((2, 3), keepdim=True), target.mean((2, 3), keepdim=True)
    cov = ((pred - pm) * (target - tm)).mean((2, 3), keepdim=True)
    var = ((pred - pm) ** 2).mean((2, 3), keepdim=True)
    return cov / (var + eps) * (pred - pm) + tm


def pearson_r(pred: torch.Tensor, target: torch.Tensor, eps: float = 1e-8) -> torch.Tensor:
    """``(B,)`` Pearson correlation of each image pair over its pixels (``(B, 1, H, W)``)."""
    pm, tm = pred.mean((2, 3), keepdim=True), target.mean((2, 3), keepdim=True)
    cov = ((pred - pm) * (target - tm)).mean((1, 2, 3))
    sp = ((pred - pm) ** 2).mean((1, 2, 3)).add(eps).sqrt()
    st = ((target - tm) ** 2).mean((1, 2, 3)).add(eps).sqrt()
    return cov / (sp * st)


def photo_stn_loss(
    pred: torch.Tensor, target: torch.Tensor, ssim_weight: float = 0.5
) -> torch.Tensor:
    """Pseudo-NIR against a real NIR photo, blind to the camera's gain and offset.

    ``mean(1 - r) + ssim_weight · mean(1 - SSIM(a · pred + b, target))``: Pearson ``r`` per
    crop, and SSIM after the per-crop least-squares gain and offset
    (:func:`gain_offset_fit`) — exactly the two numbers the photo evaluation reports
    (:mod:`nidar_mi.eval.photos`), since the NIR camera's exposure and black level are unknown.

    Args:
        pred, target: ``(B, 1, H, W)`` (``target`` linear NIR, any scale).
        ssim_weight: weight of the SSIM term.
    """
    r = pearson_r(pred, target)
    fitted = gain_offset_fit(pred, target)
    return (1.0 - r).mean() + ssim_weight * (1.0 - ssim_map_torch(fitted, target)).mean()


def reconstruction_loss(r: torch.Tensor, s: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
    """L_recon = mean |R * S - I|."""
    return (r * s - image).abs().mean()


def reflectance_smoothness_loss(
    r: torch.Tensor, image: torch.Tensor, gamma: float = 10.0
) -> torch.Tensor:
    """L_R = E[w_x |d_x R|] + E[w_y |d_y R|], ``w = exp(-gamma |d I|)``.

    ``d_x`` and ``d_y`` are forward differences; the expectations run over the
    ``(H, W - 1)`` and ``(H - 1, W)`` difference grids. ``I`` may have several channels; its
    absolute differences are averaged over them.
    """
    gx = (image[..., :, 1:] - image[..., :, :-1]).abs().mean(1, keepdim=True)
    gy = (image[..., 1:, :] - image[..., :-1, :]).abs().mean(1, keepdim=True)
    rx = (r[..., :, 1:] - r[..., :, :-1]).abs()
    ry = (r[..., 1:, :] - r[..., :-1, :]).abs()
    return (torch.exp(-gamma * gx) * rx).mean() + (torch.exp(-gamma * gy) * ry).mean()


def shading_prior_loss(s: torch.Tensor, kernel_size: int = 5) -> torch.Tensor:
    """L_S = mean |S - AvgPool(S)| (stride 1, same size, borders average valid pixels only)."""
    pooled = F.avg_pool2d(s, kernel_size, 1, kernel_size // 2, count_include_pad=False)
    return (s - pooled).abs().mean()


def mean_reflectance_loss(r: torch.Tensor, m0: float = 0.5) -> torch.Tensor:
    """L_med = |mean(R) - m0|, the mean taken per image, the result averaged over the batch."""
    return (r.flatten(1).mean(1) - m0).abs().mean()


TRUE_REFLECTANCE_MIN = 1e-3
"""Pixels whose true reflectance is below this hold no surface (sky) or an undefined shading;
the supervised intrinsic terms leave them out (the frame format's own threshold for
``S_true``)."""


def _true_mask(r_true: torch.Tensor) -> torch.Tensor:
    return (r_true >= TRUE_REFLECTANCE_MIN).to(r_true.dtype)


def reflectance_supervision_loss(
    r: torch.Tensor, r_true: torch.Tensor, eps: float = 1e-6
) -> torch.Tensor:
    """``sum(M |R - R_true|) / (sum M + eps)`` per image, averaged over the batch.

    ``M``: pixels with ``R_true >= TRUE_REFLECTANCE_MIN``. ``R`` lies in [0, 1] and
    ``R_true`` (the renderer's monostatic reflectance at the LiDAR wavelength) is clipped to
    [0, 1] first: retroreflectors and specular peaks exceed 1 by up to several hundred, and
    are clipped like the intensity target. The term is absolute: it pins the decomposition's
    scale as well as its pattern.
    """
    m = _true_mask(r_true)
    num = (m * (r - r_true.clamp(0.0, 1.0)).abs()).flatten(1).sum(1)
    return (num / (m.flatten(1).sum(1) + eps)).mean()


def shading_supervision_loss(
    s: torch.Tensor, s_true: torch.Tensor, r_true: torch.Tensor, eps: float = 1e-6
) -> torch.Tensor:
    """Scale-invariant log-L1 between ``S`` and the true shading.

    ``d = log(S + δ) - log(S_true + δ)`` (``δ = 1e-3``) on the pixels ``M`` of
    :func:`reflectance_supervision_loss`; the term is ``sum(M |d - mean_M(d)|) / sum M`` per
    image: a per-image gain on ``S + δ`` costs nothing, and on ``S`` nearly nothing where
    ``S ≫ δ`` (the network's input is exposure-normalised, so only the pattern of the shading is
    defined: cast shadows, incidence).
    """
    m = _true_mask(r_true)
    d = torch.log(s + 1e-3) - torch.log(s_true.clamp_min(0) + 1e-3)
    n = m.flatten(1).sum(1) + eps
    mean_d = (m * d).flatten(1).sum(1) / n
    num = (m * (d - mean_d.view(-1, 1, 1, 1)).abs()).flatten(1).sum(1)
    return (num / n).mean()


def _masked(pred, target, mask):
    m = mask.to(pred.dtype)
    return pred * m, target * m, m


def masked_multiscale_l1(
    pred: torch.Tensor,
    target: torch.Tensor,
    mask: torch.Tensor,
    scales=(1.0, 0.5, 0.25),
    eps: float = 1e-6,
) -> torch.Tensor:
    """L1^ms = (1/|S|) sum_s ||M_s * E_s||_1 / (||M_s||_1 + eps).

    ``E_s = D_s(M pred) - D_s(M target)`` with bilinear ``D_s`` and ``M_s`` the nearest
    down-sampled mask; the output size at scale ``s`` is ``floor(s H) x floor(s W)``.
    """
    p, t, m = _masked(pred, target, mask)
    total = pred.new_zeros(())
    for s in scales:
        if s != 1.0:
            size = (int(pred.shape[-2] * s), int(pred.shape[-1] * s))
            ps = F.interpolate(p, size=size, mode="bilinear", align_corners=False)
            ts = F.interpolate(t, size=size, mode="bilinear", align_corners=False)
            ms = F.interpolate(m, size=size, mode="nearest")
        else:
            ps, ts, ms = p, t, m
        num = (ms * (ps - ts).abs()).flatten(1).sum(1)
        den = ms.flatten(1).sum(1) * ps.shape[1] + eps
        total = total + (num / den).mean()
    return total / len(scales)


def masked_l2(
    pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, eps: float = 1e-6
) -> torch.Tensor:
    """L2 = ||M * E||_2^2 / (||M||_1 + eps)."""
    p, t, m = _masked(pred, target, mask)
    num = ((p - t) ** 2).flatten(1).sum(1)
    return (num / (m.flatten(1).sum(1) * p.shape[1] + eps)).mean()


def masked_ssim_loss(
    pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, eps: float = 1e-6
) -> torch.Tensor:
    """L_SSIM = 1 - sum(M * SSIM_map(M pred, M target)) / (||M||_1 + eps)."""
    p, t, m = _masked(pred, target, mask)
    smap = ssim_map_torch(p, t)
    num = (m * smap).flatten(1).sum(1)
    return (1 - num / (m.flatten(1).sum(1) * p.shape[1] + eps)).mean()


def intensity_loss(
    pred: torch.Tensor,
    target: torch.Tensor,
    mask: torch.Tensor,
    w1: float = 1.0,
    w2: float = 0.5,
    w_ssim: float = 0.2,
    scales=(1.0, 0.5, 0.25),
    eps: float = 1e-6,
) -> torch.Tensor:
    """L_int = w1 L1^ms + w2 L2 + w_ssim L_SSIM (all masked)."""
    return (
        w1 * masked_multiscale_l1(pred, target, mask, scales, eps)
        + w2 * masked_l2(pred, target, mask, eps)
        + w_ssim * masked_ssim_loss(pred, target, mask, eps)
    )


def linear_warmup(step: int, warmup_steps: float) -> float:
    """Factor ``min(1, (step + 1) / warmup_steps)`` of a linear warm-up (1 without warm-up)."""
    if warmup_steps <= 0:
        return 1.0
    return min(1.0, (step + 1) / warmup_steps)


def irnet_objective(
    outputs: dict[str, torch.Tensor],
    image: torch.Tensor,
    target: torch.Tensor,
    mask: torch.Tensor,
    cfg,
    int_factor: float = 1.0,
    r_true: torch.Tensor | None = None,
    s_true: torch.Tensor | None = None,
) -> tuple[torch.Tensor, dict[str, float]]:
    """Total IRNet loss (paper Eq. 8) and its terms, plus the supervised intrinsic terms on
    rendered frames.

    Args:
        outputs: ``R``, ``S``, ``I_hat``, each ``(B, 1, H, W)``.
        image: ``(B, 1, H, W)`` image the decomposition explains.
        target: ``(B, 1, H, W)`` sparse LiDAR intensity (0 off-mask).
        mask: ``(B, 1, H, W)`` valid projected pixels.
        cfg: a :class:`nidar_mi.nidar.config.LossConfig`.
        int_factor: warm-up factor applied to ``lambda_int``.
        r_true, s_true: ``(B, 1, H, W)`` true reflectance and shading of rendered frames;
            required when ``cfg.lambda_r_true`` or ``cfg.lambda_s_true`` is positive.

    Returns:
        The scalar loss and a dict of the unweighted terms (``recon``, ``R``, ``S``, ``med``,
        ``int``, and ``R_true`` / ``S_true`` when their weights are positive) as floats.
    """
    r, s, i_hat = outputs["R"], outputs["S"], outputs["I_hat"]
    terms = {
        "recon": reconstruction_loss(r, s, image),
        "R": reflectance_smoothness_loss(r, image, cfg.gamma),
        "S": shading_prior_loss(s, cfg.shading_pool),
        "med": mean_reflectance_loss(r, cfg.m0),
        "int": intensity_loss(i_hat, target, mask, cfg.w1, cfg.w2, cfg.w_ssim, cfg.scales, cfg.eps),
    }
    total = (
        cfg.lambda_recon * terms["recon"]
        + cfg.lambda_r * terms["R"]
        + cfg.lambda_s * terms["S"]
        + cfg.lambda_med * terms["med"]
        + cfg.lambda_int * int_factor * terms["int"]
    )
    if cfg.lambda_r_true > 0 or cfg.lambda_s_true > 0:
        if r_true is None or s_true is None:
            raise ValueError("supervised intrinsic terms need r_true and s_true")
    if cfg.lambda_r_true > 0:
        terms["R_true"] = reflectance_supervision_loss(r, r_true, cfg.eps)
        total = total + cfg.lambda_r_true * terms["R_true"]
    if cfg.lambda_s_true > 0:
        terms["S_true"] = shading_supervision_loss(s, s_true, r_true, cfg.eps)
        total = total + cfg.lambda_s_true * terms["S_true"]
    return total, {k: float(v.detach()) for k, v in terms.items()}
