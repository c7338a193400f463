"""The drive study: does simulated intensity help odometry and place recognition downstream?

:func:`run_study` reads as its steps:

1. **drive**: a ``city`` (or ``suburb``) layout and its drive (:mod:`nidar_mi.scenegen`);
2. **frames**: the drive scanned from every pose (:func:`.drive_sweeps.render_sweeps`: the package's
   trajectory renderer, :mod:`nidar_mi.sequence`, one instantaneous sweep per pose), once with
   the spectral materials (plus the camera at every pose) and once on the RGB-only twin; NIDAR's
   intensity from the camera images (:func:`.drive_sweeps.nidar_intensity`);
3. **odometry**: KISS-ICP on the frames (:func:`.kiss.run_odometry`), ATE / RPE / end drift
   against the true poses (:mod:`.odometry`), on the whole sweeps, on the same sweeps written in
   the KITTI odometry layout and read by kiss-icp's own loader (:data:`KITTI_LAYOUT`: a client
   nobody here wrote accepts the files), and on the sweeps without their ground plane (:data:`GROUND_REMOVED`: the rings a flat simulated road draws round the
   sensor hold registration back, see docs/CASE_STUDY.md); with ``sequence`` (a
   ``render --trajectory`` folder with per-point times) also on the motion-distorted sweeps, with
   and without de-skewing;
4. **loops**: for each intensity source a scan-context descriptor per frame, matched along the
   drive (:mod:`.loops`), precision / recall of the loops;
5. **pose graph**: the matches of each source that pass a registration check become loop
   constraints on KISS-ICP's trajectory without the ground (:mod:`.pose_graph`), and ATE again;
6. **report**: ``results.json``, ``report.md`` and the figures (:mod:`.report`).

The five intensity sources share each frame's geometry and differ only in the value scan context
keeps per bin (:data:`SOURCES`). Everything is cached under ``OUT`` (the sweeps of each kind as a
sequence folder per request, NIDAR per weights), so running the same command again after new
NIDAR weights ship recomputes only NIDAR's columns and the steps after them.
"""

from __future__ import annotations

import logging
import os
import shutil
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ...errors import NidarError
from ...io.ownership import Owner

__all__ = [
    "GROUND_REMOVED",
    "KITTI_LAYOUT",
    "SOURCES",
    "StudyConfig",
    "source_values",
    "run_study",
    "gt_at_mid_sweep",
]

log = logging.getLogger("nidar_mi.drive")

#: Intensity sources: the per-point value each puts into the descriptor.
SOURCES = {
    "physics": "simulated intensity with the spectral materials, range-compensated (I·d²)",
    "nidar": "NIDAR's intensity from the camera image (0 outside the camera's view)",
    "rgb_twin": "simulated intensity on the RGB-only twin of the scene, range-compensated",
    "carla": "CARLA's exp(-0.004 d)",
    "none": "no intensity: height above the road (Scan Context)",
}
#: Points lower than this in the LiDAR frame (m) are dropped before the descriptor (the
#: reference implementation's ground filter).
ISC_MIN_Z_M = -0.9
#: The odometry run on sweeps without their ground plane (:func:`.kiss.remove_ground`): the
#: trajectory the loop search and the pose graph start from.
GROUND_REMOVED = "instantaneous, ground removed"
#: The odometry run through kiss-icp's own KITTI loader on the sweeps written in that layout.
KITTI_LAYOUT = "instantaneous, KITTI layout read by kiss-icp"


