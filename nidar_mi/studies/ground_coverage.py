"""Ground coverage per ring: a simulated flat road against real KITTI HDL-64E frames.

A real HDL-64E S2 on a flat road returns each laser's ground in a narrow band of range around
the laser's flat-ground intersection, and keeps detecting asphalt at grazing incidence out to
about 50 m. This module measures both sides the same way, per ring (0 = highest laser):

* **real** (:func:`kitti_ground_rings`): KITTI frames read from a user path (never copied);
  the ring of every point from the storage order and the road plane by RANSAC
  (:mod:`nidar_mi.datasets.kitti_rings`); ground = within 0.2 m of the plane or grown outward
  from it along each azimuth (:func:`nidar_mi.datasets.kitti_rings.grow_ground`). The range of
  a point is its distance from the sensor origin, ``|xyz|``. ``P(detect)`` of ring r is
  conditional on the road being visible: of the ground returns of the next lower ring r+1, the
  fraction at whose azimuth ring r also returned ground (ring r returning something else there,
  a car or a kerb, is left out; returning nothing is a miss). It is a lower bound where the road
  ends or rises out of view. Each frame also gives the sensor's pose over its road plane
  (height and tilt, :func:`nidar_mi.datasets.kitti_rings.pose_over_plane`) and whether the
  sweep was cut to the front half (x > 0).
* **simulated** (:func:`simulate_flat_road`): a LiDAR preset over an endless flat road of one
  material, scanned by the real ``lidar`` plugin, either level at the KITTI rig's 1.73 m or,
  frame by frame, at the pose a real frame measured (the road is still a plane: only the car's
  height and attitude over it are taken from the frame; nothing of the sensor). Ranges are
  ``|xyz|`` as on the real side, and so is ``P(detect)`` of a ring: of the columns where ring
  r+1 returned the road, the fraction where ring r did too. Every beam that met the road is also
  counted by its range (:attr:`RingCoverage.range_hits`), so that ``P(detect)`` of the simulated
  road at any range can be read whatever the ring (:meth:`RingCoverage.p_at_range`).

:func:`compare_rings` puts them side by side, per ring: the median and 90th percentile of the
ground range, real and simulated, and ``P(detect)``. The ground-range criterion: a ring
**matches** when both its simulated median and 90th percentile lie within 10 % of the real ones;
rings are compared where the real frames hold at least 50 ground returns of that ring per frame
(:data:`MIN_GROUND_PER_FRAME`). ``P(detect)`` agrees when the simulated road's ``P(detect)`` at
the ring's real median range (the detection model alone) is within 0.1 (absolute) of the real
ring's, where that rests on at least 200 references; the same ring's simulated ``P(detect)`` is
compared too (it mixes in where the ring meets the road). :func:`summarize` counts the rings.
:func:`target_detection_scanned` measures the fraction of beams a Lambertian target at normal
incidence returns at a range, :func:`target_reach_scanned` how far it is reported without
receiver noise.
"""

from __future__ import annotations

import glob
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import NidarError

__all__ = [
    "RingCoverage",
    "flat_road_scene_xml",
    "simulate_flat_road",
    "kitti_ground_rings",
    "compare_rings",
    "summarize",
    "target_detection_scanned",
    "target_reach_scanned",
    "LAMBERTIAN_ASPHALT",
    "ROUGH_ASPHALT",
    "MIN_GROUND_PER_FRAME",
    "MIN_REFERENCES",
    "TOLERANCE",
    "RANGE_BINS_M",
    "SENSOR_HEIGHT_M",
]

#: The road of the old model: Lambertian asphalt_old (its earthlib spectrum).
LAMBERTIAN_ASPHALT = "lambertian:asphalt_old"
#: The library's asphalt_old: roughdiffuse (nidar_mi.lidar.link_budget).
ROUGH_ASPHALT = "asphalt_old"
#: Height of the simulated sensor over the road, m (KITTI's Velodyne).
SENSOR_HEIGHT_M = 1.73
#: A ring's ground ranges are compared where the real frames hold at least this many of its
#: ground returns per frame (about 5 % of a 2000-column sweep).
MIN_GROUND_PER_FRAME = 50
#: A ring's P(detect) is compared where its real estimate rests on at least this many references.
MIN_REFERENCES = 200
#: Relative tolerance on the median and 90th percentile; absolute tolerance on P(detect).
TOLERANCE = 0.10
#: Edges of the range bins (m) in which a simulated coverage counts the beams that met the
#: road and those reported (1 % wide, 1-300 m).
RANGE_BINS_M = np.geomspace(1.0, 300.0, int(np.ceil(np.log(300.0) / np.log(1.01))) + 1)


