"""The drive study's outputs: ``results.json``, ``report.md`` and three figures.

* ``trajectory.png``: the true drive, KISS-ICP's estimate (aligned, as ATE sees it) and the
  pose-graph results per source, seen from above;
* ``pr.png``: precision / recall of the loops per intensity source;
* ``descriptors.png``: one frame's descriptor per source (rings by sectors), with a colour bar;
* ``map.png``: the city from above (buildings, walls, cars, poles and trunks) with the drive and
  the frames that revisit.

Legends sit beside the axes, where they cover no data.
"""

from __future__ import annotations

import os

import numpy as np

__all__ = ["write_report", "markdown_tables"]


def _fmt(v, nd=2, pct=False) -> str:
    if v is None:
        return "–"
    return f"{100 * v:.{nd}f}" if pct else f"{v:.{nd}f}"


def markdown_tables(results: dict) -> str:
    """The odometry, loop and pose-graph tables of a results dict, as Markdown."""
    lines = [
        "### Odometry (KISS-ICP, default configuration)",
        "",
        "| input | ATE RMSE (m) | end drift (% of path) | RPE t (%) | RPE r (deg/m) | RPE per length: t % |",
        "| --- | ---: | ---: | ---: | ---: | --- |",
    ]
    for name, r in results["odometry"].items():
        per = ", ".join(f"{L} m: {t:.2f}" for L, (t, _, _) in r["rpe"]["per_length"].items())
        lines.append(
            f"| {name} | {_fmt(r['ate']['rmse'], 3)} | {_fmt(r['end_drift']['pct'])} | "
            f"{_fmt(r['rpe']['t_err_pct'])} | {_fmt(r['rpe']['r_err_deg_per_m'], 4)} | {per} |"
        )
    lines += [
        "",
        "### Loop closure (scan context per intensity source)",
        "",
        "| source | revisits | correct-loop rate | average precision | max F1 | recall @ 100 % precision | verified loops (wrong) | ATE after pose graph (m) |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for source, s in results["loops"].items():
        g = results["pose_graph"].get(source, {})
        lines.append(
            f"| {source} | {s['revisits']} | {_fmt(s['correct_loop_rate'], 1, True)} % | "
            f"{_fmt(s['average_precision'], 3)} | {_fmt(s['max_f1'], 3)} | "
            f"{_fmt(s['recall_at_p100'], 1, True)} % | {g.get('loops', '–')} "
            f"({g.get('wrong_loops', '–')}) | {_fmt(g.get('ate', {}).get('rmse'), 3)} |"
        )
    return "\n".join(lines) + "\n"


def _figures(out: str, gt, odometry: dict, loops: dict, graphs: dict, desc: dict) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .odometry import ate

    written = []
    fig, ax = plt.subplots(figsize=(7, 6))
    ax.plot(gt[:, 0, 3], gt[:, 1, 3], "k-", lw=2.5, label="ground truth")
    for name, est in ((n, r["poses"]) for n, r in odometry.items()):
        al = ate(gt[: len(est)], est)["aligned"]  # a rendered sequence may be a frame shorter
        ax.plot(al[:, 0, 3], al[:, 1, 3], "-", lw=1.2, label=f"KISS-ICP, {name}")
    for source, g in graphs.items():
        if g["loops"]:
            p = ate(gt, g["poses"])["aligned"]
            ax.plot(p[:, 0, 3], p[:, 1, 3], "--", lw=1, label=f"pose graph, {source} loops")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, first LiDAR frame)")
    ax.set_ylabel("y (m)")
    _outside_legend(ax)
    ax.set_title("Simulated drive: trajectories (aligned for ATE)")
    path = os.path.join(out, "trajectory.png")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    written.append(path)

    fig, ax = plt.subplots(figsize=(6, 5))
    for source, entry in loops.items():
        _, p, r = entry["pr"]
        if len(p):
            ax.plot(np.r_[0.0, r], np.r_[p[0], p], drawstyle="steps-post", label=source)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_xlim(0, 1.02)
    ax.set_ylim(0, 1.02)
    if ax.get_legend_handles_labels()[0]:
        ax.legend()
    else:
        ax.text(0.5, 0.5, "no revisit in this drive", ha="center", va="center")
    ax.set_title("Loop closure: precision / recall per intensity source")
    path = os.path.join(out, "pr.png")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    written.append(path)

    fig = _descriptors_figure(desc, len(gt) // 3)
    path = os.path.join(out, "descriptors.png")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    written.append(path)
    return written


def _outside_legend(ax) -> None:
    """The axes' legend to the right of them, where it covers no data."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, framealpha=0.9)


def _descriptors_figure(desc: dict, k: int):
    """Frame ``k``'s descriptor per source, one row each, with the colour bar of the values."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(desc), 1, figsize=(7.6, 1.3 * len(desc) + 0.6), squeeze=False)
    im = None
    for a, (source, (grids, _, _)) in zip(axes[:, 0], desc.items()):
        im = a.imshow(grids[k], aspect="auto", cmap="viridis", vmin=0, vmax=1, origin="lower")
        a.set_ylabel(source, rotation=0, ha="right", va="center")
        a.set_yticks([])
    axes[-1, 0].set_xlabel("sector (6° each, from -x)")
    if im is not None:
        bar = fig.colorbar(im, ax=list(axes[:, 0]), fraction=0.04, pad=0.02)
        bar.set_label(
            "largest value in the bin / the source's 99th percentile (0: empty)", fontsize=8
        )
    fig.suptitle(f"Descriptors of frame {k} (rings up to 40 m, value per bin)")
    return fig


def _map(out: str, layout, world_poses, revisit) -> str:
    import matplotlib.pyplot as plt

    fig = _map_figure(layout, world_poses, revisit)
    path = os.path.join(out, "map.png")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def _map_figure(layout, world_poses, revisit):
    """The city from above with the drive; the legend beside the map, not over it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ...scenegen.primitives import Block, Cylinder

    fig, ax = plt.subplots(figsize=(8, 6.5))
    colours = {"_b": "0.3", "_car": "tab:red", "_w": "tab:brown", "_gw": "tab:brown"}
    for s in layout.shapes:
        if isinstance(s, Block) and s.center[2] + s.half_size[2] > 0.4:
            a = np.radians(s.yaw_deg)
            R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
            hx, hy = s.half_size[:2]
            c = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy], [-hx, -hy]]) @ R.T
            c = c + np.array(s.center[:2])
            colour = next((v for k, v in colours.items() if k in s.id), "tab:blue")
            ax.plot(c[:, 0], c[:, 1], "-", color=colour, lw=0.6)
        elif isinstance(s, Cylinder) and s.p0[2] == 0.0 and s.p1[2] > 1.5:
            ax.plot(s.p0[0], s.p0[1], ".", color="tab:green", ms=2)
    p = world_poses[:, :3, 3]
    ax.plot(p[:, 0], p[:, 1], "m-", lw=1.2, label="drive")
    ax.plot(p[revisit, 0], p[revisit, 1], "o", color="tab:orange", ms=3, label="revisiting frames")
    ax.plot(p[0, 0], p[0, 1], "k^", ms=8, label="start")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    _outside_legend(ax)
    ax.set_title(
        "The city from above: buildings (grey), cars (red), walls (brown), poles and trunks (green)"
    )
    return fig


def write_report(
    out: str, results: dict, *, gt, odometry, loops, graphs, desc, layout=None, world_poses=None
) -> None:
    """Write ``results.json``, ``report.md`` and the figures into ``out`` (``map.png`` when the
    ``layout`` and the ``world_poses`` (N, 4, 4) are given)."""
    from ...io.atomic import atomic_write_json, atomic_write_text

    figures = _figures(out, gt, odometry, loops, graphs, desc)
    if layout is not None and world_poses is not None and loops:
        revisit = next(iter(loops.values()))["matches"].revisit
        figures.append(_map(out, layout, world_poses, revisit))
    results["figures"] = [os.path.basename(p) for p in figures]
    atomic_write_json(os.path.join(out, "results.json"), results)
    cfg = results["config"]
    head = (
        f"# Drive study: {cfg['kind']} seed {cfg['seed']}, {cfg['frames']} frames at "
        f"{cfg['rate_hz']:g} Hz, {results['drive']['length_m']:.0f} m, "
        f"{results['drive']['revisits']} revisits\n\n"
    )
    timing = ", ".join(f"{k} {v:.0f} s" for k, v in cfg["timings"].items())
    body = markdown_tables(results) + f"\nWall times: {timing}.\n\n"
    body += "".join(f"![{p}]({p})\n" for p in results["figures"])
    atomic_write_text(os.path.join(out, "report.md"), head + body)
