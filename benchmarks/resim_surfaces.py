"""Where the re-simulated intensities miss: each held-out frame's matched returns split by the
surface that the re-simulated return lies on (docs/RESIMULATION.md, "Where the intensity error
is").

``python benchmarks/resim_surfaces.py --work DIR [--runs NAME,...]``

``DIR`` is a ``benchmarks/resim_drives.py --work`` folder (each run's drive in
``DIR/drives/<run>``, its re-simulation in ``DIR/out/<run>``). Each held-out frame's real
returns are matched to its re-simulated scan (``OUT/heldout/<id>.bin``) as the command scores
them (:func:`nidar_mi.resim.scan_scores.matches`: the nearest re-simulated return within
0.1 m). Each matched re-simulated return, moved into world coordinates by the frame's pose, is
put on the nearest triangle of ``OUT/surfaces.ply`` (Open3D's closest-point query): a triangle
of the fused mesh (the first ``report.json["mesh"]["faces"]``), or of a splat (the rest); one
farther than :data:`ON_PLY_M` from both lies on the surfaces that moved, which are added per
held-out frame and are not in that file (a moving surface within that distance of a static one
counts as the static one). Prints, per run over its held-out frames together, each kind's share
of the matched returns and their intensity RMSE and Spearman, as a markdown table.

``--chamfer`` prints where the geometry misses instead (docs/RESIMULATION.md, "Where the
geometry error is"): the two halves of the Chamfer distance, the re-simulated-to-real half
split by the kind of surface every re-simulated return lies on (its share of the returns and
its part of the half), and the re-simulated returns of the fused mesh farther than
:data:`FAR_M` from every real return by what the real beam next to each one saw
(:func:`far_causes`). KITTI is research-only data: only numbers are printed.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

#: A re-simulated return farther than this from every triangle of ``surfaces.ply`` lies on the
#: surfaces that moved, m.
ON_PLY_M = 0.05
KINDS = ("mesh", "splat", "moving")
#: A re-simulated return farther than this from every real return is in the Chamfer's tail, m.
FAR_M = 0.5
#: A re-simulated return's real beam: the real return nearest to it in direction, within this
#: angle (deg; the HDL-64E's columns are 0.17° apart, its rings 0.3-0.5°).
BEAM_DEG = 0.3
CAUSES = ("real nearer", "real farther", "no real return", "within FAR_M")


def far_causes(sim: np.ndarray, real: np.ndarray) -> np.ndarray:
    """(N,) what the real scan saw along each re-simulated return's beam: ``sim`` (N, 3) and
    ``real`` (M, 3), both in the sensor's frame, m. The real return nearest in direction
    within :data:`BEAM_DEG`: 0 when it is more than :data:`FAR_M` nearer (the scene had an
    occluder there that the re-simulation lacks), 1 when more than ``FAR_M`` farther (the
    re-simulation has a surface that the scene did not have then), 3 when within ``FAR_M``
    in range; 2 when there is none (the sensor returned nothing there)."""
    from scipy.spatial import cKDTree

    def unit(p):
        return p / np.linalg.norm(p, axis=1, keepdims=True)

    chord = 2.0 * np.sin(np.radians(BEAM_DEG) / 2.0)
    gap, j = cKDTree(unit(real)).query(unit(sim), distance_upper_bound=chord)
    seen = np.isfinite(gap)
    r_sim = np.linalg.norm(sim, axis=1)
    r_real = np.full(len(sim), np.nan)
    r_real[seen] = np.linalg.norm(real[j[seen]], axis=1)
    cause = np.full(len(sim), 2)
    cause[seen] = 3
    cause[seen & (r_real < r_sim - FAR_M)] = 0
    cause[seen & (r_real > r_sim + FAR_M)] = 1
    return cause


def surface_kind(world: np.ndarray, vertices, faces, mesh_faces: int) -> np.ndarray:
    """(N,) 0 (the fused mesh), 1 (a splat) or 2 (neither: the surfaces that moved) for
    (N, 3) world points, the triangles ``faces`` (T, 3) over ``vertices`` (V, 3), m, the first
    ``mesh_faces`` of them the fused mesh's."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(np.asarray(vertices, np.float32), np.asarray(faces, np.uint32))
    found = scene.compute_closest_points(o3d.core.Tensor(np.asarray(world, np.float32)))
    gap = np.linalg.norm(found["points"].numpy() - world, axis=1)
    prim = found["primitive_ids"].numpy().astype(np.int64)
    return np.where(gap > ON_PLY_M, 2, np.where(prim >= mesh_faces, 1, 0))


def _run(run_dir: Path, out_dir: Path):
    """``(frames, kind_of, scans)`` of one run: its drive's frames, ``kind_of(xyz, k)`` (the
    :func:`surface_kind` of frame ``k``'s (N, 3) sensor-frame points) and, per held-out frame,
    ``(k, xyz, intensity)`` of its re-simulated scan."""
    from plyfile import PlyData

    from nidar_mi.io.kitti import read_kitti_bin, read_kitti_poses
    from nidar_mi.resim.drive_folder import open_drive
    from nidar_mi.resim.frames import load_frames

    report = json.loads((out_dir / "report.json").read_text())
    drive = open_drive(str(run_dir), holdout=report["holdout"])
    frames = load_frames(drive)
    poses = read_kitti_poses(str(out_dir / "poses.txt"))
    ply = PlyData.read(str(out_dir / "surfaces.ply"))
    vertices = np.stack([np.asarray(ply["vertex"][a], np.float64) for a in "xyz"], 1)
    faces = np.stack(ply["face"]["vertex_indices"])

    def kind_of(xyz, k):
        world = xyz @ poses[k, :3, :3].T + poses[k, :3, 3]
        return surface_kind(world, vertices, faces, report["mesh"]["faces"])

    scans = [
        (drive.index(fid), *read_kitti_bin(str(out_dir / "heldout" / f"{fid}.bin")))
        for fid in drive.holdout
    ]
    return frames, kind_of, scans