@dataclass
class RingCoverage:
    """Ground returns per ring (R rings).

    Attributes:
        ranges: per ring, (n_r,) float64 ranges ``|xyz|`` (m) of its ground returns.
        detected: (R,) int, beams (sim) or references (real) where the ground was reported.
        missed: (R,) int, where it was visible but not reported.
        frames: how many sweeps were pooled.
        flat_range_m: (R,) where each ring meets flat ground from the nominal pose (simulated;
            ``inf`` where it does not), or None (real).
        poses: (F, 4, 4) the sensor's pose in its road's frame (road = the plane z = 0) per
            frame (real), or the poses scanned (simulated).
        front_only: (F,) bool, the sweep holds only the front half (x > 0).
        range_hits: (B,) int, simulated only: beams that met the road, per bin of range
            (:data:`RANGE_BINS_M`, whatever their ring), or None.
        range_detected: (B,) int, of those, the beams reported, or None.
    """

    ranges: list[np.ndarray]
    detected: np.ndarray
    missed: np.ndarray
    frames: int
    flat_range_m: np.ndarray | None = None
    poses: np.ndarray | None = None
    front_only: np.ndarray | None = None
    range_hits: np.ndarray | None = None
    range_detected: np.ndarray | None = None

    def p_at_range(self, range_m: np.ndarray, *, window: float = 0.05) -> np.ndarray:
        """``P(detect)`` of the simulated road at each of ``range_m`` (simulated coverage only):
        the fraction of beams reported among those that met the road within ``±window``
        (relative) of that range, whatever their ring: the detection model alone. NaN where
        fewer than 50 beams met the road there.

        Args:
            range_m: (N,) ranges, m.
            window: half width of the range window, relative.
        """
        if self.range_hits is None or self.range_detected is None:
            raise ValueError("p_at_range needs a simulated coverage")
        d = np.asarray(range_m, dtype=np.float64)
        lo = np.searchsorted(RANGE_BINS_M, d / (1.0 + window), side="right") - 1
        hi = np.searchsorted(RANGE_BINS_M, d * (1.0 + window), side="left")
        hits = np.concatenate([[0], np.cumsum(self.range_hits)])
        det = np.concatenate([[0], np.cumsum(self.range_detected)])
        lo = np.clip(lo, 0, len(self.range_hits))
        hi = np.clip(hi, 0, len(self.range_hits))
        n, k = hits[hi] - hits[lo], det[hi] - det[lo]
        return np.where(n >= 50, k / np.maximum(n, 1), np.nan)

    @property
    def p_detect(self) -> np.ndarray:
        """(R,) detected / (detected + missed); NaN where there is no reference."""
        total = self.detected + self.missed
        return np.where(total > 0, self.detected / np.maximum(total, 1), np.nan)

    @property
    def counts(self) -> np.ndarray:
        """(R,) int ground returns per ring."""
        return np.array([len(r) for r in self.ranges], dtype=np.int64)

    def percentile(self, q: float) -> np.ndarray:
        """(R,) the ``q``-th percentile of the ground range per ring (m); NaN where a ring has
        none."""
        return np.array([np.percentile(r, q) if len(r) else np.nan for r in self.ranges])

    def medians(self) -> np.ndarray:
        """(R,) median ground range per ring (m); NaN where a ring has none."""
        return self.percentile(50.0)


def _road_bsdf(material: str) -> str:
    if material.startswith("lambertian:"):
        from ..materials import reflectance
        from ..materials.spectra import GRID_NM

        name = material.split(":", 1)[1]
        rho = reflectance(name, GRID_NM)
        pairs = ", ".join(f"{w:g}:{v:.6g}" for w, v in zip(GRID_NM, rho))
        return f'<bsdf type="diffuse" id="road_mat"><spectrum name="reflectance" value="{pairs}"/></bsdf>'
    return (
        f'<bsdf type="nidar_material" id="road_mat"><string name="name" value="{material}"/></bsdf>'
    )


