"""Seeded city and suburb layouts: a grid of blocks with streets that loop, for drives.

A layout of this module is a street grid of ``nx`` x ``ny`` blocks (:class:`StreetGrid`): streets
run along the lines ``x = i * pitch`` and ``y = j * pitch`` (i = 0..nx, j = 0..ny), so every
block can be driven around and every corner revisited. What a registration needs to follow a
drive, and what a place-recognition descriptor needs to tell two places apart, is structure across
the road that differs from place to place; every street side therefore gets its own draw of:

* buildings of varied length, depth, height and set-back (``city``: 1-5 floors close to the
  sidewalk; ``suburb``: 1-2 floor houses behind front gardens), with walls or fences in the gaps
  and pilasters in relief on their street facades;
* street lights, sign posts, wheelie bins, bollards, benches, street trees and bushes;
* parked cars along the kerbs (``city``: parking strips, ~60 % of the bays; ``suburb``: ~30 %).

The rig (an HDL-64E at 1.73 m and a forward camera) stands at the start of :func:`drive_route`'s
route, looking along it. The frame is the one of :mod:`.layout`: z up, metres, degrees.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .layout import sample_light, sample_rig
from .objects import building, bush, local_point, pick, rnd, sign_post, street_light, tree, vehicle
from .primitives import Block, Cylinder, Layout, Patch, Shape
from .streets import (
    DEFAULT_BLOCKS,
    LIDAR_HEIGHT_M,
    StreetGrid,
    sample_grid,
)

__all__ = ["sample_city"]

_KERB_M = 0.15
_NO_PARKING_M = 5.0  # no car parks closer than this to the end of a block side (turning cars)


# ---------------------------------------------------------------- streets


def _streets(rng: np.random.Generator, g: StreetGrid) -> list[Shape]:
    """Ground, one road strip per street line, centre dashes, sidewalks around every block."""
    ext_x, ext_y = g.nx * g.pitch, g.ny * g.pitch
    m = g.pitch * 0.6  # streets run on past the outer crossings
    road = pick(rng, "road")
    cx, cy = ext_x / 2, ext_y / 2
    shapes: list[Shape] = [
        Patch(
            "ground_base",
            pick(rng, "urban_ground"),
            (rnd(cx), rnd(cy), -0.03),
            (rnd(ext_x / 2 + 3 * g.pitch), rnd(ext_y / 2 + 3 * g.pitch)),
        )
    ]
    for i in range(g.nx + 1):
        x = i * g.pitch
        shapes.append(
            Patch(f"road_x{i}", road, (rnd(x), rnd(cy), 0.0), (rnd(g.road_half), rnd(cy + m)))
        )
    for j in range(g.ny + 1):
        y = j * g.pitch
        shapes.append(
            Patch(f"road_y{j}", road, (rnd(cx), rnd(y), 0.0), (rnd(cx + m), rnd(g.road_half)))
        )
    paint = "lane_paint_white" if g.kind == "city" else pick(rng, "marking")
    dash, gap = rng.uniform(2.0, 3.5), rng.uniform(4.0, 7.0)
    k = 0
    for i in range(g.nx + 1):  # dashes between the crossings
        for j in range(g.ny):
            y = j * g.pitch + g.road_half + 1.0
            while y + dash < (j + 1) * g.pitch - g.road_half - 1.0:
                shapes.append(
                    Patch(
                        f"dash_{k}",
                        paint,
                        (rnd(i * g.pitch), rnd(y + dash / 2), 0.005),
                        (0.07, rnd(dash / 2)),
                    )
                )
                y, k = y + dash + gap, k + 1
    for j in range(g.ny + 1):
        for i in range(g.nx):
            x = i * g.pitch + g.road_half + 1.0
            while x + dash < (i + 1) * g.pitch - g.road_half - 1.0:
                shapes.append(
                    Patch(
                        f"dash_{k}",
                        paint,
                        (rnd(x + dash / 2), rnd(j * g.pitch), 0.005),
                        (rnd(dash / 2), 0.07),
                    )
                )
                x, k = x + dash + gap, k + 1
    walk = pick(rng, "sidewalk")
    for bi in range(g.nx):
        for bj in range(g.ny):
            x0, x1, y0, y1 = g.block_bounds(bi, bj)
            w = g.walk_w
            hz = _KERB_M / 2
            for side, c, h in (
                ("s", ((x0 + x1) / 2, y0 - w / 2), ((x1 - x0) / 2 + w, w / 2)),
                ("n", ((x0 + x1) / 2, y1 + w / 2), ((x1 - x0) / 2 + w, w / 2)),
                ("w", (x0 - w / 2, (y0 + y1) / 2), (w / 2, (y1 - y0) / 2)),
                ("e", (x1 + w / 2, (y0 + y1) / 2), (w / 2, (y1 - y0) / 2)),
            ):
                shapes.append(
                    Block(
                        f"walk_{bi}_{bj}_{side}",
                        walk,
                        (rnd(c[0]), rnd(c[1]), rnd(hz)),
                        (rnd(h[0]), rnd(h[1]), rnd(hz)),
                    )
                )
            shapes.append(
                Patch(
                    f"lot_{bi}_{bj}",
                    pick(rng, "urban_ground"),
                    (rnd((x0 + x1) / 2), rnd((y0 + y1) / 2), 0.002),
                    (rnd((x1 - x0) / 2), rnd((y1 - y0) / 2)),
                )
            )
    return shapes


# ---------------------------------------------------------------- one block


@dataclass(frozen=True)
class _Side:
    """One side of a block: its building line runs from ``a`` to ``b`` (m along ``u``), ``o`` is
    the point of the line at u = 0, ``u`` the unit direction along it and ``n`` the unit normal
    towards the street."""

    name: str
    o: tuple[float, float]
    u: tuple[float, float]
    n: tuple[float, float]
    a: float
    b: float

    def at(self, s: float, off: float) -> tuple[float, float]:
        """World (x, y) at ``s`` along the line and ``off`` towards the street (negative: into
        the block)."""
        return (
            self.o[0] + s * self.u[0] + off * self.n[0],
            self.o[1] + s * self.u[1] + off * self.n[1],
        )

    @property
    def heading(self) -> float:
        """Azimuth of the normal towards the street, degrees."""
        return math.degrees(math.atan2(self.n[1], self.n[0]))


def _block_sides(g: StreetGrid, bi: int, bj: int) -> list[_Side]:
    x0, x1, y0, y1 = g.block_bounds(bi, bj)
    return [
        _Side("s", (0.0, y0), (1.0, 0.0), (0.0, -1.0), x0, x1),
        _Side("n", (0.0, y1), (1.0, 0.0), (0.0, 1.0), x0, x1),
        _Side("w", (x0, 0.0), (0.0, 1.0), (-1.0, 0.0), y0, y1),
        _Side("e", (x1, 0.0), (0.0, 1.0), (1.0, 0.0), y0, y1),
    ]


def _wall(rng: np.random.Generator, id_: str, side: _Side, s0: float, s1: float, off: float):
    """A garden or boundary wall (or a fence) along ``side`` from ``s0`` to ``s1``."""
    h = rng.uniform(0.9, 2.4)
    t = rng.uniform(0.2, 0.35)
    mat = pick(rng, "wall") if rng.random() < 0.75 else "wood_pallet"
    cx, cy = side.at((s0 + s1) / 2, off)
    yaw = math.degrees(math.atan2(side.u[1], side.u[0]))
    return Block(
        id_,
        mat,
        (rnd(cx), rnd(cy), rnd(h / 2)),
        (rnd((s1 - s0) / 2), rnd(t / 2), rnd(h / 2)),
        rnd(yaw, 2),
    )


def _frontage(rng: np.random.Generator, g: StreetGrid, prefix: str, side: _Side, depth_max: float):
    """Buildings along one side, walls or fences in the gaps (``depth_max``: how deep a building
    may reach into the block)."""
    shapes: list[Shape] = []
    city = g.kind == "city"
    s, k = side.a + rng.uniform(0.0, 3.0), 0
    while s < side.b - 5.0:
        length = rng.uniform(9.0, 22.0) if city else rng.uniform(8.0, 13.0)
        s1 = min(s + length, side.b - 0.5)
        setback = rng.uniform(0.0, 2.0) if city else rng.uniform(4.0, 8.0)
        depth = min(rng.uniform(8.0, 14.0) if city else rng.uniform(7.0, 10.0), depth_max - setback)
        if s1 - s > 5.0 and depth > 4.0 and rng.random() < (0.85 if city else 0.8):
            cx, cy = side.at((s + s1) / 2, -setback - depth / 2)
            parts = building(rng, f"{prefix}_b{k}", cx, cy, side.heading, s1 - s, depth)
            if not city:  # houses: at most two floors
                parts = [p for p in parts if "_window_2" not in p.id and "_window_3" not in p.id]
                parts = [_cap_height(p, 7.0) for p in parts]
            shapes += parts
            shapes += _pilasters(rng, f"{prefix}_b{k}", side, s, s1, setback, parts[0])
            if setback > 2.5 and rng.random() < 0.7:  # a front-garden wall or hedge
                if rng.random() < 0.6:
                    shapes.append(_wall(rng, f"{prefix}_gw{k}", side, s, s1, -0.3))
                else:
                    for q in range(int((s1 - s) // 2.5)):
                        bx, by = side.at(s + 1.2 + 2.5 * q, -0.8)
                        shapes += bush(rng, f"{prefix}_hedge{k}_{q}", bx, by)
        elif s1 - s > 2.0:
            shapes.append(_wall(rng, f"{prefix}_w{k}", side, s, s1, -rng.uniform(0.2, 1.5)))
        k += 1
        s = s1 + (rng.uniform(0.0, 4.0) if city else rng.uniform(2.0, 7.0))
    return shapes


def _pilasters(
    rng: np.random.Generator, prefix: str, side: _Side, s0: float, s1: float, setback: float, walls
) -> list[Shape]:
    """Relief on a street facade: pilasters 0.3-0.5 m wide standing 0.15-0.45 m proud of the wall,
    every 3-6 m from ``s0`` to ``s1`` (real facades are not flat: the relief tells a scan
    registration how far it moved along the street)."""
    height = walls.center[2] + walls.half_size[2]
    yaw = rnd(math.degrees(math.atan2(side.u[1], side.u[0])), 2)
    out: list[Shape] = []
    u, q = s0 + rng.uniform(0.2, 1.0), 0
    while u < s1 - 0.3:
        w, d = rng.uniform(0.3, 0.5), rng.uniform(0.15, 0.45)
        x, y = side.at(u, -setback + d / 2 - 0.02)
        out.append(
            Block(
                f"{prefix}_pilaster{q}",
                walls.material,
                (rnd(x), rnd(y), rnd(height / 2)),
                (rnd(w / 2), rnd(d / 2), rnd(height / 2)),
                yaw,
            )
        )
        u, q = u + rng.uniform(3.0, 6.0), q + 1
    return out


def _cap_height(shape, h_max: float):
    """A block building part lowered to at most ``h_max`` (suburban houses)."""
    if isinstance(shape, Block) and shape.center[2] + shape.half_size[2] > h_max + 0.3:
        if shape.id.endswith("_roof"):
            return dataclasses.replace(shape, center=(*shape.center[:2], rnd(h_max + 0.1)))
        if shape.id.endswith("_walls"):
            return dataclasses.replace(
                shape,
                center=(*shape.center[:2], rnd(h_max / 2)),
                half_size=(*shape.half_size[:2], rnd(h_max / 2)),
            )
    return shape


def _furniture(rng: np.random.Generator, g: StreetGrid, prefix: str, side: _Side) -> list[Shape]:
    """Street lights, sign posts, bins, bollards, benches and trees on one sidewalk, and the
    cars parked at its kerb."""
    shapes: list[Shape] = []
    kerb = g.walk_w  # offset of the kerb line from the building line
    taken: list[float] = []

    def free(s: float, r: float) -> bool:
        return side.a + r < s < side.b - r and all(abs(s - t) > r + 0.6 for t in taken)

    city = g.kind == "city"
    s = side.a + rng.uniform(2.0, 12.0)
    k = 0
    while s < side.b:
        if free(s, 0.5):
            x, y = side.at(s, kerb - 0.4)
            shapes += street_light(rng, f"{prefix}_light{k}", x, y, side.heading)
            taken.append(s)
            k += 1
        s += rng.uniform(16.0, 28.0) if city else rng.uniform(25.0, 40.0)
    if rng.random() < (0.6 if city else 0.85):
        s = side.a + rng.uniform(1.0, 8.0)
        k = 0
        while s < side.b:
            if free(s, 1.0) and rng.random() < 0.8:
                x, y = side.at(s, kerb * rng.uniform(0.55, 0.75))
                shapes += tree(rng, f"{prefix}_tree{k}", x, y)
                taken.append(s)
                k += 1
            s += rng.uniform(7.0, 14.0)
    items = (
        [("sign", 0.5)] * int(rng.integers(0, 3))
        + [("bin", 0.5)] * int(rng.integers(1, 5))
        + [("bollard", 0.3)] * int(rng.integers(0, 4))
        + [("bench", 1.0)] * int(rng.integers(0, 2))
    )
    for k, (what, r) in enumerate(items):
        for _ in range(6):  # a few tries for a free spot
            s = rng.uniform(side.a, side.b)
            if free(s, r):
                break
        else:
            continue
        taken.append(s)
        if what == "sign":
            x, y = side.at(s, kerb - 0.3)
            heading = side.heading + (90.0 if rng.random() < 0.5 else -90.0)
            shapes += sign_post(rng, f"{prefix}_sign{k}", x, y, heading)
        elif what == "bin":
            x, y = side.at(s, rng.uniform(0.3, kerb - 0.4))
            yaw = rnd(side.heading + rng.uniform(-10, 10), 2)
            shapes.append(
                Block(
                    f"{prefix}_bin{k}",
                    pick(rng, "car_paint"),
                    (rnd(x), rnd(y), 0.55),
                    (0.3, 0.36, 0.55),
                    yaw,
                )
            )
        elif what == "bollard":
            x, y = side.at(s, kerb - 0.25)
            shapes.append(
                Cylinder(
                    f"{prefix}_bollard{k}",
                    pick(rng, "bollard"),
                    (rnd(x), rnd(y), 0.0),
                    (rnd(x), rnd(y), rnd(rng.uniform(0.8, 1.1))),
                    rnd(rng.uniform(0.08, 0.14)),
                )
            )
        else:
            x, y = side.at(s, rng.uniform(0.6, kerb - 0.6))
            yaw = math.degrees(math.atan2(side.u[1], side.u[0]))
            shapes += _bench(rng, f"{prefix}_bench{k}", x, y, yaw)
    # parked cars along the kerb, facing the traffic of that side (right-hand traffic)
    occupancy = 0.6 if city else 0.3
    lane_off = kerb + g.park_w / 2
    s = side.a + _NO_PARKING_M + rng.uniform(0.0, 3.0)
    k = 0
    while s < side.b - _NO_PARKING_M:
        if rng.random() < occupancy:
            x, y = side.at(s, lane_off)
            heading = math.degrees(math.atan2(-side.u[1], -side.u[0]))
            if side.name in ("n", "w"):
                heading = math.degrees(math.atan2(side.u[1], side.u[0]))
            shapes += vehicle(rng, f"{prefix}_car{k}", x, y, heading + rng.uniform(-3.0, 3.0))
            k += 1
        s += rng.uniform(5.6, 8.0)
    return shapes


def _bench(rng: np.random.Generator, prefix: str, x: float, y: float, yaw: float) -> list[Shape]:
    legs = pick(rng, "pole")
    out: list[Shape] = [
        Block(
            f"{prefix}_seat", "wood_pallet", (rnd(x), rnd(y), 0.45), (0.9, 0.22, 0.03), rnd(yaw, 2)
        )
    ]
    for i, u in enumerate((-0.75, 0.75)):
        lx, ly = local_point(x, y, yaw, u, 0.0)
        out.append(
            Block(
                f"{prefix}_leg{i}", legs, (rnd(lx), rnd(ly), 0.21), (0.03, 0.2, 0.21), rnd(yaw, 2)
            )
        )
    return out


def _block(rng: np.random.Generator, g: StreetGrid, bi: int, bj: int) -> list[Shape]:
    x0, x1, y0, y1 = g.block_bounds(bi, bj)
    shapes: list[Shape] = []
    sides = _block_sides(g, bi, bj)
    half_y = (y1 - y0) / 2
    for side in sides:
        prefix = f"blk{bi}_{bj}{side.name}"
        if side.name in ("s", "n"):
            shapes += _frontage(rng, g, prefix, side, min(12.0, half_y - 0.5))
        else:  # east and west frontages between the corner plots of the north and south rows
            corner = min(12.0, half_y - 0.5)
            inner = dataclasses.replace(side, a=side.a + corner, b=side.b - corner)
            if inner.b - inner.a > 6.0:
                shapes += _frontage(rng, g, prefix, inner, (x1 - x0) / 2 - 0.5)
            elif inner.b - inner.a > 1.0:  # a boundary wall closes the gap between the corners
                shapes.append(_wall(rng, f"{prefix}_w", inner, inner.a, inner.b, -0.5))
        # the sidewalk sits on the street side of the building line
        shapes += _furniture(rng, g, prefix, side)
    return shapes


# ---------------------------------------------------------------- the layout


def sample_city(
    rng: np.random.Generator, kind: str = "city", blocks: tuple[int, int] = DEFAULT_BLOCKS
) -> tuple[Layout, StreetGrid]:
    """Draw a city or suburb layout and its street grid.

    Args:
        rng: the only source of randomness.
        kind: ``city`` or ``suburb``.
        blocks: (nx, ny) blocks (nx >= 2, ny >= 1).

    Returns:
        The layout (its rig stands at the start of :func:`drive_route`, heading north, in the
        right-hand lane) and the grid.
    """
    from .route import route_start

    g = sample_grid(rng, kind, blocks)
    shapes = _streets(rng, g)
    for bi in range(g.nx):
        for bj in range(g.ny):
            shapes += _block(rng, g, bi, bj)
    sun, sky = sample_light(rng)
    x, y, heading = route_start(g)
    rig = sample_rig(rng, x, y, heading)
    # the LiDAR looks exactly along the road at KITTI's height; the camera keeps its mounting
    # relative to it (turned and lifted with it)
    turn = math.radians(heading - rig.lidar_yaw_deg)
    cx, cy = rig.camera_position[0] - x, rig.camera_position[1] - y
    cam = (
        x + cx * math.cos(turn) - cy * math.sin(turn),
        y + cx * math.sin(turn) + cy * math.cos(turn),
        rig.camera_position[2] - rig.lidar_position[2] + LIDAR_HEIGHT_M,
    )
    rig = dataclasses.replace(
        rig,
        lidar_preset="hdl64e",
        lidar_position=(rnd(x), rnd(y), LIDAR_HEIGHT_M),
        lidar_yaw_deg=rnd(heading, 2),
        camera_position=(rnd(cam[0]), rnd(cam[1]), rnd(cam[2])),
        camera_yaw_deg=rnd(rig.camera_yaw_deg + math.degrees(turn), 2),
    )
    ids = [s.id for s in shapes]
    assert len(ids) == len(set(ids)), "duplicate shape ids"
    return Layout(kind=kind, shapes=tuple(shapes), sun=sun, sky=sky, rig=rig), g
