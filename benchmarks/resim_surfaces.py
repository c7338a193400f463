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
of the matched returns and their intensity RMSE and Spearman, as a markdown table. KITTI is
research-only data: only numbers are printed.
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


def run_split(run_dir: Path, out_dir: Path) -> dict:
    """Kind -> (predicted, real) intensities of the matched returns of every held-out frame."""
    from plyfile import PlyData

    from nidar_mi.io.kitti import read_kitti_bin, read_kitti_poses
    from nidar_mi.resim.drive_folder import open_drive
    from nidar_mi.resim.frames import load_frames
    from nidar_mi.resim.scan_scores import matches

    report = json.loads((out_dir / "report.json").read_text())
    drive = open_drive(str(run_dir), holdout=report["holdout"])
    frames = load_frames(drive)
    poses = read_kitti_poses(str(out_dir / "poses.txt"))
    ply = PlyData.read(str(out_dir / "surfaces.ply"))
    vertices = np.stack([np.asarray(ply["vertex"][a], np.float64) for a in "xyz"], 1)
    faces = np.stack(ply["face"]["vertex_indices"])
    out = {kind: ([], []) for kind in KINDS}
    for fid in drive.holdout:
        k = drive.index(fid)
        xyz, intensity = read_kitti_bin(str(out_dir / "heldout" / f"{fid}.bin"))
        ok, idx = matches(frames.xyz[k], xyz)
        world = xyz[idx[ok]] @ poses[k, :3, :3].T + poses[k, :3, 3]
        kind = surface_kind(world, vertices, faces, report["mesh"]["faces"])
        for i, name in enumerate(KINDS):
            out[name][0].append(intensity[idx[ok]][kind == i])
            out[name][1].append(frames.intensity[k][ok][kind == i])
    return {name: tuple(np.concatenate(v) for v in pair) for name, pair in out.items()}


def main(argv=None) -> int:
    from work_folder import work_parser, work_runs

    from nidar_mi.resim.scan_scores import intensity_metrics

    ap = work_parser(__doc__.split("\n\n")[0])
    args = ap.parse_args(argv)
    runs = work_runs(args)
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


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main())
