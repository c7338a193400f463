"""How well an image value ranks the true LiDAR-wavelength reflectance, and what the image adds.

On rendered frames (:mod:`nidar_mi.dataset`, ``source`` ``render``) two numbers per value source:

* **cue**: Spearman of the value at the LiDAR returns against the true reflectance ρ(λ) there
  (the frame's sparse ``reflectance`` map, on its ``mask`` pixels): per frame (mean) and over
  every return of every frame (pooled). That ρ is π·f_r(ω, ω) along the beam, so the gloss of
  paint, the opposition surge of rough asphalt and concrete and the incidence are in it; frames
  rendered with the albedo maps also carry ``R_surface``, the surface's own diffuse reflectance
  at λ, and every cue is scored against it too (``surface_per_frame``, ``surface_pooled``): what
  a per-surface cue can know. Sources: the camera's luminance (Rec. 709 of the linear RGB), the
  STN's pseudo-NIR, the R map of each NIDAR weights folder, all at the frame's own resolution
  (``scale`` 1), and on frames with ``A_true`` the earthlib colour map of the true albedo colour
  (:func:`~nidar_mi.materials.visible_albedo.colour_reflectance_map`: what the visible colour
  could tell with the shading perfectly removed).
* **image gain** (NIDAR weights only): a ``gbm`` profile of R and the incidence ``|cos θ|``
  (the form of ``sim-905``; the incidence estimated from each scan's points,
  :func:`nidar_mi.geometry.incidence_cosine`) is fitted on the returns of the training frames;
  on the test frames its intensity is scored (Spearman against the rendered intensity) once
  with R of the real camera image and once with R of a uniform grey image of the same size
  through the same profile. The gain is the difference: what the image contributes beyond the
  geometry.
* **truth gain** (``--truth-gain KEY,...``): the image gain's ceiling. The same profile form
  fitted with a rendered truth map at the returns in place of R (``R_surface``: a per-surface
  cue without error; ``reflectance``: the monostatic ρ the intensity is made of; ``R_true``:
  the dense monostatic ρ·T² along the camera ray), scored on the test frames against the same
  form fitted on a constant value (the incidence alone): what no cue of that kind can exceed
  under this protocol (the returns' nearest pixels, the sensor's noise, ray drop and per-laser
  gains, the estimated incidence).

The command ``python -m nidar_mi.reflectance_cue`` (:mod:`nidar_mi.cli.reflectance_cue`) runs
them on datasets and writes every number as JSON.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import NidarError
from ..io.images import REC709_LUMA, srgb_to_linear
from ..training_frames import frame_has, list_frames, load_frame
from .metrics import spearman

__all__ = [
    "GREY_LEVEL",
    "TRUTH_KEYS",
    "dataset_frames",
    "frame_returns",
    "image_gain",
    "luminance",
    "score_cues",
    "truth_gain",
]

#: 8-bit sRGB level of the uniform grey image of the image-gain test.
GREY_LEVEL = 128
_FRAME_KEYS = ("rgb", "reflectance", "mask", "K", "T_cam_lidar", "points_xyz", "points_intensity")
#: The truth maps :func:`truth_gain` can put in R's place.
TRUTH_KEYS = ("reflectance", "R_surface", "R_true")


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance ``(H, W)`` float32 of the linear RGB of 8-bit sRGB ``(H, W, 3)``."""
    lin = srgb_to_linear(rgb.astype(np.float32) / np.float32(255.0))
    return (lin @ np.asarray(REC709_LUMA, np.float32)).astype(np.float32)


def frame_returns(frame: dict) -> dict[str, np.ndarray]:
    """The frame's returns with their pixel, range, incidence and intensity.

    Returns:
        ``rows``, ``cols`` (N,) int nearest pixels (clipped to the image), ``range`` (N,) m,
        ``cos`` (N,) estimated ``|cos θ|``, ``intensity`` (N,) the rendered intensity.
    """
    from ..geometry import incidence_cosine

    xyz = frame["points_xyz"].astype(np.float64)
    p = xyz @ frame["T_cam_lidar"][:3, :3].T + frame["T_cam_lidar"][:3, 3]
    uvw = p @ frame["K"].T
    z = np.maximum(uvw[:, 2], 1e-9)
    h, w = frame["mask"].shape
    cols = np.clip(np.rint(uvw[:, 0] / z), 0, w - 1).astype(np.int64)
    rows = np.clip(np.rint(uvw[:, 1] / z), 0, h - 1).astype(np.int64)
    return {
        "rows": rows,
        "cols": cols,
        "range": np.linalg.norm(xyz, axis=1),
        "cos": incidence_cosine(xyz),
        "intensity": frame["points_intensity"].astype(np.float64),
    }


