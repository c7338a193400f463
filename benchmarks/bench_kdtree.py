"""The package's two k-d tree queries with pykdtree and with scipy's cKDTree, on a real scan.

    .venv/bin/python benchmarks/bench_kdtree.py [--scans DIR] [--rounds 15]

The queries: k = 20 neighbours of every point of a scan, the query shares on two threads (as
:mod:`nidar_mi.geometry.normals` runs it; for cKDTree also with its own ``workers=2``), and the
nearest neighbour within 0.3 m of the next scan's points within 40 m (the drive study's loop
overlap, :func:`nidar_mi.eval.drive.kiss.overlap`). The rounds run every query in turn, so all
see the same machine load; min and median wall times. ``DIR`` holds KITTI ``velodyne/*.bin``
(default: ``$NIDAR_MI_DATA/kitti/velodyne``, else ``../shared/data/kitti/velodyne``); the
results are printed, not the data. docs/BENCHMARKS.md, "The k-d tree library".
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np


def _scan(path: Path) -> np.ndarray:
    xyz = np.fromfile(path, dtype="<f4").reshape(-1, 4)[:, :3]
    return np.ascontiguousarray(xyz, dtype=np.float64)


def queries(p: np.ndarray, q: np.ndarray) -> dict:
    """Name -> a function running one query (module docstring)."""
    from pykdtree.kdtree import KDTree
    from scipy.spatial import cKDTree

    shares = np.array_split(p, 2)
    near = np.ascontiguousarray(q[np.linalg.norm(q[:, :2], axis=1) < 40.0])

    def knn(tree_of):
        def run():
            tree = tree_of(p)
            with ThreadPoolExecutor(2) as pool:
                list(pool.map(lambda s: tree.query(s, k=20), shares))

        return run

    def within(tree_of):
        return lambda: tree_of(p).query(near, k=1, distance_upper_bound=0.3)

    return {
        "k=20, pykdtree": knn(lambda a: KDTree(a, leafsize=16)),
        "k=20, cKDTree (threads)": knn(lambda a: cKDTree(a, leafsize=16)),
        "k=20, cKDTree workers=2": lambda: cKDTree(p, leafsize=16).query(p, k=20, workers=2),
        "within 0.3 m, pykdtree": within(KDTree),
        "within 0.3 m, cKDTree": within(cKDTree),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    data = Path(os.environ.get("NIDAR_MI_DATA") or Path("..") / "shared" / "data")
    p.add_argument("--scans", default=str(data / "kitti" / "velodyne"), help="KITTI velodyne/")
    p.add_argument("--rounds", type=int, default=15, help="rounds of every query (15)")
    args = p.parse_args(argv)
    files = sorted(Path(args.scans).glob("*.bin"))[:2]
    if len(files) < 2:
        print(f"error: two KITTI scans needed in {args.scans}", file=sys.stderr)
        return 2
    runs = queries(_scan(files[0]), _scan(files[1]))
    times: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(args.rounds):
        for name, run in runs.items():
            t0 = time.perf_counter()
            run()
            times[name].append(time.perf_counter() - t0)
    for name, t in times.items():
        print(f"{name:26s} min {1e3 * min(t):7.1f} ms  median {1e3 * statistics.median(t):7.1f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
