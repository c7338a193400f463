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
from dataclasses import dataclass

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
    placer = _Placer()
    street = _sample_street(rng)
    rig_xy = _rig_in_a_right_lane(rng, street)
    placer.take(rig_xy[0], rig_xy[1], 5.0)  # clear around the rig (a tree reaches 4.5 m)
    shapes = _road_surface(rng, street)
    shapes += _markings(rng, street)
    walks = _sample_sidewalks(rng)
    for side in ("left", "right"):
        shapes += _roadside(rng, street, walks, side, placer)
    shapes += _vehicles(rng, street, placer)
    shapes += _ground_patches(rng, street, walks)
    shapes += _bushes_and_clutter(rng, street, placer)
    return shapes, rig_xy


@dataclass(frozen=True)
class _Street:
    """The road of an urban layout, along x; y across it (m), +y on the left.

    Attributes:
        lane_w: lane width.
        lanes: 2 or 4 lanes (half of them on either side of y = 0).
        park_l, park_r: width of the parking strip on the left and right (0: none).
        cross: x extent of a cross street, or None.
    """

    lane_w: float
    lanes: int
    park_l: float
    park_r: float
    cross: tuple[float, float] | None

    @property
    def half(self) -> float:
        """Half the width of the lanes."""
        return self.lanes * self.lane_w / 2

    @property
    def y_lo(self) -> float:
        """Right kerb line."""
        return -self.half - self.park_r

    @property
    def y_hi(self) -> float:
        """Left kerb line."""
        return self.half + self.park_l

    @property
    def holes(self) -> list[tuple[float, float]]:
        """The x intervals the cross street cuts out of everything along the road."""
        return [self.cross] if self.cross else []

    def kerb(self, side: str) -> tuple[float, float]:
        """(y of the kerb line, +1 or -1: the direction away from the road) of a side."""
        return (self.y_hi, 1.0) if side == "left" else (self.y_lo, -1.0)

    def clear_of_cross(self, x: float, margin: float = 0.0) -> bool:
        """``x`` lies ``margin`` or more outside the cross street (or there is none)."""
        return not self.cross or not self.cross[0] - margin < x < self.cross[1] + margin

    def span_clear_of_cross(self, x0: float, x1: float, margin: float = 0.0) -> bool:
        """[x0, x1] ends more than ``margin`` before the cross street or starts after it."""
        return not self.cross or x1 < self.cross[0] - margin or x0 > self.cross[1] + margin


@dataclass(frozen=True)
class _Sidewalks:
    """Kerbed sidewalks on both sides: kerb height (m), material, width per side (m)."""

    kerb: float
    material: str
    width: dict[str, float]


def _sample_street(rng: np.random.Generator) -> _Street:
    """Two lanes (or four, 25 %), parking strips (60 % per side), a cross street (40 %)."""
    lane_w = rng.uniform(3.0, 3.75)
    lanes = 4 if rng.random() < 0.25 else 2
    park_l = rng.uniform(2.0, 2.5) if rng.random() < 0.6 else 0.0
    park_r = rng.uniform(2.0, 2.5) if rng.random() < 0.6 else 0.0
    cross = None
    if rng.random() < 0.4:
        xc, cw = rng.uniform(18.0, 50.0), rng.uniform(7.0, 12.0)
        cross = (xc - cw / 2, xc + cw / 2)
    return _Street(lane_w, lanes, park_l, park_r, cross)


def _rig_in_a_right_lane(rng: np.random.Generator, street: _Street) -> tuple[float, float]:
    """The rig's (x, y): x = 0, near the centre of a right-hand lane."""
    rig_lane = 0 if street.lanes == 2 or rng.random() < 0.5 else 1
    return (0.0, -street.lane_w * (rig_lane + 0.5) + rng.uniform(-0.3, 0.3))


def _road_surface(rng: np.random.Generator, street: _Street) -> list[Shape]:
    """The far ground plane, the road and the cross street."""
    shapes: list[Shape] = [
        Patch("ground_base", pick(rng, "urban_ground"), (25.0, 0.0, _BASE_Z), (150.0, 150.0))
    ]
    road = pick(rng, "road")
    shapes.append(_strip("road", road, X_MIN, X_MAX, street.y_lo, street.y_hi, 0.0))
    if street.cross:
        shapes.append(_strip("cross_road_left", road, *street.cross, street.y_hi, 70.0, 0.0))
        shapes.append(_strip("cross_road_right", road, *street.cross, -70.0, street.y_lo, 0.0))
    return shapes


