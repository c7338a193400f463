"""Seeded builders of scene objects (vehicles, buildings, trees, poles, signs, clutter).

Each builder takes a :class:`numpy.random.Generator`, an id prefix and a placement, draws the
object's dimensions and library materials, and returns its shapes. Sizes are typical real-world
dimensions in metres. Coordinates are rounded to the millimetre (angles to 0.01 degree) so that
the XML written from them is stable.
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from contextvars import ContextVar

import numpy as np

from ..errors import NidarError
from .primitives import Block, Cylinder, Panel, Shape, Sphere

__all__ = [
    "local_point",
    "HELDOUT_MATERIALS",
    "MATERIALS",
    "MATERIAL_SETS",
    "material_set",
    "part_options",
    "pick",
    "rnd",
    "vehicle",
    "building",
    "tree",
    "bush",
    "sign_post",
    "street_light",
    "clutter",
]

#: Library materials each object part draws from.
MATERIALS: dict[str, tuple[str, ...]] = {
    "road": ("asphalt_old", "asphalt_new"),
    "path": ("gravel", "dirt", "sand", "asphalt_new", "soil_dry"),
    "marking": ("lane_paint_white", "lane_paint_yellow"),
    "sidewalk": ("concrete", "asphalt_new", "gravel"),
    "kerb_paint": ("curb_paint_red", "lane_paint_yellow", "concrete"),
    "urban_ground": ("grass", "grass_dry", "concrete", "gravel", "soil_dry", "dirt"),
    "wild_ground": ("grass", "grass_dry", "soil_dry", "dirt", "sand"),
    "wall": ("brick_red", "concrete", "wood_pallet", "sand", "shingle"),
    "roof": ("roof_tile_red", "shingle", "concrete", "steel_galvanised"),
    "window": ("glass_clear", "glass_blue"),
    "door": ("wood_pallet", "car_paint_black", "steel_galvanised", "car_paint_white"),
    "car_paint": (
        "car_paint_red",
        "car_paint_blue",
        "car_paint_white",
        "car_paint_black",
        "car_paint_silver",
    ),
    "pole": ("aluminium", "steel_galvanised", "iron", "wood_pallet"),
    "sign": ("retro_sheeting_white", "retro_sheeting_red"),
    "sign_back": ("aluminium", "steel_galvanised"),
    "crown": ("tree_canopy", "tree_canopy", "grass_dry"),
    "bush": ("tree_canopy", "grass", "grass_dry"),
    "crate": ("wood_pallet", "plastic_wrap", "fabric", "car_paint_blue", "concrete"),
    "bollard": ("concrete", "steel_galvanised", "curb_paint_red"),
    "boulder": ("gravel", "concrete", "sand"),
}


#: Materials kept out of the training scenes to test generalisation to unseen spectra: a
#: soil, a dry vegetation, sand, brick, clay tile, two paints, a tinted glass, iron, red sheeting,
#: plastic and fabric. Every part keeps at least one other material.
HELDOUT_MATERIALS = frozenset(
    {
        "asphalt_old",
        "dirt",
        "sand",
        "lane_paint_yellow",
        "grass_dry",
        "brick_red",
        "roof_tile_red",
        "glass_blue",
        "car_paint_red",
        "car_paint_silver",
        "iron",
        "retro_sheeting_red",
        "plastic_wrap",
        "fabric",
    }
)
#: Which materials scenes draw from: ``all``; ``train`` (none of :data:`HELDOUT_MATERIALS`);
#: ``heldout`` (a part's held-out materials where it has any, else its others).
MATERIAL_SETS = ("all", "train", "heldout")
_material_set: ContextVar[str] = ContextVar("material_set", default="all")


@contextmanager
def material_set(name: str):
    """Draw the materials of :func:`pick` from the set ``name`` (:data:`MATERIAL_SETS`) inside the
    block."""
    if name not in MATERIAL_SETS:
        raise NidarError(f"material set must be one of {', '.join(MATERIAL_SETS)} (got {name!r})")
    token = _material_set.set(name)
    try:
        yield
    finally:
        _material_set.reset(token)


def part_options(part: str, which: str = "all") -> tuple[str, ...]:
    """The materials ``part`` draws from in material set ``which``."""
    options = MATERIALS[part]
    if which == "all":
        return options
    held = tuple(m for m in options if m in HELDOUT_MATERIALS)
    kept = tuple(m for m in options if m not in HELDOUT_MATERIALS)
    return kept if which == "train" else (held or kept)


def pick(rng: np.random.Generator, part: str) -> str:
    """A library material for ``part`` (a key of :data:`MATERIALS`), drawn uniformly from the
    current material set (:func:`material_set`)."""
    options = part_options(part, _material_set.get())
    return options[int(rng.integers(len(options)))]


def rnd(v: float, digits: int = 3) -> float:
    """``v`` rounded to ``digits`` decimals, as a plain float (never ``-0.0``)."""
    return round(float(v), digits) + 0.0


def _pt(x: float, y: float, z: float) -> tuple[float, float, float]:
    return (rnd(x), rnd(y), rnd(z))


def local_point(
    x0: float, y0: float, heading_deg: float, u: float, v: float
) -> tuple[float, float]:
    """World (x, y) of the point (u forward, v left) of a frame at (x0, y0) facing heading."""
    a = math.radians(heading_deg)
    return x0 + u * math.cos(a) - v * math.sin(a), y0 + u * math.sin(a) + v * math.cos(a)


def vehicle(
    rng: np.random.Generator, prefix: str, x: float, y: float, heading_deg: float
) -> list[Shape]:
    """A car or van: body, glazed cabin around a dark interior, roof, four wheels.

    Args:
        x, y: centre of the footprint on the ground, m.
        heading_deg: direction the vehicle faces.
    """
    van = rng.random() < 0.2
    length = rng.uniform(4.8, 5.6) if van else rng.uniform(3.9, 4.9)
    width = rng.uniform(1.75, 2.0) if van else rng.uniform(1.65, 1.9)
    wheel_r = rng.uniform(0.3, 0.36)
    body_h = rng.uniform(0.55, 0.75)
    cabin_h = rng.uniform(0.9, 1.1) if van else rng.uniform(0.4, 0.55)
    cabin_len = length * (rng.uniform(0.6, 0.7) if van else rng.uniform(0.42, 0.55))
    cabin_u = -length / 2 + cabin_len / 2 + (0.15 if van else rng.uniform(0.35, 0.7))
    paint, glass = pick(rng, "car_paint"), pick(rng, "window")
    h = rnd(heading_deg, 2)
    z_body = wheel_r * 0.55 + body_h / 2
    z_cabin = z_body + body_h / 2 + cabin_h / 2
    cx, cy = local_point(x, y, heading_deg, cabin_u, 0.0)
    shapes: list[Shape] = [
        Block(
            f"{prefix}_body", paint, _pt(x, y, z_body), _pt(length / 2, width / 2, body_h / 2), h
        ),
        Block(
            f"{prefix}_cabin_glass",
            glass,
            _pt(cx, cy, z_cabin - 0.01),
            _pt(cabin_len / 2, width / 2 - 0.06, cabin_h / 2 - 0.01),
            h,
        ),
        Block(
            f"{prefix}_interior",
            "car_paint_black",
            _pt(cx, cy, z_cabin - 0.02),
            _pt(cabin_len / 2 - 0.12, width / 2 - 0.2, cabin_h / 2 - 0.06),
            h,
        ),
        Block(
            f"{prefix}_roof",
            paint,
            _pt(cx, cy, z_cabin + cabin_h / 2 + 0.02),
            _pt(cabin_len / 2, width / 2 - 0.05, 0.02),
            h,
        ),
    ]
    axle = length / 2 - rng.uniform(0.7, 0.95)
    for name, u in (("front", axle), ("rear", -axle)):
        for side, sgn in (("left", 1.0), ("right", -1.0)):
            ax, ay = local_point(x, y, heading_deg, u, sgn * (width / 2 - 0.02))
            bx, by = local_point(x, y, heading_deg, u, sgn * (width / 2 - 0.24))
            shapes.append(
                Cylinder(
                    f"{prefix}_wheel_{name}_{side}",
                    "rubber_tyre",
                    _pt(ax, ay, wheel_r),
                    _pt(bx, by, wheel_r),
                    rnd(wheel_r),
                )
            )
    return shapes


def building(
    rng: np.random.Generator,
    prefix: str,
    x: float,
    y: float,
    facade_heading_deg: float,
    length: float,
    depth: float,
) -> list[Shape]:
    """A block building: walls, roof slab, a grid of windows and a door on its street facade.

    Args:
        x, y: centre of the footprint, m.
        facade_heading_deg: outward normal of the street facade.
        length: facade length, m; ``depth``: footprint depth, m.
    """
    floors = int(rng.integers(1, 6))
    floor_h = rng.uniform(2.8, 3.4)
    height = floors * floor_h + rng.uniform(0.2, 1.0)
    wall, roof, glass = pick(rng, "wall"), pick(rng, "roof"), pick(rng, "window")
    yaw = rnd(facade_heading_deg - 90.0, 2)  # the block's x axis runs along the facade
    shapes: list[Shape] = [
        Block(
            f"{prefix}_walls",
            wall,
            _pt(x, y, height / 2),
            _pt(length / 2, depth / 2, height / 2),
            yaw,
        ),
        Block(
            f"{prefix}_roof",
            roof,
            _pt(x, y, height + 0.1),
            _pt(length / 2 + 0.2, depth / 2 + 0.2, 0.1),
            yaw,
        ),
    ]
    # The facade lies at depth/2 along the heading from the centre; panels sit 3 cm in front.
    win_w = rng.uniform(0.8, 1.6)
    n_cols = max(1, int((length - 1.0) // (win_w + rng.uniform(1.0, 2.5))))
    pitch = length / n_cols
    door_col = int(rng.integers(n_cols))
    for f in range(floors):
        for c in range(n_cols):
            v = -length / 2 + pitch * (c + 0.5)
            px, py = local_point(x, y, facade_heading_deg, depth / 2 + 0.03, -v)
            if f == 0 and c == door_col:
                shapes.append(
                    Panel(
                        f"{prefix}_door",
                        pick(rng, "door"),
                        _pt(px, py, 1.05),
                        (rnd(0.55), rnd(1.05)),
                        rnd(facade_heading_deg, 2),
                    )
                )
                continue
            zc = f * floor_h + floor_h * 0.55
            shapes.append(
                Panel(
                    f"{prefix}_window_{f}_{c}",
                    glass,
                    _pt(px, py, zc),
                    (rnd(win_w / 2), rnd(floor_h * 0.22)),
                    rnd(facade_heading_deg, 2),
                )
            )
    return shapes


def tree(rng: np.random.Generator, prefix: str, x: float, y: float) -> list[Shape]:
    """A trunk and one to three overlapping crown spheres (reaching at most 4.5 m from the trunk)."""
    trunk_h = rng.uniform(1.8, 4.5)
    trunk_r = rng.uniform(0.1, 0.35)
    crown_r = rng.uniform(1.3, 3.2)
    crown = pick(rng, "crown")
    shapes: list[Shape] = [
        Cylinder(
            f"{prefix}_trunk",
            "bark",
            _pt(x, y, 0.0),
            _pt(x, y, trunk_h + crown_r * 0.6),
            rnd(trunk_r),
        )
    ]
    for i in range(int(rng.integers(1, 4))):
        a = rng.uniform(0, 2 * math.pi)
        # the first sphere is the crown itself; others bulge out of it
        off = 0.0 if i == 0 else rng.uniform(0.3, 0.6) * crown_r
        r = crown_r * (1.0 if i == 0 else rng.uniform(0.55, 0.8))
        dz = 0.0 if i == 0 else rng.uniform(-0.3, 0.5)
        shapes.append(
            Sphere(
                f"{prefix}_crown_{i}",
                crown,
                _pt(
                    x + off * math.cos(a),
                    y + off * math.sin(a),
                    trunk_h + crown_r + dz,
                ),
                rnd(r),
            )
        )
    return shapes


def bush(rng: np.random.Generator, prefix: str, x: float, y: float) -> list[Shape]:
    """A shrub: a sphere sunk into the ground."""
    r = rng.uniform(0.4, 1.3)
    return [Sphere(prefix, pick(rng, "bush"), _pt(x, y, r * rng.uniform(0.2, 0.6)), rnd(r))]


def sign_post(
    rng: np.random.Generator, prefix: str, x: float, y: float, heading_deg: float
) -> list[Shape]:
    """A traffic sign: a pole, a metal back plate and retroreflective sheeting facing ``heading``."""
    top = rng.uniform(2.0, 2.8)
    half = rng.uniform(0.3, 0.45)
    pole_r = rng.uniform(0.03, 0.05)
    h = rnd(heading_deg, 2)
    fx, fy = local_point(x, y, heading_deg, pole_r + 0.02, 0.0)
    sx, sy = local_point(x, y, heading_deg, pole_r + 0.035, 0.0)
    return [
        Cylinder(
            f"{prefix}_pole", pick(rng, "pole"), _pt(x, y, 0.0), _pt(x, y, top + half), rnd(pole_r)
        ),
        Block(f"{prefix}_back", pick(rng, "sign_back"), _pt(fx, fy, top), _pt(0.01, half, half), h),
        Panel(
            f"{prefix}_face",
            pick(rng, "sign"),
            _pt(sx, sy, top),
            (rnd(half - 0.01), rnd(half - 0.01)),
            h,
        ),
    ]


def street_light(
    rng: np.random.Generator, prefix: str, x: float, y: float, heading_deg: float
) -> list[Shape]:
    """A lamp post: a tall pole, an arm reaching towards ``heading`` and the lamp housing."""
    height = rng.uniform(5.0, 8.0)
    arm = rng.uniform(0.8, 2.0)
    metal = pick(rng, "pole")
    ax, ay = local_point(x, y, heading_deg, arm, 0.0)
    return [
        Cylinder(
            f"{prefix}_pole", metal, _pt(x, y, 0.0), _pt(x, y, height), rnd(rng.uniform(0.06, 0.12))
        ),
        Cylinder(f"{prefix}_arm", metal, _pt(x, y, height - 0.1), _pt(ax, ay, height - 0.1), 0.04),
        Block(
            f"{prefix}_lamp",
            "aluminium",
            _pt(ax, ay, height - 0.2),
            (0.3, 0.15, 0.08),
            rnd(heading_deg, 2),
        ),
    ]


def clutter(rng: np.random.Generator, prefix: str, x: float, y: float) -> list[Shape]:
    """One small object: a crate or wrapped pallet, a bin, a bollard, a boulder or a bench."""
    kind = int(rng.integers(5))
    yaw = rnd(rng.uniform(0, 180), 2)
    if kind == 0:  # crate / pallet load
        s = rng.uniform(0.3, 0.7)
        hz = rng.uniform(0.3, 0.8)
        return [
            Block(
                prefix,
                pick(rng, "crate"),
                _pt(x, y, hz),
                _pt(s, s * rng.uniform(0.7, 1.3), hz),
                yaw,
            )
        ]
    if kind == 1:  # wheelie bin
        return [Block(prefix, pick(rng, "car_paint"), _pt(x, y, 0.5), (0.3, 0.35, 0.5), yaw)]
    if kind == 2:  # bollard
        return [
            Cylinder(
                prefix,
                pick(rng, "bollard"),
                _pt(x, y, 0.0),
                _pt(x, y, rng.uniform(0.7, 1.1)),
                rnd(rng.uniform(0.08, 0.15)),
            )
        ]
    if kind == 3:  # boulder
        r = rng.uniform(0.3, 0.9)
        return [Sphere(prefix, pick(rng, "boulder"), _pt(x, y, r * 0.4), rnd(r))]
    # bench: a seat and two legs
    seat = "wood_pallet"
    legs = pick(rng, "pole")
    shapes: list[Shape] = [Block(f"{prefix}_seat", seat, _pt(x, y, 0.45), (0.9, 0.22, 0.03), yaw)]
    for i, u in enumerate((-0.75, 0.75)):
        lx, ly = local_point(x, y, yaw, u, 0.0)
        shapes.append(Block(f"{prefix}_leg_{i}", legs, _pt(lx, ly, 0.21), (0.03, 0.2, 0.21), yaw))
    return shapes
