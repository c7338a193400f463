"""Points and intensity on calibration panels in rain and fog, beside the measured statements
(docs/WEATHER.md, "Against the measured and published curves").

``python benchmarks/weather_panels.py [--cols N] [--sensor NAME ...]``

The panels of ``scenes/target.xml`` (white 95 %, grey 50 %, black 5 %, 1 m x 1 m, at 5, 10 and
20 m) are scanned at 905 nm in clear air and in the conditions of the two weather-tunnel and
test-road studies of the Korea Institute of Civil Engineering and Building Technology below
(:func:`nidar_mi.studies.weather_curves.panel_sweep`): per condition, the share of each panel's
clear points still returned from it (``NPC``, their "number of point cloud") and the change of
the mean intensity of those points. The studies report no spread in the text that could be
read (their abstracts); they report orders of the conditions and one t-tested "no difference",
and those are what the model is put beside.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys

#: What was read, where: (source, statement).
SOURCES = {
    "KP2022": (
        "Kim & Park, A Study of LiDAR's Detection Performance Degradation in Fog and Rain "
        "Climate, J. Korea Inst. ITS 21(2) 101-115, 2022, doi:10.12815/kits.2022.21.2.101 "
        "(abstract, journal.kits.or.kr)"
    ),
    "KPK2023": (
        "Kim, Park & Kim, Empirical Analysis of Autonomous Vehicle's LiDAR Detection "
        "Performance Degradation for Actual Road Driving in Rain and Fog, Sensors 23(6) 2972, "
        "2023, doi:10.3390/s23062972 (abstract)"
    ),
}
#: KP2022: "the performance of LiDAR decreased in the order in situations of 20 mm/h
#: rainfall, fog visibility less than 200 m, 50 mm/h rainfall, fog visibility less than 150 m,
#: fog visibility less than 100 m, and fog visibility less than 50 m" (NPC and intensity).
ORDER_KP2022 = [("rain", 20.0), ("fog", 200.0), ("rain", 50.0), ("fog", 150.0)]
ORDER_KP2022 += [("fog", 100.0), ("fog", 50.0)]
#: KPK2023: "These indicators decreased with deteriorating weather in order of light rain
#: (10-20 mm/h), weak fog (<150 m), intense rain (30-40 mm/h), and thick fog (<=50 m)"; each
#: group is represented by the condition at its severe end.
ORDER_KPK2023 = [("rain", 20.0), ("fog", 150.0), ("rain", 40.0), ("fog", 50.0)]
#: KP2022: "in the case of white, there was no difference in performance at a measurement
#: distance of 10 m even at 50 m fog visibility ... also statistically significant" (t-test).
NO_DIFFERENCE = ("white_95", 10.0, ("fog", 50.0))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="weather_panels.py", description=__doc__.split("\n")[0])
    p.add_argument("--cols", type=int, default=2048, help="columns per revolution (64-16384)")
    p.add_argument(
        "--sensor",
        action="append",
        help="HDL-64E-like or OS1-like (repeatable; default both)",
    )
    return p


def _weather(kind: str, value: float):
    from nidar_mi.weather import Weather

    return Weather(fog=value) if kind == "fog" else Weather(rain=value)


def _key(weather) -> tuple[str, float]:
    return ("fog", weather.fog) if weather.fog else ("rain", weather.rain)


def _severity(points, key) -> float:
    """1 - the mean intensity ratio of the normal-incidence panels at 10 and 20 m (a beam
    that no longer returns the panel counts as 0)."""
    sel = [p for p in points if p.incidence == 0.0 and p.distance >= 10.0]
    sel = [p for p in sel if _key(p.weather) == key]
    vals = [
        p.npc_ratio * (0.0 if math.isnan(p.intensity_ratio) else p.intensity_ratio) for p in sel
    ]
    return 1.0 - sum(vals) / len(vals)


def _pairs(order, severity) -> tuple[int, int, list[str]]:
    """Pairs of conditions the model orders as the measurement does, of all pairs, and the
    inverted ones."""
    agree, inverted = 0, []
    for a, b in itertools.combinations(order, 2):  # a measured milder than b
        if severity[a] < severity[b]:
            agree += 1
        else:
            inverted.append(f"{a[0]} {a[1]:g} vs {b[0]} {b[1]:g}")
    return agree, len(inverted) + agree, inverted


def report(name: str, points) -> None:
    keys = list(dict.fromkeys(ORDER_KP2022 + ORDER_KPK2023))
    print(f"\n{name}, 905 nm: NPC ratio / intensity ratio per panel (normal incidence)\n")
    print("| panel | " + " | ".join(f"{k} {v:g}" for k, v in keys) + " |")
    print("|---|" + "---:|" * len(keys))
    by_panel: dict[str, dict] = {}
    for p in points:
        by_panel.setdefault(p.panel, {})[_key(p.weather)] = p
    for panel, row in by_panel.items():
        if next(iter(row.values())).incidence != 0.0:
            continue
        cells = [f"{row[k].npc_ratio:.2f} / {row[k].intensity_ratio:.2f}" for k in keys]
        print(f"| {panel} | " + " | ".join(cells) + " |")
    severity = {k: _severity(points, k) for k in keys}
    print(
        "\nseverity (1 - mean intensity ratio, 10 and 20 m panels): "
        + ", ".join(f"{k} {v:g}: {severity[k, v]:.3f}" for k, v in keys)
    )
    for tag, order in (("KP2022", ORDER_KP2022), ("KPK2023", ORDER_KPK2023)):
        agree, total, inverted = _pairs(order, severity)
        print(f"order of {tag}: {agree} of {total} pairs as measured; inverted: {inverted}")
    material, distance, key = NO_DIFFERENCE
    p = next(
        q
        for q in points
        if q.material == material
        and q.distance == distance
        and q.incidence == 0.0
        and _key(q.weather) == key
    )
    print(
        f"{material} at {distance:g} m, fog {key[1]:g} m (measured: no significant "
        f"difference): NPC ratio {p.npc_ratio:.3f}, intensity ratio {p.intensity_ratio:.3f}"
    )


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from nidar_mi.studies import weather_curves as ws

    names = args.sensor or list(ws.SENSORS)
    unknown = [n for n in names if n not in ws.SENSORS]
    if unknown or not 64 <= args.cols <= 16384:
        what = f"unknown sensor {unknown[0]!r}" if unknown else f"--cols {args.cols}"
        print(f"error: {what} (sensors: {', '.join(ws.SENSORS)}; cols 64-16384)", file=sys.stderr)
        return 2
    from nidar_mi.backend import set_variant

    set_variant()
    for tag, source in SOURCES.items():
        print(f"{tag}: {source}")
    keys = list(dict.fromkeys(ORDER_KP2022 + ORDER_KPK2023))
    conditions = [_weather(k, v) for k, v in keys]
    for name in names:
        report(name, ws.panel_sweep(ws.SENSORS[name], 905.0, conditions, cols=args.cols))
    return 0


if __name__ == "__main__":
    sys.exit(main())
