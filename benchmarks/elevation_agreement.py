"""Elevation agreement of the HDL-64E layouts with real KITTI returns (docs/SENSORS.md).

``python benchmarks/elevation_agreement.py [--kitti DIR ...] [--calibration FILE ...]``

For each KITTI folder (default: ``../shared/data/kitti`` and ``../shared/data/kitti_raw_0926``,
those that exist) and each layout (the ``hdl64e`` preset's uniform table, its per-laser table,
and every calibration file given), the median and 90th percentile of |Δelevation| of the real
returns against the simulator's beams, ring-matched and nearest-ring
(:mod:`nidar_mi.eval.layout_agreement`). The frames are read where they lie and never copied.
"""

from __future__ import annotations

import argparse
import os
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: Where the real frames are looked for: $NIDAR_MI_DATA, else ../shared/data beside the repository.
DATA_ROOT = os.environ.get("NIDAR_MI_DATA") or os.path.join(REPO, "..", "shared", "data")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="elevation_agreement.py", description=__doc__.split("\n")[0])
    p.add_argument("--kitti", action="append", help="KITTI folder with velodyne/*.bin (repeatable)")
    p.add_argument(
        "--calibration",
        action="append",
        default=[],
        help="a per-laser calibration file (db.xml, ROS .yaml, Ouster .json) to score too",
    )
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from nidar_mi.datasets.kitti_frames import default_kitti_dirs
    from nidar_mi.errors import NidarError
    from nidar_mi.eval.layout_agreement import elevation_agreement
    from nidar_mi.lidar.config import LidarConfig

    dirs = args.kitti or [str(d) for d in default_kitti_dirs(DATA_ROOT)]
    if not dirs:
        print("skipped: no KITTI frames found (give --kitti DIR)", file=sys.stderr)
        return 0
    layouts = {"hdl64e uniform": {"preset": "hdl64e", "layout": "uniform"}}
    layouts["hdl64e per_laser"] = {"preset": "hdl64e", "layout": "per_laser"}
    for path in args.calibration:
        layouts[f"calibration {os.path.basename(path)}"] = {
            "preset": "hdl64e",
            "calibration_file": path,
        }
    print(
        "| frames | layout | returns | ring-matched median / p90 (°) | nearest median / p90 (°) |"
    )
    print("|---|---|---:|---:|---:|")
    try:
        for d in dirs:
            for name, values in layouts.items():
                try:
                    pattern = LidarConfig.from_mapping("l", values).pattern
                except ValueError as e:
                    raise NidarError(str(e)) from None
                a = elevation_agreement(pattern, os.path.join(d, "velodyne"))
                skipped = f" ({len(a.skipped)} skipped)" if a.skipped else ""
                print(
                    f"| {os.path.basename(os.path.normpath(d))} ({len(a.frames)}{skipped}) | {name} "
                    f"| {a.returns} | {a.ring_matched_median:.4f} / {a.ring_matched_p90:.4f} "
                    f"| {a.nearest_median:.4f} / {a.nearest_p90:.4f} |",
                    flush=True,
                )
    except NidarError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
