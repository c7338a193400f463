"""Regenerate the golden scan of tests/golden/small_scene.xml: ``python tests/golden/regenerate.py``."""

from __future__ import annotations

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
SCENE = os.path.join(HERE, "small_scene.xml")
GOLDEN = os.path.join(HERE, "small_scene_points.npz")


def scan_golden_scene():
    """Scan the golden scene in the CPU variant; returns the points dict."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    loaded = load_scene(SCENE, variant="llvm_ad_spectral")
    return scan(loaded.scene, loaded.lidars[0]).points()


def main() -> int:
    from nidar_mi.backend import set_variant
    from nidar_mi.io.points import write_npz

    set_variant("llvm_ad_spectral")
    pts = scan_golden_scene()
    write_npz(GOLDEN, pts)
    print(f"wrote {len(pts['range'])} points to {GOLDEN} ({os.path.getsize(GOLDEN)} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