def _markings(rng: np.random.Generator, street: _Street) -> list[Shape]:
    """Centre and lane lines (solid or dashed), edge lines, sometimes a zebra crossing; 5 mm up."""
    shapes: list[Shape] = []
    lane_w, half, holes = street.lane_w, street.half, street.holes
    paint = pick(rng, "marking")
    centre_solid = street.lanes == 4 or rng.random() < 0.3
    dash, gap = rng.uniform(2.0, 4.0), rng.uniform(4.0, 9.0)
    lanes = (-lane_w, lane_w) if street.lanes == 4 else ()
    lines = [(0.0, centre_solid)] + [(y, False) for y in lanes]
    for i, (yl, solid) in enumerate(lines):
        if solid:
            for j, (a, b) in enumerate(_segments(X_MIN, X_MAX, holes)):
                shapes.append(_strip(f"line_{i}_{j}", paint, a, b, yl - 0.07, yl + 0.07, 0.005))
            continue
        x, k = X_MIN + rng.uniform(0.0, gap), 0
        while x + dash < X_MAX:
            if street.span_clear_of_cross(x, x + dash):
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
        xz = street.cross[0] - 3.5 if street.cross else rng.uniform(12.0, 45.0)
        y = -half + 0.3
        k = 0
        while y + 0.5 < half - 0.3:
            shapes.append(
                _strip(f"zebra_{k}", "lane_paint_white", xz - 1.5, xz + 1.5, y, y + 0.5, 0.006)
            )
            y, k = y + 1.0, k + 1
    return shapes


def _sample_sidewalks(rng: np.random.Generator) -> _Sidewalks:
    kerb = rng.uniform(0.1, 0.18)
    material = pick(rng, "sidewalk")
    width = {"left": rng.uniform(1.8, 4.0), "right": rng.uniform(1.8, 4.0)}
    return _Sidewalks(kerb, material, width)


def _roadside(
    rng: np.random.Generator, street: _Street, walks: _Sidewalks, side: str, placer: _Placer
) -> list[Shape]:
    """One side of the road: sidewalk blocks and the ground behind them, buildings, street trees,
    lights and sign posts."""
    shapes: list[Shape] = []
    y0, s = street.kerb(side)
    w = walks.width[side]
    for j, (a, b) in enumerate(_segments(X_MIN, X_MAX, street.holes)):
        ya, yb = sorted((y0, y0 + s * w))
        shapes.append(
            Block(
                f"sidewalk_{side}_{j}",
                walks.material,
                (rnd((a + b) / 2), rnd((ya + yb) / 2), rnd(walks.kerb / 2)),
                (rnd((b - a) / 2), rnd(w / 2), rnd(walks.kerb / 2)),
            )
        )
        ya, yb = sorted((y0 + s * w, y0 + s * 60.0))
        shapes.append(_strip(f"ground_{side}_{j}", pick(rng, "urban_ground"), a, b, ya, yb, 0.0))
    shapes += _buildings(rng, street, side, y0, s, w)
    if rng.random() < 0.6:
        shapes += _street_trees(rng, street, side, y0, s * w, placer)
    if rng.random() < 0.7:
        shapes += _street_lights(rng, street, side, y0, s, placer)
    for k in range(int(rng.integers(0, 3))):
        xs, ys = rng.uniform(5.0, 60.0), y0 + s * rng.uniform(0.3, 0.6)
        heading = 180.0 + rng.uniform(-20.0, 20.0) if rng.random() < 0.8 else rng.uniform(0, 360)
        if placer.take(xs, ys, 0.6):
            shapes += sign_post(rng, f"sign_{side}_{k}", xs, ys, heading)
    return shapes


def _buildings(
    rng: np.random.Generator, street: _Street, side: str, y0: float, s: float, w: float
) -> list[Shape]:
    """A row of buildings (85 % of the plots) set back 0.5-7 m from the back of the sidewalk
    (kerb at ``y0``, ``s`` = +1 or -1 away from the road, width ``w``)."""
    shapes: list[Shape] = []
    xb = X_MIN + rng.uniform(0.0, 6.0)
    k = 0
    while xb < X_MAX - 6.0:
        length, depth = rng.uniform(8.0, 25.0), rng.uniform(8.0, 16.0)
        setback = rng.uniform(0.5, 7.0)
        x0, x1 = xb, min(xb + length, X_MAX)
        build = rng.random() < 0.85
        if build and street.span_clear_of_cross(x0, x1, 1.0) and x1 - x0 > 5.0:
            yc = y0 + s * (w + setback + depth / 2)
            heading = -90.0 if s > 0 else 90.0
            shapes += building(rng, f"bldg_{side}_{k}", (x0 + x1) / 2, yc, heading, x1 - x0, depth)
            k += 1
        xb = x1 + rng.uniform(0.0, 8.0)
    return shapes