def flat_road_scene_xml(
    preset: str,
    material: str,
    *,
    height_m: float = SENSOR_HEIGHT_M,
    cols: int | None = None,
    threshold: float | None = None,
    noise: float | None = None,
    layout: str | None = None,
    calibration_file: str | os.PathLike | None = None,
) -> str:
    """Scene XML: ``preset`` at ``height_m`` over a 4 km flat road of ``material``.

    Args:
        preset: LiDAR preset.
        material: a library material name, or ``lambertian:<name>`` for a Lambertian road with
            that material's reflectance spectrum.
        height_m: sensor height above the road.
        cols: columns per sweep (preset's when None).
        threshold: detection threshold (the preset's when None).
        noise: receiver noise ``receiver_noise_std`` (the preset's when None).
        layout: ``uniform`` or ``per_laser`` (the preset's default when None).
        calibration_file: a per-laser calibration file (absolute path) to cast instead.
    """
    lines = [
        '<scene version="3.0.0">',
        '  <sensor type="lidar" id="lidar">',
        f'    <string name="preset" value="{preset}"/>',
        '    <float name="range_max" value="120"/>',
    ]
    if layout is not None:
        lines.append(f'    <string name="layout" value="{layout}"/>')
    if calibration_file is not None:
        path = os.path.abspath(os.fspath(calibration_file))
        lines.append(f'    <string name="calibration_file" value="{path}"/>')
    if cols is not None:
        lines.append(f'    <integer name="horizontal_resolution" value="{int(cols)}"/>')
    if threshold is not None:
        lines.append(f'    <float name="detection_threshold" value="{threshold:.9g}"/>')
    if noise is not None:
        lines.append(f'    <float name="receiver_noise_std" value="{noise:.9g}"/>')
    lines += [
        f'    <transform name="to_world"><translate z="{height_m:.9g}"/></transform>',
        "  </sensor>",
        f"  {_road_bsdf(material)}",
        '  <shape type="rectangle" id="road" label="road">',
        '    <transform name="to_world"><scale value="2000"/></transform><ref id="road_mat"/>',
        "  </shape>",
        "</scene>",
    ]
    return "\n".join(lines) + "\n"


def _flat_ranges(pattern, height_m: float) -> np.ndarray:
    """(R,) ``|xyz|`` where each ring's beam of column 0 meets the plane ``z = -h`` below a
    level sensor; inf where it points up."""
    ring = np.arange(pattern.rings)
    d, o = pattern.rays_at(ring, np.zeros(pattern.rings))
    o = np.zeros_like(d) if o is None else o
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (-height_m - o[:, 2]) / d[:, 2]
    p = o + t[:, None] * d
    return np.where((d[:, 2] < 0) & (t > 0), np.linalg.norm(p, axis=1), np.inf)


def simulate_flat_road(
    preset: str = "hdl64e",
    material: str = ROUGH_ASPHALT,
    *,
    poses: np.ndarray | None = None,
    front_only: Sequence[bool] | None = None,
    seed: int = 0,
    **road,
) -> RingCoverage:
    """Scan a flat road (:func:`flat_road_scene_xml`); per ring its reported ground returns.

    Args:
        preset, material: the scene's LiDAR preset and road (:func:`flat_road_scene_xml`).
        poses: (F, 4, 4) sensor poses over the road (the plane z = 0), one sweep each (e.g. a
            real coverage's ``poses``); None: one level sweep at ``height_m``.
        front_only: (F,) keep only the points ahead (x > 0 in the sensor frame) of sweep k, as
            in real sweeps cut to the front half; None: keep all.
        seed: noise seed of the first sweep; sweep k uses ``seed + k``.
        **road: the rest of the scene, :func:`flat_road_scene_xml`'s keyword options
            (``height_m``, ``cols``, ``threshold``, ``noise``, ``layout``,
            ``calibration_file``).
    """
    from ..lidar.scan import scan
    from ..scene import load_scene_text

    height_m = road.get("height_m", SENSOR_HEIGHT_M)
    loaded = load_scene_text(flat_road_scene_xml(preset, material, **road))
    lidar = loaded.lidars[0]
    if poses is None:
        level = np.eye(4)
        level[2, 3] = height_m
        poses = level[None]
    poses = np.asarray(poses, dtype=np.float64)
    front = np.zeros(len(poses), bool) if front_only is None else np.asarray(front_only, bool)
    tally = _Tally(lidar.config.rings)
    for k, pose in enumerate(poses):
        tally.add(scan(loaded.scene, lidar, seed=seed + k, to_world=pose), pose, front[k])
    return RingCoverage(
        [np.concatenate(x) for x in tally.ranges],
        tally.detected,
        tally.missed,
        len(poses),
        _flat_ranges(lidar.config.pattern, height_m),
        poses,
        front,
        tally.range_hits,
        tally.range_detected,
    )


