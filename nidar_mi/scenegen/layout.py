"""Seeded sampling of scene layouts: urban streets and vegetated paths.

:func:`sample_layout` is a pure function of its :class:`numpy.random.Generator`: the same
generator state gives the same :class:`~.primitives.Layout`. Both kinds share one frame: the
road or path runs along +x from :data:`X_MIN` to :data:`X_MAX`, the rig stands near x = 0 in
the right-hand lane (or on the path) looking along +x, z is up.

* ``urban``: a two- or four-lane road (optional parking strips, a cross street, a zebra
  crossing), lane and edge markings, kerbed sidewalks, ground strips and patches, rows of
  buildings with windows and doors, parked and moving vehicles, street lights, sign posts,
  street trees, bushes and clutter.
* ``vegetated``: a path through grass and soil patches, trees, bushes, boulders, benches, lamp
  posts, trail signs, sometimes a shed and a parked car.
"""

from __future__ import annotations

import math

import numpy as np

from .objects import (
    building,
    bush,
    clutter,
    pick,
    rnd,
    sign_post,
    street_light,
    tree,
    vehicle,
)
from .primitives import Block, Layout, Patch, Rig, Shape, Sky, Sun

__all__ = ["KINDS", "X_MIN", "X_MAX", "sample_layout", "sample_rig", "sample_light"]

KINDS = ("urban", "vegetated")
#: Extent of the road/path along x, m.
X_MIN, X_MAX = -40.0, 90.0
LIDAR_PRESETS = ("hdl64e", "vlp16")
_BASE_Z = -0.03  # the far ground plane lies just below the modelled ground


class _Placer:
    """Rejects footprints (circles) that overlap those already placed."""

    def __init__(self) -> None:
        self.taken: list[tuple[float, float, float]] = []

    def free(self, x: float, y: float, r: float) -> bool:
        return all(math.hypot(x - a, y - b) >= r + c for a, b, c in self.taken)

    def take(self, x: float, y: float, r: float) -> bool:
        if not self.free(x, y, r):
            return False
        self.taken.append((x, y, r))
        return True