@dataclass
class StudyConfig:
    """What one run of the study does (written to ``results.json``).

    Attributes:
        kind: ``city`` or ``suburb``.
        seed: scene seed.
        blocks: (nx, ny) blocks.
        frames: frames of the drive.
        rate_hz: frame rate.
        speed: cruising speed, m/s.
        cols: LiDAR columns per sweep (HDL-64E: 2048).
        width, height, spp: camera image size and samples per pixel (for NIDAR).
        weights: NIDAR weights folder (None: the shipped model).
        sources: intensity sources to compare (keys of :data:`SOURCES`).
        skip_m, radius_m, candidates: loop search (:func:`.loops.match_drive`).
        rpe_lengths: RPE segment lengths, m.
        loop_overlap: overlap a registered loop needs to enter the pose graph.
        loop_candidates: the best-scoring matches of each source that are registered (and, when
            they pass the overlap check, enter the pose graph).
        sequence: a ``render --trajectory`` folder of the same drive (optional).
        body_motion: the body rolls, pitches and heaves (:func:`nidar_mi.scenegen.route.drive`).
    """

    kind: str = "city"
    seed: int = 0
    blocks: tuple[int, int] = (4, 3)
    frames: int = 500
    rate_hz: float = 10.0
    speed: float = 10.0
    cols: int = 2048
    width: int = 320
    height: int = 180
    spp: int = 4
    weights: str | None = None
    sources: tuple[str, ...] = tuple(SOURCES)
    skip_m: float = 20.0
    radius_m: float = 5.0
    candidates: int = 10
    rpe_lengths: tuple[int, ...] = (25, 50, 100, 200)
    loop_overlap: float = 0.7
    loop_candidates: int = 60
    sequence: str | None = None
    body_motion: bool = True
    timings: dict = field(default_factory=dict)

    def check(self) -> None:
        """Raise :class:`NidarError` for a value the study cannot run with."""
        bad = [s for s in self.sources if s not in SOURCES]
        if bad or not self.sources:
            raise NidarError(
                f"`sources`: unknown '{','.join(bad)}' (choose from {', '.join(SOURCES)})"
            )
        from ...scenegen.route import check_drive

        if self.frames < 10:
            raise NidarError(f"`frames` must be >= 10 (got {self.frames})")
        check_drive(self.frames, self.rate_hz, self.speed)
        if self.cols < 16 or self.width < 16 or self.height < 16 or self.spp < 1:
            raise NidarError("`cols`, `width` and `height` must be >= 16 and `spp` >= 1")


def source_values(source: str, xyz, intensity, rng_m, nidar=None) -> np.ndarray:
    """The value of each point for one intensity source (before the drive's normalisation).

    Args:
        source: a key of :data:`SOURCES`.
        xyz: (N, 3) points in the LiDAR frame, m.
        intensity: (N,) simulated intensity (raw: g·ρ·cosθ/d²).
        rng_m: (N,) range, m.
        nidar: (N,) NIDAR intensity (0 where no camera saw the point), for ``nidar``.
    """
    from ...scenegen.streets import LIDAR_HEIGHT_M

    if source in ("physics", "rgb_twin"):
        return np.asarray(intensity, np.float64) * np.asarray(rng_m, np.float64) ** 2
    if source == "nidar":
        if nidar is None:
            raise NidarError("the nidar source needs NIDAR's columns")
        return np.asarray(nidar, np.float64)
    if source == "carla":
        return np.exp(-0.004 * np.asarray(rng_m, np.float64))
    if source == "none":
        return np.maximum(np.asarray(xyz, np.float64)[:, 2] + LIDAR_HEIGHT_M, 0.0)
    raise NidarError(f"unknown intensity source '{source}'")


def gt_at_mid_sweep(poses: np.ndarray, times: np.ndarray, period: float) -> np.ndarray:
    """(N, 4, 4) poses at ``times + period / 2``, SE(3)-interpolated
    (:func:`nidar_mi.geometry.se3.interpolate_poses`); past the last frame the motion of the
    last step goes on. ``period`` is at most the last step."""
    from ...geometry.se3 import interpolate_poses

    times = np.asarray(times, dtype=np.float64)
    ext_t = np.r_[times, times[-1] + (times[-1] - times[-2])]
    step = np.linalg.inv(poses[-2]) @ poses[-1]
    ext = np.concatenate([poses, (poses[-1] @ step)[None]])
    return interpolate_poses(ext_t, ext, times + period / 2)


# ---------------------------------------------------------------- steps