class _Tally:
    """What :func:`simulate_flat_road` counts over its sweeps, per ring and per range bin."""

    def __init__(self, rings: int) -> None:
        bins = len(RANGE_BINS_M) - 1
        self.rings = rings
        self.ranges: list[list[np.ndarray]] = [[] for _ in range(rings)]
        self.detected = np.zeros(rings, dtype=np.int64)
        self.missed = np.zeros(rings, dtype=np.int64)
        self.range_hits = np.zeros(bins, dtype=np.int64)
        self.range_detected = np.zeros(bins, dtype=np.int64)

    def add(self, r, pose: np.ndarray, front: bool) -> None:
        """One sweep ``r`` (a :class:`~nidar_mi.lidar.result.ScanResult`) from ``pose``; only
        the beams pointing ahead with ``front``."""
        bins = len(self.range_hits)
        origins = np.zeros_like(r.directions) if r.origins is None else r.origins
        # where each beam meets the road, reported or not: |xyz| in the sensor frame
        o_z = origins @ pose[2, :3] + pose[2, 3]
        d_z = r.directions @ pose[2, :3]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(d_z < 0, -o_z / d_z, np.inf)
        dist = np.linalg.norm(
            origins + np.where(np.isfinite(t), t, 0.0)[..., None] * r.directions, axis=-1
        )
        # a sweep cut to the front half keeps the beams pointing ahead (x > 0)
        keep = r.directions[..., 0] > 0 if front else np.ones(r.valid.shape, bool)
        valid, hit = r.valid & keep, r.hit & keep
        for q in range(self.rings):
            self.ranges[q].append(dist[q][valid[q]])
        # P(detect) of ring q as on the real side: where ring q+1 returned the road
        ref = np.zeros_like(valid)
        ref[:-1] = valid[1:] & hit[:-1]
        self.detected += (ref & valid).sum(axis=1)
        self.missed += (ref & ~valid).sum(axis=1)
        b_idx = np.searchsorted(RANGE_BINS_M, dist[hit], side="right") - 1
        inside = (b_idx >= 0) & (b_idx < bins)
        self.range_hits += np.bincount(b_idx[inside], minlength=bins)
        self.range_detected += np.bincount(
            b_idx[inside], weights=valid[hit][inside], minlength=bins
        ).astype(np.int64)


def _conditional_detection(az, ring, ground, step, rings: int):
    """Per ring r: (detected, missed) at the azimuths where ring r+1 returned ground."""
    from ..datasets.kitti_rings import nearest_in_ring

    detected = np.zeros(rings, dtype=np.int64)
    missed = np.zeros(rings, dtype=np.int64)
    for r in range(rings - 1):
        own = np.flatnonzero(ring == r)
        ref = az[(ring == r + 1) & ground]
        idx, present = nearest_in_ring(az[own], ref, step)
        detected[r] = int(np.sum(present & ground[own[idx]])) if len(own) else 0
        missed[r] = int(np.sum(~present))
    return detected, missed


