"""Ground coverage per ring: a simulated flat road against real KITTI HDL-64E frames.

A real HDL-64E S2 on a flat road returns each laser's ground in a narrow band of range around
the laser's flat-ground intersection, and keeps detecting asphalt at grazing incidence out to
about 50 m. This module measures both sides the same way, per ring (0 = highest laser):

* **simulated** (:func:`simulate_flat_road`): a LiDAR preset at the KITTI rig's 1.73 m over an
  endless flat road of one material, scanned by the real ``lidar`` plugin; every column of a
  ring meets the road, so ``P(detect)`` is the fraction of its columns reported.
* **real** (:func:`kitti_ground_rings`): KITTI frames read from a user path (never copied);
  the ring of every point from the storage order and the road plane by RANSAC
  (:mod:`nidar_mi.datasets.kitti_rings`); ground = within 0.2 m of the plane or grown outward
  from it along each azimuth (:func:`nidar_mi.datasets.kitti_rings.grow_ground`). ``P(detect)`` of
  ring r is conditional on the road being visible: of the ground returns of the next lower
  ring r+1, the fraction at whose azimuth ring r also returned ground (ring r returning
  something else there, a car or a kerb, is left out; returning nothing is a miss). It is a
  lower bound where the road ends or rises out of view.

:func:`compare_rings` puts them side by side: per ring the median ground range of each, their
ratio, the two ``P(detect)`` and whether both agree within a tolerance (10 %: the ratio within
[0.9, 1.1] and ``|ΔP| <= 0.1``). The median range tests the ring geometry (the preset's
elevation table and beam origins); ``P(detect)`` the detection model (threshold, and the road's
backscatter at grazing incidence). :func:`target_reach_scanned` finds by bisection how far a
Lambertian target at normal incidence is reported.
"""

from __future__ import annotations

import glob
import os
import tempfile
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
    "target_reach_scanned",
    "LAMBERTIAN_ASPHALT",
    "ROUGH_ASPHALT",
]

#: The road of the old model: Lambertian asphalt_old (its earthlib spectrum).
LAMBERTIAN_ASPHALT = "lambertian:asphalt_old"
#: The library's asphalt_old: roughdiffuse (nidar_mi.lidar.calibration).
ROUGH_ASPHALT = "asphalt_old"


@dataclass
class RingCoverage:
    """Ground returns per ring (R rings).

    Attributes:
        ranges: per ring, (n_r,) float64 ranges (m) of its ground returns.
        detected: (R,) int, columns (sim) or references (real) where the ground was reported.
        missed: (R,) int, where it was visible but not reported.
        frames: how many sweeps were pooled.
        flat_range_m: (R,) where each ring meets flat ground (simulated; ``inf`` above the
            horizon), or None (real).
    """

    ranges: list[np.ndarray]
    detected: np.ndarray
    missed: np.ndarray
    frames: int
    flat_range_m: np.ndarray | None = None

    def p_at_range(self, range_m: np.ndarray) -> np.ndarray:
        """``P(detect)`` of the ring whose flat-ground range is nearest each of ``range_m``
        (simulated coverage only): the detection model at a range, whatever the ring."""
        if self.flat_range_m is None:
            raise ValueError("p_at_range needs the flat-ground range of each ring")
        ok = np.isfinite(self.flat_range_m)
        flat, p = self.flat_range_m[ok], np.nan_to_num(self.p_detect[ok])
        d = np.asarray(range_m, dtype=np.float64)
        nearest = np.argmin(np.abs(np.log(flat)[None, :] - np.log(d)[:, None]), axis=1)
        return p[nearest]

    @property
    def p_detect(self) -> np.ndarray:
        """(R,) detected / (detected + missed); NaN where there is no reference."""
        total = self.detected + self.missed
        return np.where(total > 0, self.detected / np.maximum(total, 1), np.nan)

    def medians(self) -> np.ndarray:
        """(R,) median ground range per ring (m); NaN where a ring has none."""
        return np.array([np.median(r) if len(r) else np.nan for r in self.ranges])


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
    height_m: float = 1.73,
    cols: int | None = None,
    threshold: float | None = None,
) -> str:
    """Scene XML: ``preset`` at ``height_m`` over a 4 km flat road of ``material``.

    Args:
        preset: LiDAR preset.
        material: a library material name, or ``lambertian:<name>`` for a Lambertian road with
            that material's reflectance spectrum.
        height_m: sensor height above the road.
        cols: columns per sweep (preset's when None).
        threshold: detection threshold (the preset's when None).
    """
    lines = [
        '<scene version="3.0.0">',
        '  <sensor type="lidar" id="lidar">',
        f'    <string name="preset" value="{preset}"/>',
        '    <float name="range_max" value="120"/>',
    ]
    if cols is not None:
        lines.append(f'    <integer name="horizontal_resolution" value="{int(cols)}"/>')
    if threshold is not None:
        lines.append(f'    <float name="detection_threshold" value="{threshold:.9g}"/>')
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