@dataclass
class _Drive:
    """The drive of a study: its scene, trajectory and true poses.

    Attributes:
        scene: the scene XML.
        trajectory: the rig's TUM file.
        poses: (N, 4, 4) ``T_world_lidar`` per frame.
        info: the drive's entry of the scene index.
    """

    scene: str
    trajectory: str
    poses: np.ndarray
    info: dict

    @property
    def gt(self) -> np.ndarray:
        """(N, 4, 4) true poses ``T_{lidar_0 <- lidar_k}``."""
        return np.linalg.inv(self.poses[0]) @ self.poses


def _drive(out: str, cfg: StudyConfig) -> _Drive:
    from ...io.trajectory import read_trajectory
    from ...scenegen.generate import generate, scene_id

    folder = os.path.join(out, "scene")
    index = generate(
        folder,
        1,
        cfg.seed,
        kind=cfg.kind,
        progress=False,
        blocks=tuple(cfg.blocks),
        drive={
            "frames": cfg.frames,
            "rate_hz": cfg.rate_hz,
            "speed": cfg.speed,
            "body_motion": cfg.body_motion,
        },
        nested=True,
    )
    sid = scene_id(cfg.seed, 0)
    entry = next(e for e in index["scenes"] if e["id"] == sid)
    tum = os.path.join(folder, entry["drive"]["files"]["tum"])
    poses = read_trajectory(tum).poses @ np.array(entry["lidar"]["T_world_lidar"])  # on the rig
    return _Drive(os.path.join(folder, entry["file"]), tum, poses, entry["drive"])


@dataclass
class _Sweeps:
    """The rendered sweeps of a study, per kind (``physics``, ``rgb_twin``), and NIDAR's
    columns.

    Attributes:
        folders: kind -> its sequence folder.
        loads: kind -> ``load(k) -> Sweep`` (:func:`.drive_sweeps.read_sequence`).
        nidar: the folder of NIDAR's columns (None without the ``nidar`` source).
    """

    folders: dict
    loads: dict
    nidar: str | None = None

    def nidar_columns(self, k: int) -> dict[str, np.ndarray]:
        """NIDAR's ``intensity_nidar`` and ``nidar_observed`` of frame ``k``."""
        with np.load(os.path.join(self.nidar, f"{k:06d}.npz")) as f:
            return {key: f[key] for key in f.files}


def _render(out: str, cfg: StudyConfig, drive: _Drive, timings: dict, progress: bool) -> _Sweeps:
    """The sweeps of every kind the sources need and NIDAR's columns, timed into ``timings``."""
    from .drive_sweeps import SweepRequest, nidar_intensity, read_sequence, render_sweeps

    params = {"cols": str(cfg.cols), "width": str(cfg.width), "height": str(cfg.height)}
    base = SweepRequest(drive.scene, drive.trajectory, cfg.rate_hz, cfg.frames, params=params)
    kinds = {"physics": replace(base, cameras="nidar" in cfg.sources, spp=cfg.spp)}
    if "rgb_twin" in cfg.sources:
        kinds["rgb_twin"] = replace(base, rgb_twin=True)
    sweeps = _Sweeps({}, {})
    for kind, request in kinds.items():
        t0 = time.perf_counter()
        folder = os.path.join(out, "frames", kind)
        sweeps.folders[kind] = render_sweeps(request, folder, progress=progress)
        sweeps.loads[kind] = read_sequence(folder)[2]
        timings[f"frames_{kind}"] = time.perf_counter() - t0
        log.debug("frames_%s: %.1f s", kind, timings[f"frames_{kind}"])
    if "nidar" in cfg.sources:
        t0 = time.perf_counter()
        sweeps.nidar = nidar_intensity(
            sweeps.folders["physics"], os.path.join(out, "frames"), cfg.weights, progress=progress
        )
        timings["nidar"] = time.perf_counter() - t0
        log.debug("nidar: %.1f s", timings["nidar"])
    return sweeps


