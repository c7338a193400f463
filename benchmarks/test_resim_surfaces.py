"""The surface a re-simulated return lies on (benchmarks/resim_surfaces.py), by hand."""

from __future__ import annotations

import os
import sys

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import resim_surfaces as bench  # noqa: E402


def test_points_on_the_mesh_on_a_splat_and_off_both():
    # the fused mesh: the unit square z = 0 (two triangles); then one splat, the square
    # x in [5, 5.1], y in [0, 0.1] at z = 1 (two triangles)
    v = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [5, 0, 1], [5.1, 0, 1], [5.1, 0.1, 1],
         [5, 0.1, 1]], dtype=float,
    )  # fmt: skip
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    pts = np.array(
        [
            [0.5, 0.5, 0.0],  # on the mesh
            [0.2, 0.7, 0.04],  # 4 cm above it: still on it
            [5.05, 0.05, 1.0],  # on the splat
            [5.05, 0.05, 1.0 - 0.049],  # just within ON_PLY_M of it
            [0.5, 0.5, 0.06],  # 6 cm above the mesh: a surface that moved
            [3.0, 0.0, 0.5],  # far from both
        ]
    )
    np.testing.assert_array_equal(bench.surface_kind(pts, v, f, 2), [0, 0, 1, 1, 2, 2])
    # every triangle counted as the mesh's: no splat
    np.testing.assert_array_equal(bench.surface_kind(pts, v, f, 4), [0, 0, 0, 0, 2, 2])