def _load_xml(xml: str):
    from ..scene import load_scene

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "scene.xml")
        with open(path, "w", encoding="utf-8") as f:
            f.write(xml)
        return load_scene(path)


def simulate_flat_road(
    preset: str = "hdl64e",
    material: str = ROUGH_ASPHALT,
    *,
    height_m: float = 1.73,
    cols: int | None = None,
    threshold: float | None = None,
) -> RingCoverage:
    """Scan a flat road (:func:`flat_road_scene_xml`); per ring its reported ground returns."""
    from ..lidar.scan import scan

    loaded = _load_xml(
        flat_road_scene_xml(preset, material, height_m=height_m, cols=cols, threshold=threshold)
    )
    r = scan(loaded.scene, loaded.lidars[0], seed=0)
    ranges = [r.range[k][r.valid[k]].astype(np.float64) for k in range(r.valid.shape[0])]
    detected = r.valid.sum(axis=1)
    missed = (r.hit & ~r.valid).sum(axis=1)
    down = np.sin(np.radians(-r.config.elevations))
    flat = np.where(down > 0, height_m / np.maximum(down, 1e-12), np.inf)
    return RingCoverage(ranges, detected, missed, 1, flat)


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
) -> RingCoverage:
    """Ground returns per ring of real KITTI HDL-64E sweeps (method in the module docstring).

    Args:
        velodyne_dir: a folder of KITTI ``*.bin`` sweeps (read in place).
        frames: frame ids (file stems); None takes every file.
        rings: lasers per sweep; a sweep whose storage order gives another count (a truncated
            file) is left out.
        seed: RANSAC seed.

    Raises:
        NidarError: the folder holds no usable sweep.
    """
    from ..datasets.kitti_rings import azimuth_deg, ground_plane, grow_ground, scan_rings
    from ..io.points import read_kitti_bin

    paths = sorted(glob.glob(os.path.join(os.fspath(velodyne_dir), "*.bin")))
    if frames is not None:
        wanted = set(frames)
        paths = [p for p in paths if os.path.splitext(os.path.basename(p))[0] in wanted]
    rng = np.random.default_rng(seed)
    ranges: list[list[np.ndarray]] = [[] for _ in range(rings)]
    detected = np.zeros(rings, dtype=np.int64)
    missed = np.zeros(rings, dtype=np.int64)
    used = 0
    for path in paths:
        xyz, _ = read_kitti_bin(path)
        xyz = xyz.astype(np.float64)
        ring = scan_rings(xyz)
        if ring.max() + 1 != rings:
            continue
        az = azimuth_deg(xyz)
        steps = np.diff(np.sort(az[ring == rings // 2]))
        step = float(np.median(steps[(steps > 0) & (steps < 1.0)]))
        ground = grow_ground(xyz, ring, ground_plane(xyz, rng), step)
        d = np.linalg.norm(xyz, axis=1)
        for r in range(rings):
            ranges[r].append(d[(ring == r) & ground])
        det, mis = _conditional_detection(az, ring, ground, step, rings)
        detected += det
        missed += mis
        used += 1
    if used == 0:
        raise NidarError(f"{velodyne_dir}: no whole {rings}-ring KITTI sweep found")
    return RingCoverage([np.concatenate(r) for r in ranges], detected, missed, used)


def compare_rings(
    real: RingCoverage,
    sim: RingCoverage,
    *,
    tolerance: float = 0.10,
    min_references: int = 200,
) -> list[dict]:
    """Per ring: real and simulated median ground range, ratio, P(detect), agreement.

    Only rings whose real ``P(detect)`` rests on at least ``min_references`` visible-ground
    references are compared (``compared`` False otherwise; rings above the horizon never are).

    Returns:
        One dict per ring: ``ring``, ``real_median_m``, ``sim_median_m``, ``ratio``,
        ``real_p``, ``sim_p`` (the same ring), ``sim_p_at_range`` (the simulated ring nearest
        the real median range: the detection model alone), ``references``, ``compared``,
        ``range_ok``, ``p_ok``, ``ok`` (both), ``p_at_range_ok``.
    """
    rm, sm = real.medians(), sim.medians()
    rp, sp = real.p_detect, sim.p_detect
    at_range = sim.p_at_range(np.where(np.isfinite(rm), rm, 1.0))
    refs = real.detected + real.missed
    rows = []
    for r in range(len(rm)):
        compared = bool(refs[r] >= min_references and np.isfinite(rm[r]))
        ratio = sm[r] / rm[r] if compared and np.isfinite(sm[r]) else np.nan
        sim_p = 0.0 if compared and not np.isfinite(sp[r]) else sp[r]
        range_ok = bool(compared and np.isfinite(ratio) and abs(ratio - 1.0) <= tolerance)
        p_ok = bool(compared and abs(sim_p - rp[r]) <= tolerance)
        rows.append(
            {
                "ring": r,
                "real_median_m": float(rm[r]),
                "sim_median_m": float(sm[r]),
                "ratio": float(ratio),
                "real_p": float(rp[r]),
                "sim_p": float(sim_p),
                "sim_p_at_range": float(at_range[r]) if compared else float("nan"),
                "references": int(refs[r]),
                "compared": compared,
                "range_ok": range_ok,
                "p_ok": p_ok,
                "ok": range_ok and p_ok,
                "p_at_range_ok": bool(compared and abs(at_range[r] - rp[r]) <= tolerance),
            }
        )
    return rows


def target_reach_scanned(
    reflectivity: float,
    threshold: float,
    *,
    lo_m: float = 5.0,
    hi_m: float = 300.0,
    tol_m: float = 0.05,
) -> float:
    """How far (m) the scan reports a Lambertian target of ``reflectivity`` at normal incidence.

    One horizontal beam meets a 40 m wide vertical panel; the LiDAR is moved back (an opaque
    pose: one compiled kernel) and the reach bracketed by bisection to ``tol_m``.
    """
    from ..lidar.scan import scan

    xml = f"""<scene version="3.0.0">
  <sensor type="lidar" id="lidar">
    <string name="elevation_angles" value="0"/><integer name="horizontal_resolution" value="1"/>
    <float name="fov_h" value="1e-3"/><float name="range_max" value="{hi_m * 2:g}"/>
    <float name="detection_threshold" value="{threshold:.9g}"/>
  </sensor>
  <shape type="rectangle" id="panel">
    <transform name="to_world"><scale value="20"/><rotate y="1" angle="-90"/></transform>
    <bsdf type="diffuse"><spectrum name="reflectance" value="{reflectivity:.9g}"/></bsdf>
  </shape>
</scene>
"""
    loaded = _load_xml(xml)

    def seen(d: float) -> bool:
        T = np.eye(4)
        T[0, 3] = -d  # the panel lies in the plane x = 0, its normal towards -x
        return bool(scan(loaded.scene, loaded.lidars[0], to_world=T).valid[0, 0])

    if not seen(lo_m):
        return 0.0
    lo, hi = lo_m, hi_m
    while hi - lo > tol_m:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if seen(mid) else (lo, mid)
    return lo