def _odometry_runs(cfg: StudyConfig, out: str, sweeps: _Sweeps, gt, progress: bool) -> dict:
    from .kiss import remove_ground, run_odometry
    from .odometry import ate, end_drift, rpe_kitti

    def metrics(truth, est, t0):
        return {
            "ate": {k: v for k, v in ate(truth, est).items() if k != "aligned"},
            "rpe": rpe_kitti(truth, est, lengths=cfg.rpe_lengths),
            "end_drift": end_drift(truth, est),
            "seconds": time.perf_counter() - t0,
        }

    load = sweeps.loads["physics"]
    runs = {}
    t0 = time.perf_counter()
    est = run_odometry(lambda k: (load(k).xyz, None), cfg.frames, progress=progress)
    runs["instantaneous"] = metrics(gt, est, t0) | {"poses": est}
    t0 = time.perf_counter()
    est = run_odometry(lambda k: (remove_ground(load(k).xyz), None), cfg.frames, progress=progress)
    runs[GROUND_REMOVED] = metrics(gt, est, t0) | {"poses": est}
    t0 = time.perf_counter()
    est, truth = _kiss_on_kitti_layout(cfg, out, load, gt, progress)
    runs[KITTI_LAYOUT] = metrics(truth, est, t0) | {"poses": est}
    if cfg.sequence:
        runs |= _distorted_runs(cfg, metrics, progress)
    return runs


def _distorted_runs(cfg: StudyConfig, metrics, progress: bool) -> dict:
    """KISS-ICP on the motion-distorted sweeps of ``cfg.sequence``, with and without its
    de-skewing, scored against the poses at mid-sweep."""
    from .drive_sweeps import read_sequence
    from .kiss import run_odometry

    seq_poses, seq_times, load = read_sequence(cfg.sequence)
    # the renderer needs each sweep inside the trajectory, so it may hold a frame less
    n = min(len(seq_poses), cfg.frames)
    mid = gt_at_mid_sweep(seq_poses[:n], seq_times[:n], 1.0 / cfg.rate_hz)
    mid = np.linalg.inv(mid[0]) @ mid
    # a distorted sweep mixes the poses of its whole firing time and KISS-ICP's de-skewing
    # corrects it to the middle: both are scored against the pose at mid-sweep
    runs = {}
    for name, deskew in (("distorted", False), ("distorted + KISS-ICP de-skew", True)):
        t0 = time.perf_counter()

        def frame(k):
            f = load(k)
            return f.xyz, f.t

        est = run_odometry(frame, n, deskew=deskew, progress=progress)
        runs[name] = metrics(mid, est, t0) | {"poses": est}
    return runs


def _kiss_on_kitti_layout(cfg: StudyConfig, out: str, load, gt: np.ndarray, progress: bool):
    """The frames written in the KITTI odometry layout and read back by kiss-icp's own KITTI
    loader (which also applies its 0.205° vertical-angle correction for KITTI's HDL-64E): the
    estimate and the loader's ground truth."""
    from kiss_icp.datasets.kitti import KITTIOdometryDataset

    from ...io.kitti import write_sequence
    from .kiss import run_odometry

    root = os.path.join(out, "kitti")
    seq = os.path.join(root, "sequences", "00")
    if not os.path.exists(os.path.join(seq, "poses.txt")):
        clouds = []
        for k in range(cfg.frames):
            f = load(k)
            clouds.append({"xyz": f.xyz, "intensity": f.intensity})
        times = np.arange(cfg.frames) / cfg.rate_hz
        write_sequence(seq, clouds, gt, times)
        os.makedirs(os.path.join(root, "poses"), exist_ok=True)
        shutil.copyfile(os.path.join(seq, "poses.txt"), os.path.join(root, "poses", "00.txt"))
    data = KITTIOdometryDataset(root, 0)
    if len(data) != cfg.frames:
        raise NidarError(f"{root}: kiss-icp's KITTI loader found {len(data)} sweeps")
    est = run_odometry(lambda k: (data[k][0], None), cfg.frames, progress=progress)
    return est, np.asarray(data.gt_poses)