def kitti_ground_rings(
    velodyne_dir: str | os.PathLike,
    frames: Sequence[str] | None = None,
    *,
    rings: int = 64,
    seed: int = 0,
    progress: bool = False,
) -> RingCoverage:
    """Ground returns per ring of real KITTI HDL-64E sweeps (method in the module docstring).

    Args:
        velodyne_dir: a folder of KITTI ``*.bin`` sweeps (read in place).
        frames: frame ids (file stems); None takes every file.
        rings: lasers per sweep; a sweep whose storage order gives another count (a truncated
            file) is left out.
        seed: RANSAC seed.
        progress: show a progress bar.

    Raises:
        NidarError: the folder holds no usable sweep.
    """
    from ..datasets.kitti_rings import (
        azimuth_deg,
        ground_plane,
        grow_ground,
        pose_over_plane,
        scan_rings,
    )
    from ..io.kitti import read_kitti_bin

    paths = sorted(glob.glob(os.path.join(os.fspath(velodyne_dir), "*.bin")))
    if frames is not None:
        wanted = set(frames)
        paths = [p for p in paths if os.path.splitext(os.path.basename(p))[0] in wanted]
    from ..progress import progress_bar

    paths = progress_bar(paths, show=progress, desc="KITTI sweeps", unit="sweep")
    rng = np.random.default_rng(seed)
    ranges: list[list[np.ndarray]] = [[] for _ in range(rings)]
    detected = np.zeros(rings, dtype=np.int64)
    missed = np.zeros(rings, dtype=np.int64)
    poses, front = [], []
    for path in paths:
        xyz, _ = read_kitti_bin(path)
        xyz = xyz.astype(np.float64)
        ring = scan_rings(xyz)
        if ring.max() + 1 != rings:
            continue
        az = azimuth_deg(xyz)
        steps = np.diff(np.sort(az[ring == rings // 2]))
        step = float(np.median(steps[(steps > 0) & (steps < 1.0)]))
        plane = ground_plane(xyz, rng)
        ground = grow_ground(xyz, ring, plane, step)
        d = np.linalg.norm(xyz, axis=1)
        for r in range(rings):
            ranges[r].append(d[(ring == r) & ground])
        det, mis = _conditional_detection(az, ring, ground, step, rings)
        detected += det
        missed += mis
        poses.append(pose_over_plane(*plane))
        front.append(bool(np.mean(xyz[:, 0] < 0.0) < 0.01))
    if not poses:
        raise NidarError(f"{velodyne_dir}: no whole {rings}-ring KITTI sweep found")
    return RingCoverage(
        [np.concatenate(r) for r in ranges],
        detected,
        missed,
        len(poses),
        None,
        np.stack(poses),
        np.array(front),
    )


def compare_rings(
    real: RingCoverage,
    sim: RingCoverage,
    *,
    tolerance: float = TOLERANCE,
    min_ground_per_frame: float = MIN_GROUND_PER_FRAME,
    min_references: int = MIN_REFERENCES,
) -> list[dict]:
    """Per ring: real and simulated ground-range median and 90th percentile, P(detect).

    Args:
        real, sim: the two coverages (same ring count).
        tolerance: relative on the range statistics, absolute on P(detect).
        min_ground_per_frame: a ring's ranges are compared where the real coverage holds at
            least this many of its ground returns per frame.
        min_references: a ring's P(detect) is compared where its real estimate rests on at
            least this many references.

    Returns:
        One dict per ring: ``ring``, ``real_ground`` (count), ``real_median_m``,
        ``sim_median_m``, ``ratio`` (median, sim/real), ``real_p90_m``, ``sim_p90_m``,
        ``ratio_p90``, ``compared`` (enough real ground), ``median_ok``, ``p90_ok``,
        ``range_ok`` (both), ``references``, ``p_compared``, ``real_p``, ``sim_p`` (the same
        ring; 0 where the simulated ring meets no road), ``p_ok``, ``sim_p_at_range`` (the
        simulated ring nearest the real median range: the detection model alone; needs the
        simulated flat ranges) and ``p_at_range_ok``, ``ok`` (``range_ok``, and ``p_ok`` where
        P is compared).
    """
    rm, sm = real.medians(), sim.medians()
    r90, s90 = real.percentile(90.0), sim.percentile(90.0)
    rp, sp = real.p_detect, sim.p_detect
    count = real.counts
    refs = real.detected + real.missed
    at_range = (
        sim.p_at_range(np.where(np.isfinite(rm), rm, 1.0))
        if sim.range_hits is not None
        else np.full(len(rm), np.nan)
    )

    def within(a, b):
        return bool(np.isfinite(a) and np.isfinite(b) and abs(a / b - 1.0) <= tolerance)

    rows = []
    for r in range(len(rm)):
        compared = bool(count[r] >= min_ground_per_frame * real.frames and np.isfinite(rm[r]))
        p_compared = bool(refs[r] >= min_references)
        sim_p = 0.0 if not np.isfinite(sp[r]) else float(sp[r])
        median_ok = compared and within(sm[r], rm[r])
        p90_ok = compared and within(s90[r], r90[r])
        p_ok = bool(p_compared and abs(sim_p - rp[r]) <= tolerance)
        rows.append(
            {
                "ring": r,
                "real_ground": int(count[r]),
                "real_median_m": float(rm[r]),
                "sim_median_m": float(sm[r]),
                "ratio": float(sm[r] / rm[r]) if compared else float("nan"),
                "real_p90_m": float(r90[r]),
                "sim_p90_m": float(s90[r]),
                "ratio_p90": float(s90[r] / r90[r]) if compared else float("nan"),
                "compared": compared,
                "median_ok": median_ok,
                "p90_ok": p90_ok,
                "range_ok": median_ok and p90_ok,
                "references": int(refs[r]),
                "p_compared": p_compared,
                "real_p": float(rp[r]),
                "sim_p": sim_p,
                "p_ok": p_ok,
                "sim_p_at_range": float(at_range[r]) if p_compared else float("nan"),
                "p_at_range_ok": bool(p_compared and abs(at_range[r] - rp[r]) <= tolerance),
                "ok": median_ok and p90_ok and (p_ok or not p_compared),
            }
        )
    return rows


def summarize(rows: list[dict]) -> dict[str, int]:
    """Ring counts of :func:`compare_rings`: ``compared``, ``median_ok``, ``p90_ok``,
    ``range_ok``; ``p_compared``, ``p_ok``, ``p_at_range_ok``; ``ok``."""
    keys = (
        "compared",
        "median_ok",
        "p90_ok",
        "range_ok",
        "p_compared",
        "p_ok",
        "p_at_range_ok",
        "ok",
    )
    return {k: int(sum(bool(r[k]) for r in rows)) for k in keys}


def _target_scene(
    reflectivity: float,
    threshold: float,
    noise: float,
    beams: int,
    hi_m: float,
    divergence: float = 0.0,
):
    from ..scene import load_scene_text

    return load_scene_text(f"""<scene version="3.0.0">
  <sensor type="lidar" id="lidar">
    <float name="beam_divergence" value="{divergence:.9g}"/>
    <string name="elevation_angles" value="0"/>
    <integer name="horizontal_resolution" value="{int(beams)}"/>
    <float name="fov_h" value="1e-3"/><boolean name="fov_h_centred" value="true"/>
    <float name="range_max" value="{hi_m * 2:g}"/>
    <float name="detection_threshold" value="{threshold:.9g}"/>
    <float name="receiver_noise_std" value="{noise:.9g}"/>
  </sensor>
  <shape type="rectangle" id="panel">
    <transform name="to_world"><scale value="20"/><rotate y="1" angle="-90"/></transform>
    <bsdf type="diffuse"><spectrum name="reflectance" value="{reflectivity:.9g}"/></bsdf>
  </shape>
</scene>
""")


def _at_distance(d: float) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = -d  # the panel lies in the plane x = 0, its normal towards -x
    return T


def target_detection_scanned(
    reflectivity: float,
    range_m: float,
    threshold: float,
    noise: float,
    *,
    beams: int = 4000,
    seed: int = 0,
    beam_divergence: float = 0.0,
) -> float:
    """The fraction of ``beams`` beams a Lambertian target of ``reflectivity`` at normal
    incidence and ``range_m`` returns (the scanned ``P_D``; its binomial deviation is
    ``sqrt(P (1 - P) / beams)``); ``beam_divergence`` (mrad) > 0 casts diverging beams (their
    footprint lies wholly on the 40 m panel)."""
    from ..lidar.scan import scan

    loaded = _target_scene(
        reflectivity, threshold, noise, beams, 2.0 * range_m, divergence=beam_divergence
    )
    r = scan(loaded.scene, loaded.lidars[0], seed=seed, to_world=_at_distance(range_m))
    return float(r.valid.mean())


def target_reach_scanned(
    reflectivity: float,
    threshold: float,
    *,
    lo_m: float = 5.0,
    hi_m: float = 300.0,
    tol_m: float = 0.05,
) -> float:
    """How far (m) the scan reports a Lambertian target of ``reflectivity`` at normal incidence
    without receiver noise (the step at the threshold; with noise this is where ``P_D = 0.5``).

    One horizontal beam meets a 40 m wide vertical panel; the LiDAR is moved back (an opaque
    pose: one compiled kernel) and the step from seen (+1) to not seen (-1) is found by
    :func:`scipy.optimize.brentq` to ``tol_m``. Returns 0 when the target is not seen at
    ``lo_m``, ``hi_m`` when it still is there.
    """
    from functools import cache

    from scipy.optimize import brentq

    from ..lidar.scan import scan

    loaded = _target_scene(reflectivity, threshold, 0.0, 1, hi_m)

    @cache  # brentq evaluates the ends again
    def seen(d: float) -> float:
        hit = scan(loaded.scene, loaded.lidars[0], to_world=_at_distance(d)).valid[0, 0]
        return 1.0 if hit else -1.0

    if seen(lo_m) < 0:
        return 0.0
    if seen(hi_m) > 0:
        return hi_m
    return brentq(seen, lo_m, hi_m, xtol=tol_m)