def _nanmean(values: list[float]) -> float:
    finite = [v for v in values if np.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def _maps(models: dict, rgb: np.ndarray, stn) -> dict[str, np.ndarray]:
    """Every value source's ``(H, W)`` map of one image."""
    from ..nidar.infer import predict, pseudo_nir

    maps = {"luminance": luminance(rgb)}
    if stn is not None:
        maps["pseudo_nir"] = pseudo_nir(stn, rgb)
    for name, (m_stn, irnet) in models.items():
        maps[f"R:{name}"] = predict(m_stn, irnet, rgb)["R"]
    return maps


def _truth_maps(path: Path, wavelength_nm: float) -> dict[str, np.ndarray]:
    """Ceilings a cue could reach, from the frame's true maps where it carries them: the ρ(λ)
    its true albedo colour predicts through the earthlib map."""
    from ..training_frames import frame_has

    if not frame_has(path, ("A_true",)):
        return {}
    from ..materials.visible_albedo import colour_reflectance_map

    a_true = load_frame(path, ("A_true",))["A_true"]
    return {
        "true albedo colour -> rho (earthlib map)": colour_reflectance_map(wavelength_nm)(a_true)
    }


def score_cues(
    frames: list[Path], models: dict, stn=None, wavelength_nm: float = 905.0
) -> dict[str, dict[str, float]]:
    """Spearman of each source's value against ρ at the returns (module docstring).

    Two truths: the frame's sparse ``reflectance`` (ρ = π·f_r(ω, ω) along each beam: gloss,
    opposition surge and incidence included) and, on frames that carry it, ``R_surface`` at the
    same pixels (the surface's own diffuse reflectance at λ, what a per-surface cue can know).

    Args:
        frames: rendered frame files.
        models: ``{name: (stn or None, irnet)}``.
        stn: the STN whose pseudo-NIR is scored as a source (None: not scored).
        wavelength_nm: the frames' LiDAR wavelength (the colour map's λ).

    Returns:
        ``{source: {"per_frame": mean Spearman, "pooled": Spearman over all returns}}`` against
        ρ, plus ``"surface_per_frame"`` and ``"surface_pooled"`` against ``R_surface`` when
        every frame has it. Sources: ``luminance``, ``pseudo_nir``, ``R:<name>``, and on frames
        with ``A_true`` the earthlib colour map of the true albedo (a ceiling).
    """
    from ..training_frames import frame_has

    surface = all(frame_has(p, ("R_surface",)) for p in frames)
    truths = ("reflectance", "R_surface") if surface else ("reflectance",)
    per: dict[tuple[str, str], list[float]] = {}
    pooled: dict[str, list[np.ndarray]] = {}
    truth_all: dict[str, list[np.ndarray]] = {t: [] for t in truths}
    for path in frames:
        f = load_frame(path, ("rgb", "mask", *truths))
        m = f["mask"]
        maps = _maps(models, f["rgb"], stn) | _truth_maps(path, wavelength_nm)
        for t in truths:
            truth = f[t][m].astype(np.float64)
            truth_all[t].append(truth)
            for name, v in maps.items():
                per.setdefault((name, t), []).append(spearman(v[m], truth))
        for name, v in maps.items():
            pooled.setdefault(name, []).append(v[m].astype(np.float64))
    out = {}
    for name, values in pooled.items():
        v = np.concatenate(values)
        for t, prefix in zip(truths, ("", "surface_")):
            out.setdefault(name, {})[f"{prefix}per_frame"] = _nanmean(per[(name, t)])
            out[name][f"{prefix}pooled"] = spearman(v, np.concatenate(truth_all[t]))
    return out


def _returns_with_r(frames: list[Path], stn, irnet, grey: bool) -> dict[str, np.ndarray]:
    """Returns of ``frames`` with R sampled at them (of the grey image when ``grey``), and the
    frame index of each return."""
    from ..nidar.infer import predict

    def r_map(f: dict) -> np.ndarray:
        rgb = np.full_like(f["rgb"], GREY_LEVEL) if grey else f["rgb"]
        return predict(stn, irnet, rgb)["R"]

    return _returns_with(frames, r_map, _FRAME_KEYS)


def _returns_with(frames: list[Path], value_map, keys) -> dict[str, np.ndarray]:
    """Returns of ``frames`` (loaded with ``keys``) with ``value_map(frame)``, an (H, W) map,
    sampled at their nearest pixels as ``R``, and the frame index of each return."""
    parts: dict[str, list[np.ndarray]] = {}
    for k, path in enumerate(frames):
        f = load_frame(path, keys)
        ret = frame_returns(f)
        ret["R"] = value_map(f)[ret["rows"], ret["cols"]].astype(np.float64)
        ret["frame"] = np.full(len(ret["R"]), k)
        for key, v in ret.items():
            parts.setdefault(key, []).append(v)
    return {k: np.concatenate(v) for k, v in parts.items()}


def _profile_scores(profile, ret: dict[str, np.ndarray]) -> dict[str, float]:
    pred = profile(ret["R"], ret["range"], cos_incidence=ret["cos"])
    frames = np.unique(ret["frame"])
    per = [spearman(pred[ret["frame"] == k], ret["intensity"][ret["frame"] == k]) for k in frames]
    return {"per_frame": _nanmean(per), "pooled": spearman(pred, ret["intensity"])}


def image_gain(train: list[Path], test: list[Path], stn, irnet) -> dict[str, dict[str, float]]:
    """Spearman of the profile's intensity with the real and the grey image, and the gain.

    The ``gbm`` profile of R and ``|cos θ|`` is fitted on the returns of ``train`` (real
    images); the reference is the rendered intensity clipped to [0, 1].

    Returns:
        ``{"image": {...}, "grey": {...}, "gain": {...}}``, each ``{"per_frame", "pooled"}``.
    """
    from ..profiles import fit

    fit_ = _returns_with_r(train, stn, irnet, grey=False)
    ref = np.clip(fit_["intensity"], 0.0, 1.0)
    profile = fit(
        "gbm", fit_["R"], fit_["range"], ref, cos_incidence=fit_["cos"], use_geometry=False
    )
    image = _profile_scores(profile, _returns_with_r(test, stn, irnet, grey=False))
    grey = _profile_scores(profile, _returns_with_r(test, stn, irnet, grey=True))
    gain = {k: image[k] - grey[k] for k in image}
    return {"image": image, "grey": grey, "gain": gain}


def truth_gain(train: list[Path], test: list[Path], key: str) -> dict[str, dict[str, float]]:
    """The image gain's ceiling (module docstring): the ``gbm`` profile of :func:`image_gain`
    fitted with the truth map ``key`` at the training returns in place of R, and fitted on a
    constant value (the incidence alone); both scored on the test returns.

    Returns:
        ``{"truth": {...}, "geometry": {...}, "gain": {...}}``, each ``{"per_frame",
        "pooled"}`` Spearman against the rendered intensity (the gain: truth minus geometry).

    Raises:
        NidarError: ``key`` not one of :data:`TRUTH_KEYS`, or a frame without it.
    """
    from ..profiles import fit

    if key not in TRUTH_KEYS:
        raise NidarError(f"truth gain: the truth is one of {', '.join(TRUTH_KEYS)}, not {key!r}")
    missing = [p.name for p in (*train, *test) if not frame_has(p, (key,))]
    if missing:
        raise NidarError(f"truth gain: {len(missing)} frame(s) have no {key!r} (e.g. {missing[0]})")
    keys = tuple(dict.fromkeys((*_FRAME_KEYS, key)))
    fit_ = _returns_with(train, lambda f: f[key], keys)
    test_ = _returns_with(test, lambda f: f[key], keys)
    ref = np.clip(fit_["intensity"], 0.0, 1.0)
    scores = {}
    for name, const in (("truth", False), ("geometry", True)):
        values = np.zeros_like(fit_["R"]) if const else fit_["R"]
        profile = fit(
            "gbm", values, fit_["range"], ref, cos_incidence=fit_["cos"], use_geometry=False
        )
        ret = test_ | {"R": np.zeros_like(test_["R"])} if const else test_
        scores[name] = _profile_scores(profile, ret)
    scores["gain"] = {k: scores["truth"][k] - scores["geometry"][k] for k in scores["truth"]}
    return scores


def dataset_frames(data: str, splits=("train", "val", "test")) -> list[Path]:
    """The frame files of a dataset folder's ``splits``.

    Raises:
        NidarError: the splits hold no frame.
    """
    frames = [f for s in splits for f in list_frames(data, s)]
    if not frames:
        raise NidarError(f"no frames in {data}")
    return frames