def _descriptors(cfg: StudyConfig, sweeps: _Sweeps, progress: bool):
    """Per source: (N, rings, sectors) grids and occupancies."""
    from ...progress import progress_bar
    from .scan_context import descriptor, normalise

    out = {}
    for source in cfg.sources:
        load = sweeps.loads["rgb_twin" if source == "rgb_twin" else "physics"]
        vals, pts = [], []
        for k in range(cfg.frames):
            f = load(k)
            nid = sweeps.nidar_columns(k)["intensity_nidar"] if source == "nidar" else None
            keep = f.xyz[:, 2] > ISC_MIN_Z_M
            v = source_values(source, f.xyz, f.intensity, f.range, nid)
            vals.append(v[keep])
            pts.append(f.xyz[keep])
        scale = float(np.percentile(np.concatenate(vals), 99)) or 1.0
        grids, occs = [], []
        for xyz, v in progress_bar(
            list(zip(pts, vals)), show=progress, desc=f"descriptors {source}"
        ):
            g, o = descriptor(xyz, normalise(v, scale))
            grids.append(g)
            occs.append(o)
        out[source] = (np.stack(grids), np.stack(occs), scale)
    return out


def _loops(cfg: StudyConfig, desc: dict, gt: np.ndarray, odo: np.ndarray) -> dict:
    from .loops import match_drive, pr_curve, pr_summary
    from .odometry import path_length

    distance = path_length(odo)
    res = {}
    for source, (grids, occs, scale) in desc.items():
        t0 = time.perf_counter()
        m = match_drive(
            grids,
            occs,
            gt[:, :3, 3],
            distance,
            skip_m=cfg.skip_m,
            radius_m=cfg.radius_m,
            candidates=cfg.candidates,
        )
        thr, p, r = pr_curve(m)
        res[source] = {
            "summary": pr_summary(m) | {"scale": scale, "seconds": time.perf_counter() - t0},
            "matches": m,
            "pr": (thr, p, r),
        }
    return res


def _pose_graphs(cfg: StudyConfig, sweeps: _Sweeps, loops: dict, odo, gt) -> dict:
    """Per source: verified loops -> pose graph -> ATE (skipped, with a warning, without GTSAM)."""
    try:
        import gtsam  # noqa: F401
    except ImportError:
        import warnings

        warnings.warn(
            "pose-graph correction skipped: GTSAM is not installed (pip install 'nidar_mi[drive]')",
            RuntimeWarning,
            stacklevel=2,
        )
        return {}
    from .odometry import ate
    from .pose_graph import optimise

    out = {}
    cache: dict[tuple[str, int, int], tuple[np.ndarray, float]] = {}
    for source, entry in loops.items():
        t0 = time.perf_counter()
        kind = "rgb_twin" if source == "rgb_twin" else "physics"
        found = _verified_loops(cfg, sweeps.loads[kind], kind, entry["matches"], cache)
        fixed = optimise(odo, [(i, j, T) for i, j, T, _ in found])
        out[source] = {
            "loops": len(found),
            "wrong_loops": sum(not c for *_, c in found),
            "ate": {k: v for k, v in ate(gt, fixed).items() if k != "aligned"},
            "seconds": time.perf_counter() - t0,
            "poses": fixed,
        }
    return out


