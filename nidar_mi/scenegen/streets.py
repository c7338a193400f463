"""The street network of a city or suburb layout, and the drive's route through it.

Streets run along the lines ``x = i * pitch`` and ``y = j * pitch`` (i = 0..nx, j = 0..ny) of a
:class:`StreetGrid` of ``nx`` x ``ny`` blocks; :func:`drive_route` is the figure eight a drive
follows (:mod:`.trajectory` turns it into poses, :mod:`.city` builds the blocks).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .objects import rnd

__all__ = [
    "CITY_KINDS",
    "DEFAULT_BLOCKS",
    "LIDAR_HEIGHT_M",
    "StreetGrid",
    "sample_grid",
    "drive_route",
]

CITY_KINDS = ("city", "suburb")
#: Blocks (nx, ny) of a city or suburb layout unless asked otherwise.
DEFAULT_BLOCKS = (4, 3)
#: Height of the LiDAR above the road in the drive rigs (KITTI's HDL-64E: 1.73 m).
LIDAR_HEIGHT_M = 1.73


@dataclass(frozen=True)
class StreetGrid:
    """The street network of a city layout.

    Attributes:
        kind: ``city`` or ``suburb``.
        nx, ny: blocks along x and y.
        pitch: distance between neighbouring street centrelines, m.
        lane_w: lane width, m (one lane each way).
        park_w: parking strip on each side of the lanes, m (0: none).
        walk_w: sidewalk width, m.
    """

    kind: str
    nx: int
    ny: int
    pitch: float
    lane_w: float
    park_w: float
    walk_w: float

    @property
    def road_half(self) -> float:
        """Half the kerb-to-kerb width, m."""
        return self.lane_w + self.park_w

    @property
    def street_half(self) -> float:
        """Half the width from building line to building line (road and both sidewalks), m."""
        return self.road_half + self.walk_w

    def node(self, i: int, j: int) -> tuple[float, float]:
        """(x, y) of the crossing of streets ``i`` (along y) and ``j`` (along x), m."""
        return (i * self.pitch, j * self.pitch)

    def block_bounds(self, bi: int, bj: int) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1) of block (bi, bj) inside its sidewalks, m."""
        h = self.street_half
        return (
            bi * self.pitch + h,
            (bi + 1) * self.pitch - h,
            bj * self.pitch + h,
            (bj + 1) * self.pitch - h,
        )


def sample_grid(rng: np.random.Generator, kind: str, blocks: tuple[int, int]) -> StreetGrid:
    """Draw the street grid of a ``city`` (pitch 38-44 m) or ``suburb`` (pitch 48-56 m) with
    ``blocks`` = (nx, ny) blocks; both have a parking strip along each kerb."""
    if kind not in CITY_KINDS:
        raise ValueError(f"unknown city kind '{kind}' (choose from {', '.join(CITY_KINDS)})")
    nx, ny = (int(b) for b in blocks)
    if nx < 2 or ny < 1:
        raise ValueError(f"a drive needs at least 2 x 1 blocks (got {nx} x {ny})")
    lane_w = rnd(rng.uniform(3.1, 3.5))
    if kind == "city":
        return StreetGrid(
            kind,
            nx,
            ny,
            rnd(rng.uniform(38.0, 44.0)),
            lane_w,
            rnd(rng.uniform(2.0, 2.4)),
            rnd(rng.uniform(2.5, 4.0)),
        )
    return StreetGrid(
        kind,
        nx,
        ny,
        rnd(rng.uniform(48.0, 56.0)),
        lane_w,
        rnd(rng.uniform(2.0, 2.3)),
        rnd(rng.uniform(1.8, 2.5)),
    )


def drive_route(g: StreetGrid) -> list[tuple[int, int]]:
    """The crossings of the drive's figure eight, as (i, j) grid nodes, closing on its start.

    The route goes round the two blocks either side of the street ``i = c`` (c = nx // 2, the
    blocks in row ``b = (ny - 1) // 2``): north along that street, anticlockwise round the west
    block, north along it again, clockwise round the east block, back to the start. The shared
    street is driven once per loop, so every loop after the first revisits it.
    """
    c = g.nx // 2
    b = (g.ny - 1) // 2
    return [
        (c, b),
        (c, b + 1),
        (c - 1, b + 1),
        (c - 1, b),
        (c, b),
        (c, b + 1),
        (c + 1, b + 1),
        (c + 1, b),
        (c, b),
    ]