def _segments(lo: float, hi: float, holes: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The parts of [lo, hi] outside the ``holes`` intervals."""
    out, start = [], lo
    for a, b in sorted(holes):
        if a > start:
            out.append((start, min(a, hi)))
        start = max(start, b)
    if start < hi:
        out.append((start, hi))
    return [(a, b) for a, b in out if b - a > 0.05]


def _strip(id_: str, material: str, x0: float, x1: float, y0: float, y1: float, z: float) -> Patch:
    """A horizontal rectangle spanning [x0, x1] x [y0, y1] at height z."""
    return Patch(
        id_,
        material,
        (rnd((x0 + x1) / 2), rnd((y0 + y1) / 2), rnd(z)),
        (rnd((x1 - x0) / 2), rnd(abs(y1 - y0) / 2)),
    )


def sample_light(rng: np.random.Generator) -> tuple[Sun, Sky]:
    """A random sun (elevation 12-70 deg, any azimuth, irradiance x0.6-1.1) and sky (x0.6-1.6)."""
    sun = Sun(
        elevation_deg=rnd(rng.uniform(12.0, 70.0), 2),
        azimuth_deg=rnd(rng.uniform(0.0, 360.0), 2),
        scale=rnd(rng.uniform(0.6, 1.1)),
    )
    return sun, Sky(scale=rnd(rng.uniform(0.6, 1.6)))


def sample_rig(rng: np.random.Generator, x: float, y: float, heading_deg: float) -> Rig:
    """A roof rig at (x, y) facing about ``heading_deg``.

    The LiDAR (HDL-64E or VLP-16) stands 1.6-2.0 m high, yawed by up to 6 deg; the camera sits
    0.1-0.4 m ahead of it, up to 0.15 m to either side and up to 0.15 m lower, yawed by up to
    4 deg from the LiDAR and pitched 0-6 deg down, with a horizontal field of view of 70-90 deg.
    """
    preset = LIDAR_PRESETS[int(rng.integers(len(LIDAR_PRESETS)))]
    height = rng.uniform(1.6, 2.0)
    yaw = heading_deg + rng.uniform(-6.0, 6.0)
    fwd, side, dz = rng.uniform(0.1, 0.4), rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.0)
    a = math.radians(yaw)
    cam = (x + fwd * math.cos(a) - side * math.sin(a), y + fwd * math.sin(a) + side * math.cos(a))
    return Rig(
        lidar_preset=preset,
        lidar_position=(rnd(x), rnd(y), rnd(height)),
        lidar_yaw_deg=rnd(yaw, 2),
        camera_position=(rnd(cam[0]), rnd(cam[1]), rnd(height + dz)),
        camera_yaw_deg=rnd(yaw + rng.uniform(-4.0, 4.0), 2),
        camera_pitch_deg=rnd(rng.uniform(-6.0, 0.0), 2),
        camera_fov_deg=rnd(rng.uniform(70.0, 90.0), 2),
    )


def _urban(rng: np.random.Generator) -> tuple[list[Shape], tuple[float, float]]:
    shapes: list[Shape] = []
    placer = _Placer()
    lane_w = rng.uniform(3.0, 3.75)
    lanes = 4 if rng.random() < 0.25 else 2
    park_l = rng.uniform(2.0, 2.5) if rng.random() < 0.6 else 0.0
    park_r = rng.uniform(2.0, 2.5) if rng.random() < 0.6 else 0.0
    half = lanes * lane_w / 2
    y_lo, y_hi = -half - park_r, half + park_l  # road edges (kerb lines)
    cross = None
    if rng.random() < 0.4:
        xc, cw = rng.uniform(18.0, 50.0), rng.uniform(7.0, 12.0)
        cross = (xc - cw / 2, xc + cw / 2)
    holes = [cross] if cross else []
    # the rig, in a right-hand lane, keeps 5 m clear around it (a tree reaches 4.5 m from its trunk)
    rig_lane = 0 if lanes == 2 or rng.random() < 0.5 else 1
    rig_xy = (0.0, -lane_w * (rig_lane + 0.5) + rng.uniform(-0.3, 0.3))
    placer.take(rig_xy[0], rig_xy[1], 5.0)

    # ---- ground: far plane, road, cross street
    shapes.append(
        Patch("ground_base", pick(rng, "urban_ground"), (25.0, 0.0, _BASE_Z), (150.0, 150.0))
    )
    road = pick(rng, "road")
    shapes.append(_strip("road", road, X_MIN, X_MAX, y_lo, y_hi, 0.0))
    if cross:
        shapes.append(_strip("cross_road_left", road, *cross, y_hi, 70.0, 0.0))
        shapes.append(_strip("cross_road_right", road, *cross, -70.0, y_lo, 0.0))

    # ---- markings (5 mm above the road)
    paint = pick(rng, "marking")
    centre_solid = lanes == 4 or rng.random() < 0.3
    dash, gap = rng.uniform(2.0, 4.0), rng.uniform(4.0, 9.0)
    lines = [(0.0, centre_solid)] + [(y, False) for y in ((-lane_w, lane_w) if lanes == 4 else ())]
    for i, (yl, solid) in enumerate(lines):
        if solid:
            for j, (a, b) in enumerate(_segments(X_MIN, X_MAX, holes)):
                shapes.append(_strip(f"line_{i}_{j}", paint, a, b, yl - 0.07, yl + 0.07, 0.005))
            continue
        x, k = X_MIN + rng.uniform(0.0, gap), 0
        while x + dash < X_MAX:
            if not cross or x + dash < cross[0] or x > cross[1]:
                shapes.append(
                    _strip(f"dash_{i}_{k}", paint, x, x + dash, yl - 0.07, yl + 0.07, 0.005)
                )
                k += 1
            x += dash + gap
    edge = pick(rng, "marking") if rng.random() < 0.3 else "lane_paint_white"
    for side, yl in (("left", half - 0.2), ("right", -half + 0.2)):
        for j, (a, b) in enumerate(_segments(X_MIN, X_MAX, holes)):
            shapes.append(_strip(f"edge_{side}_{j}", edge, a, b, yl - 0.06, yl + 0.06, 0.005))
    if rng.random() < 0.5:  # zebra crossing ahead of the rig
        xz = cross[0] - 3.5 if cross else rng.uniform(12.0, 45.0)
        y = -half + 0.3
        k = 0
        while y + 0.5 < half - 0.3:
            shapes.append(
                _strip(f"zebra_{k}", "lane_paint_white", xz - 1.5, xz + 1.5, y, y + 0.5, 0.006)
            )
            y, k = y + 1.0, k + 1

    # ---- sidewalks (kerbed blocks) and the ground strips behind them
    kerb = rng.uniform(0.1, 0.18)
    walk = pick(rng, "sidewalk")
    widths = {"left": rng.uniform(1.8, 4.0), "right": rng.uniform(1.8, 4.0)}
    edges = {"left": (y_hi, 1.0), "right": (y_lo, -1.0)}
    for side, (y0, s) in edges.items():
        w = widths[side]
        for j, (a, b) in enumerate(_segments(X_MIN, X_MAX, holes)):
            ya, yb = sorted((y0, y0 + s * w))
            shapes.append(
                Block(
                    f"sidewalk_{side}_{j}",
                    walk,
                    (rnd((a + b) / 2), rnd((ya + yb) / 2), rnd(kerb / 2)),
                    (rnd((b - a) / 2), rnd(w / 2), rnd(kerb / 2)),
                )
            )
            ya, yb = sorted((y0 + s * w, y0 + s * 60.0))
            shapes.append(
                _strip(f"ground_{side}_{j}", pick(rng, "urban_ground"), a, b, ya, yb, 0.0)
            )
        # buildings along this side
        xb = X_MIN + rng.uniform(0.0, 6.0)
        k = 0
        while xb < X_MAX - 6.0:
            length, depth = rng.uniform(8.0, 25.0), rng.uniform(8.0, 16.0)
            setback = rng.uniform(0.5, 7.0)
            x0, x1 = xb, min(xb + length, X_MAX)
            build = rng.random() < 0.85
            if (
                build
                and (not cross or x1 < cross[0] - 1.0 or x0 > cross[1] + 1.0)
                and x1 - x0 > 5.0
            ):
                yc = y0 + s * (w + setback + depth / 2)
                heading = -90.0 if s > 0 else 90.0
                shapes += building(
                    rng, f"bldg_{side}_{k}", (x0 + x1) / 2, yc, heading, x1 - x0, depth
                )
                k += 1
            xb = x1 + rng.uniform(0.0, 8.0)
        # street trees, lights and signs on the sidewalk
        if rng.random() < 0.6:
            xt = X_MIN + rng.uniform(0.0, 10.0)
            k = 0
            while xt < X_MAX:
                yt = y0 + s * w * rng.uniform(0.55, 0.8)
                if (not cross or not cross[0] - 2 < xt < cross[1] + 2) and placer.take(xt, yt, 1.0):
                    shapes += tree(rng, f"tree_{side}_{k}", xt, yt)
                    k += 1
                xt += rng.uniform(8.0, 16.0)
        if rng.random() < 0.7:
            xl = X_MIN + rng.uniform(0.0, 15.0)
            k = 0
            while xl < X_MAX:
                yl = y0 + s * 0.4
                if (not cross or not cross[0] - 1 < xl < cross[1] + 1) and placer.take(xl, yl, 0.6):
                    shapes += street_light(rng, f"light_{side}_{k}", xl, yl, -90.0 * s)
                    k += 1
                xl += rng.uniform(20.0, 35.0)
        for k in range(int(rng.integers(0, 3))):
            xs, ys = rng.uniform(5.0, 60.0), y0 + s * rng.uniform(0.3, 0.6)
            heading = (
                180.0 + rng.uniform(-20.0, 20.0) if rng.random() < 0.8 else rng.uniform(0, 360)
            )
            if placer.take(xs, ys, 0.6):
                shapes += sign_post(rng, f"sign_{side}_{k}", xs, ys, heading)

    # ---- vehicles: parked in the strips, moving in the lanes
    for side, width, y_edge, heading in (
        ("left", park_l, y_hi, 180.0),
        ("right", park_r, y_lo, 0.0),
    ):
        if width <= 0.0:
            continue
        yv = y_edge - math.copysign(width / 2, y_edge)
        xv, k = X_MIN + rng.uniform(0.0, 5.0), 0
        while xv < X_MAX - 3.0:
            occupied = rng.random() < 0.6
            if (
                occupied
                and (not cross or not cross[0] - 4 < xv < cross[1] + 4)
                and placer.take(xv, yv, 2.4)
            ):
                shapes += vehicle(rng, f"car_{side}_{k}", xv, yv, heading + rng.uniform(-3.0, 3.0))
                k += 1
            xv += rng.uniform(5.5, 8.5)
    for k in range(int(rng.integers(0, 5))):
        lane = int(rng.integers(lanes))
        yv = -half + lane_w * (lane + 0.5) + rng.uniform(-0.3, 0.3)
        heading = 0.0 if yv < 0 else 180.0
        xv = rng.uniform(-30.0, 80.0)
        if placer.take(xv, yv, 2.6):
            shapes += vehicle(rng, f"car_lane_{k}", xv, yv, heading + rng.uniform(-2.0, 2.0))

    # ---- patches of other ground cover behind the sidewalks (2 mm apart, clear of a cross street)
    for k in range(int(rng.integers(0, 5))):
        s = 1.0 if rng.random() < 0.5 else -1.0
        side = "left" if s > 0 else "right"
        hx, hy = rng.uniform(2.0, 8.0), rng.uniform(1.0, 5.0)
        xc = rng.uniform(X_MIN + hx, X_MAX - hx)
        yc = edges[side][0] + s * (widths[side] + hy + rng.uniform(0.0, 8.0))
        if not cross or xc + hx < cross[0] or xc - hx > cross[1]:
            shapes.append(
                Patch(
                    f"patch_{k}",
                    pick(rng, "urban_ground"),
                    (rnd(xc), rnd(yc), rnd(0.002 * (k + 1))),
                    (rnd(hx), rnd(hy)),
                )
            )

    # ---- bushes and clutter beside the road (not on a cross street)
    for k in range(int(rng.integers(2, 12))):
        s = 1.0 if rng.random() < 0.5 else -1.0
        edge = y_hi if s > 0 else y_lo
        xb_, yb_ = rng.uniform(-20.0, 75.0), edge + s * rng.uniform(0.4, 6.0)
        on_cross = cross is not None and cross[0] - 1.0 < xb_ < cross[1] + 1.0
        if not on_cross and placer.take(xb_, yb_, 0.7):
            maker = bush if rng.random() < 0.4 else clutter
            shapes += maker(rng, f"clutter_{k}", xb_, yb_)
    return shapes, rig_xy


def _vegetated(rng: np.random.Generator) -> tuple[list[Shape], tuple[float, float]]:
    shapes: list[Shape] = []
    placer = _Placer()
    half = rng.uniform(1.0, 2.3)
    shapes.append(
        Patch("ground_base", pick(rng, "wild_ground"), (25.0, 0.0, _BASE_Z), (150.0, 150.0))
    )
    shapes.append(_strip("path", pick(rng, "path"), X_MIN, X_MAX, -half, half, 0.0))
    for side, s in (("left", 1.0), ("right", -1.0)):
        ya, yb = sorted((s * half, s * 60.0))
        shapes.append(_strip(f"ground_{side}", pick(rng, "wild_ground"), X_MIN, X_MAX, ya, yb, 0.0))
    for k in range(int(rng.integers(3, 9))):  # patches of other cover, stacked 2 mm apart
        s = 1.0 if rng.random() < 0.5 else -1.0
        hx, hy = rng.uniform(2.0, 10.0), rng.uniform(1.5, 6.0)
        yc = s * (half + 0.3 + hy + rng.uniform(0.0, 15.0))
        shapes.append(
            Patch(
                f"patch_{k}",
                pick(rng, "wild_ground"),
                (rnd(rng.uniform(-25.0, 75.0)), rnd(yc), rnd(0.002 * (k + 1))),
                (rnd(hx), rnd(hy)),
            )
        )
    rig_xy = (0.0, rnd(rng.uniform(-0.3, 0.3)))
    placer.take(rig_xy[0], rig_xy[1], 5.0)
    placer.take(0.0, 0.0, half)  # nothing on the path near the rig

    def beside(lo: float, hi: float) -> tuple[float, float]:
        s = 1.0 if rng.random() < 0.5 else -1.0
        return rng.uniform(-35.0, 85.0), s * (half + rng.uniform(lo, hi))

    for k in range(int(rng.integers(12, 36))):
        x, y = beside(1.0, 40.0)
        if placer.take(x, y, 1.2):
            shapes += tree(rng, f"tree_{k}", x, y)
    for k in range(int(rng.integers(8, 26))):
        x, y = beside(0.5, 25.0)
        if placer.take(x, y, 0.8):
            shapes += bush(rng, f"bush_{k}", x, y)
    for k in range(int(rng.integers(2, 9))):
        x, y = beside(0.3, 6.0)
        if placer.take(x, y, 0.8):
            shapes += clutter(rng, f"clutter_{k}", x, y)
    for k in range(int(rng.integers(0, 4))):
        x, y = beside(0.3, 0.6)
        if placer.take(x, y, 0.5):
            shapes += street_light(rng, f"light_{k}", x, y, -90.0 if y > 0 else 90.0)
    for k in range(int(rng.integers(0, 3))):
        x, y = beside(0.3, 1.0)
        if placer.take(x, y, 0.5):
            shapes += sign_post(rng, f"sign_{k}", x, y, 180.0 + rng.uniform(-30.0, 30.0))
    if rng.random() < 0.3:
        x, y = beside(6.0, 15.0)
        if placer.take(x, y, 5.0):
            shapes += building(
                rng, "shed", x, y, -90.0 if y > 0 else 90.0, rng.uniform(5, 9), rng.uniform(4, 7)
            )
    if rng.random() < 0.3:
        x, y = beside(1.5, 3.0)
        if placer.take(x, y, 2.6):
            shapes += vehicle(rng, "car", x, y, rng.uniform(0.0, 360.0))
    return shapes, rig_xy


def sample_layout(rng: np.random.Generator, kind: str | None = None) -> Layout:
    """Draw one layout.

    Args:
        rng: the only source of randomness.
        kind: ``urban``, ``vegetated``, or None to draw it (60 % urban).

    Returns:
        The layout: shapes with library materials, sun, sky and rig.
    """
    if kind is None:
        kind = "urban" if rng.random() < 0.6 else "vegetated"
    if kind not in KINDS:
        raise ValueError(f"unknown layout kind '{kind}' (choose from {', '.join(KINDS)})")
    shapes, (x, y) = (_urban if kind == "urban" else _vegetated)(rng)
    sun, sky = sample_light(rng)
    rig = sample_rig(rng, x, y, 0.0)
    ids = [s.id for s in shapes]
    assert len(ids) == len(set(ids)), "duplicate shape ids"
    return Layout(kind=kind, shapes=tuple(shapes), sun=sun, sky=sky, rig=rig)
