"""Ground coverage per ring of the HDL-64E layouts against real KITTI frames (docs/SENSORS.md).

``python benchmarks/ground_coverage.py [--kitti DIR ...] [--calibration FILE ...] [--level]
[--rings-csv PATH]``

For each KITTI folder (default: ``../shared/data/kitti`` and ``../shared/data/kitti_raw_0926``,
those that exist) the real ground returns per ring (:func:`kitti_ground_rings`), and for each
set-up a flat road of ``asphalt_old`` scanned at every real frame's pose over its road plane
(``--level``: one level sweep at 1.73 m instead): the ``hdl64e`` preset's uniform table, its
per-laser table (the shipped default), the per-laser table with the old step detection (no
receiver noise), and every calibration file given. Per set-up the ring counts of
:func:`nidar_mi.studies.ground_coverage.compare_rings`: rings compared (at least 50 real ground
returns per frame), median / 90th percentile / both within 10 %; rings whose P(detect) is
compared (200 references), P(detect) of the road at the ring's real range and of the same ring
within 0.1. ``--rings-csv`` writes every ring's row (real statistics included: keep the file
with the data, outside the project). The frames are read where they lie and never copied.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: Where the real frames are looked for: $NIDAR_MI_DATA, else ../shared/data beside the repository.
DATA_ROOT = os.environ.get("NIDAR_MI_DATA") or os.path.join(REPO, "..", "shared", "data")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="ground_coverage.py", description=__doc__.split("\n")[0])
    p.add_argument("--kitti", action="append", help="KITTI folder with velodyne/*.bin (repeatable)")
    p.add_argument(
        "--calibration",
        action="append",
        default=[],
        help="a per-laser calibration file (db.xml, ROS .yaml, Ouster .json) to score too",
    )
    p.add_argument(
        "--level", action="store_true", help="one level sweep at 1.73 m, not the frames' poses"
    )
    p.add_argument("--rings-csv", help="write every ring's comparison to this CSV file")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from nidar_mi.backend import set_variant
    from nidar_mi.datasets.kitti_frames import default_kitti_dirs
    from nidar_mi.errors import NidarError
    from nidar_mi.studies.ground_coverage import (
        compare_rings,
        kitti_ground_rings,
        simulate_flat_road,
        summarize,
    )

    dirs = args.kitti or [str(d) for d in default_kitti_dirs(DATA_ROOT)]
    if not dirs:
        print("skipped: no KITTI frames found (give --kitti DIR)", file=sys.stderr)
        return 0
    for path in args.calibration:
        if not os.path.isfile(path):
            print(f"error: calibration file not found: {path}", file=sys.stderr)
            return 2
    if args.rings_csv and os.path.exists(args.rings_csv):
        print(f"error: {args.rings_csv} exists; not overwritten", file=sys.stderr)
        return 2
    set_variant()
    setups = {
        "hdl64e uniform": {"layout": "uniform"},
        "hdl64e per_laser (default)": {},
        "hdl64e per_laser, step detection": {"noise": 0.0},
    }
    for path in args.calibration:
        setups[f"calibration {os.path.basename(path)}"] = {"calibration_file": path}
    print(
        "| frames | set-up | compared | median | p90 | both | P compared | P at range | P same ring |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    table = []
    try:
        for d in dirs:
            real = kitti_ground_rings(os.path.join(d, "velodyne"), progress=True)
            pose = {} if args.level else {"poses": real.poses, "front_only": real.front_only}
            name = os.path.basename(os.path.normpath(d))
            for setup, values in setups.items():
                try:
                    sim = simulate_flat_road("hdl64e", **values, **pose)
                except ValueError as e:
                    raise NidarError(str(e)) from None
                rows = compare_rings(real, sim)
                s = summarize(rows)
                print(
                    f"| {name} ({real.frames}) | {setup} | {s['compared']} | {s['median_ok']} "
                    f"| {s['p90_ok']} | {s['range_ok']} | {s['p_compared']} "
                    f"| {s['p_at_range_ok']} | {s['p_ok']} |",
                    flush=True,
                )
                table += [{"frames": name, "setup": setup, **row} for row in rows]
    except NidarError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.rings_csv:
        import io

        from nidar_mi.io.atomic import atomic_write_text

        text = io.StringIO()
        w = csv.DictWriter(text, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)
        atomic_write_text(args.rings_csv, text.getvalue())
    return 0


if __name__ == "__main__":
    sys.exit(main())
