"""The demo street in clear air, fog and rain: camera and LiDAR side by side.

    .venv/bin/python scripts/weather_figures.py [--width 320] [--spp 128] [--cols 1024] [--out DIR]

Writes ``street_clear.png``, ``street_fog.png`` and ``street_rain.png`` (default into
``docs/figures/weather/``): left, the forward camera's image (RGB through the medium,
``nidar_mi.weather.camera_medium``; auto exposure of the clear image for all three, so the fog's own
light shows; a 3 x 3 median filter on every image takes out the isolated bright pixels of the
sun's light scattered by the medium, the path tracer's variance at this sample count); right, the HDL-64E's points seen from above, coloured by what they came from
(surface by intensity, fog, drop). Fog: MOR 50 m (advection); rain: 25 mm/h. Simulated data
only. The scene is ``scenes/street.xml``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
CONDITIONS = {"clear": {}, "fog": {"fog": 50.0}, "rain": {"rain": 25.0}}
COLOURS = {1: (0.25, 0.55, 1.0), 2: (0.0, 0.85, 0.85), 3: (0.9, 0.2, 0.9)}  # fog, drop, flake


def render(condition: str, *, width: int, spp: int, cols: int):
    """(the camera's linear RGB image, the LiDAR's points) of the street in ``condition``."""
    from nidar_mi.camera import render_camera
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene
    from nidar_mi.weather import Weather

    height = int(round(width * 9 / 16))
    params = {"width": str(width), "height": str(height), "cols": str(cols)}
    loaded = load_scene(str(REPO / "scenes" / "street.xml"), params=params)
    weather = Weather(**CONDITIONS[condition]) if CONDITIONS[condition] else None
    for sensor in loaded.lidars:
        sensor.weather = weather
    result = scan(loaded.scene, loaded.lidars[0], seed=1)
    cam = render_camera(loaded, loaded.cameras[0], wavelength=905.0, spp=spp, seed=1, albedo=False)
    return cam.rgb, result.points()


def figure(rgb: np.ndarray, points: dict, exposure: float, title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from nidar_mi.io.images import linear_to_srgb

    fig, (a, b) = plt.subplots(1, 2, figsize=(9.6, 2.9), gridspec_kw={"width_ratios": [1.6, 1]})
    from scipy.ndimage import median_filter

    rgb = median_filter(rgb, size=(3, 3, 1))
    a.imshow(np.clip(linear_to_srgb(np.clip(rgb * exposure, 0.0, 1.0)), 0.0, 1.0))
    a.set_axis_off()
    a.set_title(f"camera, {title}", fontsize=9)
    xyz = points["xyz"]
    kind = points.get("scatterer", np.zeros(len(xyz), np.uint8))
    surface = kind == 0
    shade = np.clip(np.sqrt(points["intensity"][surface] * points["range"][surface] ** 2), 0, 0.6)
    b.scatter(xyz[surface, 0], xyz[surface, 1], c=shade, cmap="gray", vmin=-0.2, vmax=0.6, s=0.3)
    for code, colour in COLOURS.items():
        sel = kind == code
        if sel.any():
            name = str(points["scatterer_names"][code])
            b.scatter(xyz[sel, 0], xyz[sel, 1], color=colour, s=0.6, label=f"{name} ({sel.sum()})")
    b.set(xlim=(-15, 45), ylim=(-15, 15), aspect="equal")
    b.set_facecolor("black")
    b.tick_params(labelsize=6)
    b.set_title(f"LiDAR from above, {title} ({len(xyz)} points)", fontsize=9)
    if (kind > 0).any():
        b.legend(fontsize=6, loc="lower right", markerscale=6)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--width", type=int, default=320, help="camera image width (16:9)")
    p.add_argument("--spp", type=int, default=128, help="camera samples per pixel")
    p.add_argument("--cols", type=int, default=1024, help="LiDAR columns")
    p.add_argument("--out", default=str(REPO / "docs" / "figures" / "weather"))
    args = p.parse_args(argv)
    from nidar_mi.backend import set_variant
    from nidar_mi.camera import auto_exposure

    set_variant()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    exposure = None
    for condition, values in CONDITIONS.items():
        rgb, points = render(condition, width=args.width, spp=args.spp, cols=args.cols)
        exposure = auto_exposure(rgb) if exposure is None else exposure
        title = condition if not values else ", ".join(f"{k} {v:g}" for k, v in values.items())
        title = title.replace("fog 50", "fog MOR 50 m").replace("rain 25", "rain 25 mm/h")
        figure(rgb, points, exposure, title, out / f"street_{condition}.png")
        print(f"wrote {out / f'street_{condition}.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