def run_chamfer(run_dir: Path, out_dir: Path) -> dict:
    """The Chamfer split of one run over its held-out frames together (module docstring):
    ``sim_to_real`` and ``real_to_sim`` (the halves' means, m), per kind its ``share`` of the
    re-simulated returns and ``part`` of the first half (m), ``far`` (the share of the
    returns farther than :data:`FAR_M`; ``far_part``, m, their part of the half) and
    ``causes`` (the shares of :data:`CAUSES` among the fused mesh's far returns)."""
    from scipy.spatial import cKDTree

    frames, kind_of, scans = _run(run_dir, out_dir)
    d_sr, d_rs, kinds, causes = [], [], [], []
    for k, xyz, _ in scans:
        real = frames.xyz[k]
        d = cKDTree(real).query(xyz)[0]
        kind = kind_of(xyz, k)
        d_sr.append(d)
        d_rs.append(cKDTree(xyz).query(real)[0])
        kinds.append(kind)
        causes.append(far_causes(xyz[(kind == 0) & (d > FAR_M)], real))
    d, kind, cause = (np.concatenate(v) for v in (d_sr, kinds, causes))
    n = len(d)
    return {
        "sim_to_real": float(d.mean()),
        "real_to_sim": float(np.concatenate(d_rs).mean()),
        "kinds": {
            name: {"share": float(np.mean(kind == i)), "part": float(d[kind == i].sum() / n)}
            for i, name in enumerate(KINDS)
        },
        "far": float(np.mean(d > FAR_M)),
        "far_part": float(d[d > FAR_M].sum() / n),
        "causes": {c: float(np.mean(cause == i)) for i, c in enumerate(CAUSES)},
    }


def run_split(run_dir: Path, out_dir: Path) -> dict:
    """Kind -> (predicted, real) intensities of the matched returns of every held-out frame."""
    from nidar_mi.resim.scan_scores import matches

    frames, kind_of, scans = _run(run_dir, out_dir)
    out = {kind: ([], []) for kind in KINDS}
    for k, xyz, intensity in scans:
        ok, idx = matches(frames.xyz[k], xyz)
        kind = kind_of(xyz[idx[ok]], k)
        for i, name in enumerate(KINDS):
            out[name][0].append(intensity[idx[ok]][kind == i])
            out[name][1].append(frames.intensity[k][ok][kind == i])
    return {name: tuple(np.concatenate(v) for v in pair) for name, pair in out.items()}


def main(argv=None) -> int:
    from work_folder import work_parser, work_runs

    from nidar_mi.resim.scan_scores import intensity_metrics

    ap = work_parser(__doc__.split("\n\n")[0])
    ap.add_argument("--chamfer", action="store_true", help="where the geometry misses instead")
    args = ap.parse_args(argv)
    runs = work_runs(args)
    if args.chamfer:
        return _chamfer_table(args.work, runs)
    head = " | ".join(f"{k}: share / RMSE / Spearman" for k in KINDS)
    print(f"| run | all: RMSE | {head} |")
    print("| --- | ---: |" + " ---: |" * len(KINDS))
    for run in runs:
        split = run_split(args.work / "drives" / run, args.work / "out" / run)
        n = sum(len(v[1]) for v in split.values())
        pred = np.concatenate([v[0] for v in split.values()])
        real = np.concatenate([v[1] for v in split.values()])
        cells = []
        for kind in KINDS:
            p, y = split[kind]
            m = intensity_metrics(p, y)
            cells.append(f"{len(y) / max(n, 1):.3f} / {m['rmse']:.3f} / {m['spearman']:.3f}")
        print(
            f"| `{run}` | {intensity_metrics(pred, real)['rmse']:.3f} | {' | '.join(cells)} |",
            flush=True,
        )
    return 0


def _chamfer_table(work: Path, runs: list[str]) -> int:
    kinds = " | ".join(f"{k}: share / part" for k in KINDS)
    causes = " / ".join(CAUSES)
    print(
        f"| run | Chamfer: sim→real + real→sim | {kinds} | far: share / part | mesh's far: {causes} |"
    )
    print("| --- | --- |" + " ---: |" * (len(KINDS) + 2))
    for run in runs:
        c = run_chamfer(work / "drives" / run, work / "out" / run)
        cells = [f"{v['share']:.3f} / {v['part']:.3f}" for v in c["kinds"].values()]
        why = " / ".join(f"{v:.2f}" for v in c["causes"].values())
        print(
            f"| `{run}` | {c['sim_to_real']:.3f} + {c['real_to_sim']:.3f} | {' | '.join(cells)} "
            f"| {c['far']:.3f} / {c['far_part']:.3f} | {why} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main())