def _street_trees(
    rng: np.random.Generator, street: _Street, side: str, y0: float, w: float, placer: _Placer
) -> list[Shape]:
    """Trees every 8-16 m, 55-80 % of the way across the sidewalk from the kerb ``y0``
    (``w``: the sidewalk's signed width)."""
    shapes: list[Shape] = []
    xt = X_MIN + rng.uniform(0.0, 10.0)
    k = 0
    while xt < X_MAX:
        yt = y0 + w * rng.uniform(0.55, 0.8)
        if street.clear_of_cross(xt, 2.0) and placer.take(xt, yt, 1.0):
            shapes += tree(rng, f"tree_{side}_{k}", xt, yt)
            k += 1
        xt += rng.uniform(8.0, 16.0)
    return shapes


def _street_lights(
    rng: np.random.Generator, street: _Street, side: str, y0: float, s: float, placer: _Placer
) -> list[Shape]:
    """Lights every 20-35 m, 0.4 m behind the kerb ``y0``, facing the road."""
    shapes: list[Shape] = []
    xl = X_MIN + rng.uniform(0.0, 15.0)
    k = 0
    while xl < X_MAX:
        yl = y0 + s * 0.4
        if street.clear_of_cross(xl, 1.0) and placer.take(xl, yl, 0.6):
            shapes += street_light(rng, f"light_{side}_{k}", xl, yl, -90.0 * s)
            k += 1
        xl += rng.uniform(20.0, 35.0)
    return shapes


def _vehicles(rng: np.random.Generator, street: _Street, placer: _Placer) -> list[Shape]:
    """Cars parked in the strips (60 % of the bays) and up to four moving in the lanes."""
    shapes: list[Shape] = []
    for side, width, y_edge, heading in (
        ("left", street.park_l, street.y_hi, 180.0),
        ("right", street.park_r, street.y_lo, 0.0),
    ):
        if width <= 0.0:
            continue
        yv = y_edge - math.copysign(width / 2, y_edge)
        xv, k = X_MIN + rng.uniform(0.0, 5.0), 0
        while xv < X_MAX - 3.0:
            occupied = rng.random() < 0.6
            if occupied and street.clear_of_cross(xv, 4.0) and placer.take(xv, yv, 2.4):
                shapes += vehicle(rng, f"car_{side}_{k}", xv, yv, heading + rng.uniform(-3.0, 3.0))
                k += 1
            xv += rng.uniform(5.5, 8.5)
    for k in range(int(rng.integers(0, 5))):
        lane = int(rng.integers(street.lanes))
        yv = -street.half + street.lane_w * (lane + 0.5) + rng.uniform(-0.3, 0.3)
        heading = 0.0 if yv < 0 else 180.0
        xv = rng.uniform(-30.0, 80.0)
        if placer.take(xv, yv, 2.6):
            shapes += vehicle(rng, f"car_lane_{k}", xv, yv, heading + rng.uniform(-2.0, 2.0))
    return shapes


def _ground_patches(rng: np.random.Generator, street: _Street, walks: _Sidewalks) -> list[Shape]:
    """Patches of other ground cover behind the sidewalks, 2 mm apart, clear of a cross street."""
    shapes: list[Shape] = []
    for k in range(int(rng.integers(0, 5))):
        s = 1.0 if rng.random() < 0.5 else -1.0
        side = "left" if s > 0 else "right"
        hx, hy = rng.uniform(2.0, 8.0), rng.uniform(1.0, 5.0)
        xc = rng.uniform(X_MIN + hx, X_MAX - hx)
        yc = street.kerb(side)[0] + s * (walks.width[side] + hy + rng.uniform(0.0, 8.0))
        if street.span_clear_of_cross(xc - hx, xc + hx):
            shapes.append(
                Patch(
                    f"patch_{k}",
                    pick(rng, "urban_ground"),
                    (rnd(xc), rnd(yc), rnd(0.002 * (k + 1))),
                    (rnd(hx), rnd(hy)),
                )
            )
    return shapes


def _bushes_and_clutter(rng: np.random.Generator, street: _Street, placer: _Placer) -> list[Shape]:
    """2-11 bushes or clutter objects beside the road, not on a cross street."""
    shapes: list[Shape] = []
    for k in range(int(rng.integers(2, 12))):
        s = 1.0 if rng.random() < 0.5 else -1.0
        edge = street.y_hi if s > 0 else street.y_lo
        x, y = rng.uniform(-20.0, 75.0), edge + s * rng.uniform(0.4, 6.0)
        if street.clear_of_cross(x, 1.0) and placer.take(x, y, 0.7):
            maker = bush if rng.random() < 0.4 else clutter
            shapes += maker(rng, f"clutter_{k}", x, y)
    return shapes


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