def _verified_loops(cfg: StudyConfig, load, kind: str, m, cache: dict) -> list:
    """The best-scoring matches of a source that registration confirms: ``(i, j, T, correct)``
    each; registrations are cached per ``(kind, i, j)`` (sources on the same sweeps share
    them)."""
    from .kiss import aligned_overlap, register_pair
    from .scan_context import SECTORS

    found = []
    matched = np.nonzero(m.match >= 0)[0]
    best = matched[np.argsort(-m.score[matched], kind="stable")[: cfg.loop_candidates]]
    for i in np.sort(best):
        j = int(m.match[i])
        key = (kind, int(i), j)
        if key not in cache:
            yaw = -2 * np.pi * m.shift[i] / SECTORS
            guess = np.eye(4)
            guess[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
            a, b = load(int(i)).xyz, load(j).xyz
            T = register_pair(b, a, guess)
            cache[key] = (T, aligned_overlap(b, a, T))
        T, ov = cache[key]
        if ov >= cfg.loop_overlap:
            found.append((int(i), j, T, bool(m.correct[i])))
    return found


#: Who writes a study's folder (:mod:`nidar_mi.io.ownership`): it adds to it (the scene, the
#: frames and NIDAR's columns are its cache), and its files are those below.
OWNER = Owner(
    "drive",
    "study",
    names=("scene/*", "frames/*", "kitti/*", "results.json", "report.md", "*.png", "*.tmp-*"),
    replaces=False,
    whole=False,
)


def run_study(
    out: str, cfg: StudyConfig, *, progress: bool = True, overwrite: bool = False
) -> dict:
    """Run every step into ``out`` and return the results.

    ``out`` is created; an earlier study's folder is reused as the cache, any other non-empty
    folder is refused unless ``overwrite`` (then the study's files are added to it; nothing
    else there is touched), another command's output always (:data:`OWNER`,
    :func:`nidar_mi.io.ownership.check_owner`).
    """
    from ...io.atomic import check_output_folder, write_record

    cfg.check()
    out = str(
        check_output_folder(
            out, owner=OWNER, overwrite=overwrite, inputs=[cfg.weights, cfg.sequence]
        )
    )
    os.makedirs(out, exist_ok=True)
    write_record(out, OWNER, [])  # an interrupted study is known as one
    timings = {}
    t0 = time.perf_counter()
    drive = _drive(out, cfg)
    timings["drive"] = time.perf_counter() - t0
    log.debug("drive: %.1f s", timings["drive"])
    sweeps = _render(out, cfg, drive, timings, progress)
    t0 = time.perf_counter()
    odometry = _odometry_runs(cfg, out, sweeps, drive.gt, progress)
    timings["odometry"] = time.perf_counter() - t0
    log.debug("odometry: %.1f s", timings["odometry"])
    odo = odometry[GROUND_REMOVED]["poses"]
    t0 = time.perf_counter()
    desc = _descriptors(cfg, sweeps, progress)
    loops = _loops(cfg, desc, drive.gt, odo)
    timings["loops"] = time.perf_counter() - t0
    log.debug("loops: %.1f s", timings["loops"])
    t0 = time.perf_counter()
    graphs = _pose_graphs(cfg, sweeps, loops, odo, drive.gt)
    timings["pose_graph"] = time.perf_counter() - t0
    log.debug("pose_graph: %.1f s", timings["pose_graph"])
    cfg.timings = timings
    results = _results(out, cfg, drive, sweeps, odometry, loops, graphs)
    _report(out, cfg, results, drive, odometry, loops, graphs, desc)
    write_record(out, OWNER, _own_files(out))
    return results


def _own_files(out: str) -> list[str]:
    """The files of ``out`` the study wrote (by name; any other file there is not listed)."""
    from ...io.ownership import folder_files

    return [f for f in folder_files(out) if OWNER.writes(f)]


def _results(out, cfg, drive: _Drive, sweeps: _Sweeps, odometry, loops, graphs) -> dict:
    """What ``results.json`` holds (the poses of each run left out)."""
    observed = None
    if sweeps.nidar is not None:
        seen = [sweeps.nidar_columns(k)["nidar_observed"] for k in range(cfg.frames)]
        observed = float(np.mean([s.mean() for s in seen]))
    return {
        "config": asdict(cfg),
        "scene": os.path.relpath(drive.scene, out),
        "drive": drive.info,
        "odometry": {k: {a: b for a, b in v.items() if a != "poses"} for k, v in odometry.items()},
        "loops": {s: v["summary"] for s, v in loops.items()},
        "pose_graph": {s: {a: b for a, b in v.items() if a != "poses"} for s, v in graphs.items()},
        "nidar_observed_fraction": observed,
    }


def _report(out, cfg, results, drive: _Drive, odometry, loops, graphs, desc) -> None:
    """``results.json``, ``report.md`` and the figures (:func:`.report.write_report`)."""
    from ...scenegen.city import sample_city
    from ...scenegen.generate import scene_rng
    from .report import write_report

    layout = sample_city(scene_rng(cfg.seed, 0), cfg.kind, tuple(cfg.blocks))[0]
    write_report(
        out,
        results,
        gt=drive.gt,
        odometry=odometry,
        loops=loops,
        graphs=graphs,
        desc=desc,
        layout=layout,
        world_poses=drive.poses,
    )
