"""Step 11 of docs/RESIMULATION.md (:mod:`nidar_mi.resim.holes`, :mod:`nidar_mi.resim.seen_through`)
measured: its radius and margins on training frames alone, and what it changes on the held-out
frames.

``python benchmarks/resim_holes.py --work DIR [--runs NAME,...] [--radii 0.3,0.4,0.5,0.7]``
``python benchmarks/resim_holes.py --work DIR --reaches none,0.25,0.5,1,2 [--runs NAME,...]``
``python benchmarks/resim_holes.py --work DIR --shares 0.3,0.5,0.7,0.9,1 [--runs NAME,...]``
``python benchmarks/resim_holes.py --work DIR --throughs 0.5,0.75,1,2 [--runs NAME,...]``
``python benchmarks/resim_holes.py --work DIR --abstain [--runs NAME,...]``
``python benchmarks/resim_holes.py --work DIR --ab [--runs NAME,...] [--json FILE]``

Radius (the default): the share of a training scan's own real returns that the hole rule would
drop, its training neighbours as the evidence, at each radius (the reach test's margin
``REACH_M``). ``--reaches``: the same at each margin of the reach test (``none``: every return in
the radius counts), radius ``HOLE_RADIUS_DEG``; ``--shares``: at each largest share of returned
beams around a point that the reach test takes for a sparse scan (``SPARSE_SHARE``; 1: any);
``--abstain``: with an evidence scan that cannot see a point keeping it, and leaving it to the
other (``Holes(abstain=...)``). These four measure the holes alone. ``--throughs``: the
see-through test alone at each margin. ``--ab``: each run reconstructed once more
(``nidar_mi.resim.reconstruction.reconstruct`` into a temporary folder, removed afterwards) and
its held-out frames evaluated five times on that one fit (:data:`AB_STEPS`): without the step,
with holes that count every return in the radius (no reach test) and where every evidence scan
decides, with the reach test, with the scans that cannot see a point abstaining (the holes as
they are), and with the see-through test's hiding too: each part's own
effect, free of the run-to-run spread of the fit's threaded sums (a few mm of Chamfer on
``kitti_raw_0926``).

``DIR`` is a ``benchmarks/resim_drives.py --work`` folder: each run's drive in
``DIR/drives/<run>`` and its re-simulation in ``DIR/out/<run>`` (its poses and held-out frames
are read from there; the held-out frames are neither scored nor used as evidence). Every third
training frame with training frames on both sides is scored. A real return the rule drops is a
return the rule would have taken from a real sensor: the radius is the smallest under 0.1 % on
every drive, and the margins are under it too. Prints a markdown table. KITTI is research-only data: only numbers are printed.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _world(xyz, pose):
    """(N, 3) LiDAR-frame points ``xyz`` in the world of the (4, 4) ``pose``."""
    return xyz @ pose[:3, :3].T + pose[:3, 3]


def false_drops(run_dir: Path, out_dir: Path, settings: list[tuple]) -> dict:
    """(radius, reach, share, through, abstain) -> (returns dropped, returns scored) over a
    run's scored training frames (through None: the holes alone; else the see-through test
    alone, each return taken as a point of the static surfaces)."""
    import nidar_mi.resim.holes as rule
    from nidar_mi.io.kitti import read_kitti_poses
    from nidar_mi.resim.drive_folder import open_drive
    from nidar_mi.resim.frames import load_frames
    from nidar_mi.resim.holes import Holes
    from nidar_mi.resim.seen_through import SeenThrough

    report = json.loads((out_dir / "report.json").read_text())
    drive = open_drive(str(run_dir), holdout=report["holdout"], poses_file=None)
    frames = load_frames(drive)
    poses = read_kitti_poses(str(out_dir / "poses.txt"))
    train = [drive.index(i) for i in drive.train]
    scored = [k for k in train[1:-1]][::3]
    out = {}
    shipped = rule.SPARSE_SHARE
    for radius, reach, share, through, abstain in settings:
        rule.SPARSE_SHARE = share  # in_hole reads it when it runs
        try:
            if through is None:
                holes = Holes(
                    frames, poses, train, radius_deg=radius, reach_m=reach, abstain=abstain
                )
                dropped = sum(int(holes.mask(k, frames.xyz[k]).sum()) for k in scored)
            else:
                seen = SeenThrough(frames, poses, train, margin_m=through, radius_deg=radius)
                dropped = sum(
                    int(seen.points(k, _world(frames.xyz[k], poses[k])).sum()) for k in scored
                )
        finally:
            rule.SPARSE_SHARE = shipped
        out[(radius, reach, share, through, abstain)] = (
            dropped,
            sum(len(frames.xyz[k]) for k in scored),
        )
    return out


#: ``--ab``'s evaluations, in order.
AB_STEPS = {
    "without": ({"holes": False, "through": False}, {}),
    "no_reach": ({"holes": True, "through": False}, {"reach_m": None, "abstain": False}),
    "no_abstain": ({"holes": True, "through": False}, {"abstain": False}),
    "no_through": ({"holes": True, "through": False}, {}),
    "with": ({"holes": True, "through": True}, {}),
}
"""name -> (evaluate_heldout's switches, the hole test's arguments)."""


def ab(run_dir: Path, out_dir: Path) -> dict:
    """``{step: mean}`` of one fresh reconstruction's held-out frames evaluated with each of
    :data:`AB_STEPS`."""
    import shutil
    import tempfile

    import nidar_mi.resim.heldout_scans as heldout
    import nidar_mi.resim.holes as holes
    from nidar_mi.backend import set_variant
    from nidar_mi.resim.reconstruction import ReconstructOptions, reconstruct

    holdout = tuple(json.loads((out_dir / "report.json").read_text())["holdout"])
    evaluate, means = heldout.evaluate_heldout, {}

    def each(*args, **kwargs):
        rule = holes.Holes
        for name, (switches, test) in AB_STEPS.items():
            holes.Holes = lambda *a, _t=test, **k: rule(*a, **{**k, **_t})
            try:  # evaluate_heldout imports Holes when it runs
                result = evaluate(*args, **{**kwargs, **switches})
            finally:
                holes.Holes = rule
            means[name] = result["mean"]
        return result

    set_variant()
    tmp = Path(tempfile.mkdtemp(prefix="resim_holes_"))
    heldout.evaluate_heldout = each  # reconstruct imports it when it runs
    try:
        reconstruct(ReconstructOptions(drive=str(run_dir), out=str(tmp / "out"), holdout=holdout))
    finally:
        heldout.evaluate_heldout = evaluate
        shutil.rmtree(tmp, ignore_errors=True)
    return means


def _ab_table(args, runs) -> dict:
    print("| run (" + " → ".join(AB_STEPS) + ") | Chamfer (m) | F@0.1 m | drop agr. |", end="")
    print(" Spearman | RMSE |\n| --- | --- | --- | --- | --- | --- |")
    out = {}
    for run in runs:
        out[run] = m = ab(args.work / "drives" / run, args.work / "out" / run)
        steps = tuple(AB_STEPS)
        cells = [
            " → ".join(f"{m[s][q]:.4f}" for s in steps)
            for q in ("chamfer_m", "fscore", "drop_agreement")
        ] + [
            " → ".join(f"{m[s]['intensity']['resim'][q]:.4f}" for s in steps)
            for q in ("spearman", "rmse")
        ]
        print(f"| `{run}` | " + " | ".join(cells) + " |", flush=True)
    return out


def main(argv=None) -> int:
    from work_folder import work_parser, work_runs

    ap = work_parser(__doc__.split("\n\n")[0])
    one = ap.add_mutually_exclusive_group()  # what to measure: one of these
    one.add_argument("--radii", default="0.3,0.4,0.5,0.7", help="radii, degrees")
    one.add_argument("--reaches", default=None, help="reach margins, m ('none': no reach test)")
    one.add_argument("--shares", default=None, help="sparse shares of the reach test")
    one.add_argument("--throughs", default=None, help="margins of the see-through test, m")
    one.add_argument(
        "--abstain", action="store_true", help="the holes without and with abstaining scans"
    )
    one.add_argument(
        "--ab", action="store_true", help="held-out scores at each step: " + ", ".join(AB_STEPS)
    )
    ap.add_argument("--json", type=Path, default=None, help="--ab: write the means here")
    args = ap.parse_args(argv)
    import signal

    from nidar_mi.cli._common import _on_sigterm

    signal.signal(signal.SIGTERM, _on_sigterm)  # --ab's temporary folder removed on SIGTERM too
    from nidar_mi.resim.holes import HOLE_RADIUS_DEG, REACH_M, SPARSE_SHARE

    if args.reaches:
        reach = [None if r == "none" else float(r) for r in args.reaches.split(",")]
        settings = [(HOLE_RADIUS_DEG, r, SPARSE_SHARE, None, True) for r in reach]
        heads = [f"{r} m" if r is not None else "no reach test" for r in reach]
    elif args.shares:
        settings = [
            (HOLE_RADIUS_DEG, REACH_M, float(f), None, True) for f in args.shares.split(",")
        ]
        heads = [f"share ≤ {f}" for _, _, f, _, _ in settings]
    elif args.throughs:
        margins = [float(m) for m in args.throughs.split(",")]
        settings = [(HOLE_RADIUS_DEG, REACH_M, SPARSE_SHARE, m, True) for m in margins]
        heads = [f"seen through by {m} m" for m in margins]
    elif args.abstain:
        settings = [(HOLE_RADIUS_DEG, REACH_M, SPARSE_SHARE, None, a) for a in (False, True)]
        heads = ["every evidence scan decides", "scans that cannot see a point abstain"]
    else:
        settings = [(float(r), REACH_M, SPARSE_SHARE, None, True) for r in args.radii.split(",")]
        heads = [f"{r}°" for r, _, _, _, _ in settings]
    runs = work_runs(args)
    if args.ab:
        out = _ab_table(args, runs)
        if args.json:
            args.json.write_text(json.dumps(out, indent=1))
        return 0
    print("| run | " + " | ".join(heads) + " |")
    print("| --- |" + " ---: |" * len(settings))
    for run in runs:
        res = false_drops(args.work / "drives" / run, args.work / "out" / run, settings)
        cells = " | ".join(f"{100 * d / max(n, 1):.3f} % ({d} of {n})" for d, n in res.values())
        print(f"| `{run}` | {cells} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main())
