"""Definitions of the named materials (measured spectra from earthlib, and models).

Measured spectra were picked from earthlib's metadata by class and visual check of each
candidate's spectrum. The Santa Barbara urban library (Herold et al. 2004, ``SOURCE == "asd"``,
notes "urban reflectance spectra from santa barbara") codes a surface in its names; for road
asphalt the 4th-5th letters give the age (``ye``/``yg`` young, ``mm``/``mg`` medium, ``of``/``op``
old), which the reflectance bears out (young asphalt is darker). Vegetation canopies are PROSAIL
simulations that earthlib ships (LAI, leaf mass per area LMA, chlorophyll CHL in the name).

Modelled spectra use the shapes of :mod:`.spectra`; their ``source`` says what they stand for.
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

from .earthlib_data import EARTHLIB_LICENSE, earthlib_notes, earthlib_spectrum
from .material import Material
from .metals import METAL_SOURCES, METALS_LICENSE, metal_nk, metal_reflectance
from .optics import SODA_LIME_SOURCE, soda_lime_ior
from .spectra import GRID_NM, Spectrum, absorption_band, flat, logistic

__all__ = [
    "build_catalog",
    "catalog_spectra",
    "CLEAR_COAT_IOR",
    "GLASS_IOR_WAVELENGTH_NM",
    "ROAD_SURFACE",
]

MODEL_LICENSE = "CC0 1.0 (parametric model defined in nidar_mi)"
#: Refractive index of automotive clear coat (acrylic / polyurethane), used for car paints.
CLEAR_COAT_IOR = 1.5
#: Mitsuba's dielectric takes one index: glass uses Rubin's n at this wavelength (nm).
GLASS_IOR_WAVELENGTH_NM = 905.0

# (name, LEVEL_2, LEVEL_3, NAME, description)
_EARTHLIB_DIFFUSE = (
    ("asphalt_new", "built", "road", "rpaeye.006-", "fresh, dark road asphalt"),
    ("asphalt_old", "built", "road", "rpaeof.001-", "aged, greyed road asphalt"),
    ("concrete", "built", "sidewalk", "spcsmg.001-", "concrete sidewalk"),
    ("brick_red", "built", "sidewalk", "subrmg.001-", "red brick paving"),
    ("roof_tile_red", "built", "tile", "fttrme.001-", "red clay roof tile"),
    ("shingle", "built", "comp_shingle", "fscnmm.003-", "dark composition roof shingle"),
    ("gravel", "bare", "gravel", "mugexx.001-", "grey gravel"),
    ("lane_paint_white", "built", "paint", "trawyg.001-", "white road-marking paint"),
    ("lane_paint_yellow", "built", "paint", "trayye.001-", "yellow road-marking paint"),
    ("curb_paint_red", "built", "paint", "tccrye.001-", "red kerb paint"),
    ("marking_paint_blue", "built", "paint", "tpabmg.001-", "blue parking-bay paint"),
    ("grass", "vegetation", "canopy", "v-LAI-3.0-LMA-0.008-CHL-40.7-N-1.6", "green grass (LAI 3)"),
    (
        "tree_canopy",
        "vegetation",
        "canopy",
        "v-LAI-6.2-LMA-0.011-CHL-51.4-N-1.8",
        "dense tree canopy (LAI 6.2)",
    ),
    ("grass_dry", "npv", "litter", "Grass_dry.9+.1green", "dry grass with 10 % green"),
    ("bark", "npv", "bark", "ndbnof.001-", "tree bark"),
    ("wood_pallet", "npv", "wood", "ndwnmm.001-", "sawn wood (pallet, fence)"),
    ("soil_dry", "bare", "soil", "FS15R_FS4275", "dry brown soil (laboratory, ICRAF-ISRIC)"),
    ("dirt", "bare", "dirt", "lcxnxx.001-", "urban bare dirt"),
    ("sand", "bare", "sand", "lbxsxx.001-", "beach sand"),
)

#: The earthlib spectra of the car paints' pigments (LEVEL_2, LEVEL_3, NAME).
_RED_PIGMENT = ("built", "paint", "tccrye.001-")
_BLUE_PIGMENT = ("built", "paint", "tpabmg.001-")


def catalog_spectra() -> list[tuple[str, str, str]]:
    """The earthlib spectra the catalogue names, ``(LEVEL_2, LEVEL_3, NAME)`` each, in order
    and without repeats (shipped as ``materials/data/earthlib_catalog.json``)."""
    names = [(l2, l3, sid) for _, l2, l3, sid, _ in _EARTHLIB_DIFFUSE]
    names += [_RED_PIGMENT, _BLUE_PIGMENT]
    return list(dict.fromkeys(names))


def _freeze(**params) -> MappingProxyType:
    return MappingProxyType(dict(params))


def _earthlib_source(level_2: str, level_3: str, name: str) -> str:
    return f"earthlib:{level_2}/{level_3}/{name}"


#: Road surfaces rendered rough (``roughdiffuse``): asphalt and concrete keep returning LiDAR
#: light at grazing incidence. ``sigma`` (facet slope deviation, degrees) is the value at which
#: ``asphalt_old`` seen from 1.73 m is detected to the HDL-64E datasheet's 50 m for pavement with
#: its 4e-5 threshold and ``B0 = 1`` (Hapke's shadow-hiding amplitude of a dark surface);
#: :func:`nidar_mi.lidar.link_budget.sigma_for_reach` reproduces it. The surge's 5 degree half
#: width matters only away from the monostatic direction (cameras) and is not calibrated.
ROAD_SURFACE = {"sigma": 35.1, "opposition_amplitude": 1.0, "opposition_width": 5.0}
_ROUGH = frozenset({"asphalt_new", "asphalt_old", "concrete"})


def _earthlib_materials() -> list[Material]:
    out = []
    for name, l2, l3, sid, desc in _EARTHLIB_DIFFUSE:
        notes = (
            f"earthlib metadata: {earthlib_notes(l2, l3, sid)}; extended below 400 nm and across "
            "1350-1460 nm as in nidar_mi.materials.earthlib_data"
        )
        params = {"reflectance": earthlib_spectrum(l2, l3, sid)}
        if name in _ROUGH:
            params |= ROAD_SURFACE
            notes += (
                "; rough diffuse road surface (roughdiffuse: Oren-Nayar sigma, Hapke opposition "
                "surge) derived in nidar_mi.lidar.link_budget"
            )
        out.append(
            Material(
                name=name,
                kind="rough_diffuse" if name in _ROUGH else "diffuse",
                description=desc,
                source=_earthlib_source(l2, l3, sid),
                license=EARTHLIB_LICENSE,
                params=_freeze(**params),
                notes=notes,
            )
        )
    return out


def _panels() -> list[Material]:
    out = []
    for name, rho, desc in (
        ("white_panel_95", 0.95, "95 % white calibration panel"),
        ("grey_panel_50", 0.50, "50 % grey calibration panel"),
        ("black_panel_5", 0.05, "5 % black calibration panel"),
    ):
        out.append(
            Material(
                name=name,
                kind="diffuse",
                description=desc,
                source=f"model:spectrally flat Lambertian target, rho = {rho} (Spectralon-like)",
                license=MODEL_LICENSE,
                params=_freeze(reflectance=flat(rho)),
                notes="ideal calibration target: flat from 360 to 1700 nm",
            )
        )
    return out


def _metals() -> list[Material]:
    out = []
    for name, metal, alpha, desc in (
        ("aluminium", "Al", 0.2, "aluminium, lightly brushed"),
        ("copper", "Cu", 0.2, "copper, lightly brushed"),
        ("chromium", "Cr", 0.1, "chromium plating"),
        ("iron", "Fe", 0.3, "bare iron / steel"),
        ("steel_galvanised", "Zn", 0.35, "hot-dip galvanised steel (zinc surface)"),
    ):
        eta, k = metal_nk(metal)
        out.append(
            Material(
                name=name,
                kind="conductor",
                description=desc,
                source=f"model:complex refractive index of {metal}, {METAL_SOURCES[metal]}",
                license=METALS_LICENSE,
                params=_freeze(metal=metal, eta=eta, k=k, alpha=alpha),
                notes=f"GGX roughness alpha={alpha}; clean metal, no oxide or paint",
            )
        )
    return out


def _car_paints() -> list[Material]:
    grid = GRID_NM
    # TiO2 white: absorption edge near 400 nm, slow decline of the binder-pigment contrast in the NIR.
    white = logistic(0.06, 0.86, 405.0, 8.0).map(
        lambda v: v * np.interp(grid, [800.0, 1700.0], [1.0, 0.85])
    )
    silver = Spectrum(grid, 0.45 * metal_reflectance("Al", grid))
    pigments = (
        (
            "car_paint_red",
            earthlib_spectrum(*_RED_PIGMENT),
            "red",
            _earthlib_source(*_RED_PIGMENT),
            EARTHLIB_LICENSE,
        ),
        (
            "car_paint_blue",
            earthlib_spectrum(*_BLUE_PIGMENT),
            "blue",
            _earthlib_source(*_BLUE_PIGMENT),
            EARTHLIB_LICENSE,
        ),
        (
            "car_paint_white",
            white,
            "white",
            "model:TiO2 white pigment, edge at 405 nm, rho 0.86 falling to 0.73 at 1700 nm",
            MODEL_LICENSE,
        ),
        (
            "car_paint_black",
            flat(0.04),
            "black",
            "model:carbon-black pigment, rho 0.04 from 360 to 1700 nm (absorbs through the NIR)",
            MODEL_LICENSE,
        ),
        (
            "car_paint_silver",
            silver,
            "metallic silver",
            f"model:aluminium flakes, rho = 0.45 R_Al(normal), {METAL_SOURCES['Al']}",
            MODEL_LICENSE,
        ),
    )
    out = []
    for name, pigment, colour_name, source, lic in pigments:
        out.append(
            Material(
                name=name,
                kind="plastic",
                description=f"{colour_name} car paint: pigment layer under a clear coat",
                source=source,
                license=lic,
                params=_freeze(reflectance=pigment, alpha=0.1, int_ior=CLEAR_COAT_IOR),
                notes=(
                    f"source gives the pigment (diffuse) layer; clear coat modelled as roughplastic "
                    f"with GGX alpha=0.1, n={CLEAR_COAT_IOR}"
                ),
            )
        )
    return out


def _other_models() -> list[Material]:
    # Polyethylene: C-H overtone/combination bands at 1.21, 1.39-1.41 and 1.73 um
    # (J. Workman, L. Weyer, Practical Guide to Interpretive Near-Infrared Spectroscopy, 2007).
    wrap = flat(0.6)
    for c, w, d in ((1210.0, 40.0, 0.15), (1395.0, 50.0, 0.20), (1730.0, 40.0, 0.30)):
        wrap = absorption_band(wrap, c, w, d)
    # Dark-blue dyed cotton: dye absorbs in the visible and turns transparent past ~700 nm;
    # cellulose/water bands near 1200 and 1490 nm.
    blue_hump = 0.06 * np.exp(-0.5 * ((GRID_NM - 460.0) / 40.0) ** 2)
    fabric = Spectrum(GRID_NM, 0.04 + blue_hump + logistic(0.0, 0.5, 720.0, 20.0).values)
    fabric = absorption_band(absorption_band(fabric, 1200.0, 60.0, 0.10), 1490.0, 120.0, 0.25)
    return [
        Material(
            name="rubber_tyre",
            kind="plastic",
            description="tyre rubber (carbon-black filled)",
            source="model:carbon-black filled rubber, rho 0.035 from 360 to 1700 nm, n=1.52",
            license=MODEL_LICENSE,
            params=_freeze(reflectance=flat(0.035), alpha=0.35, int_ior=1.52),
            notes="roughplastic, GGX alpha=0.35",
        ),
        Material(
            name="plastic_wrap",
            kind="plastic",
            description="white polyethylene stretch wrap",
            source=(
                "model:white polyethylene, rho 0.6 with C-H bands at 1210, 1395, 1730 nm "
                "(Workman & Weyer, Practical Guide to Interpretive NIR Spectroscopy, 2007)"
            ),
            license=MODEL_LICENSE,
            params=_freeze(reflectance=wrap, alpha=0.15, int_ior=1.51),
            notes="roughplastic, GGX alpha=0.15, n=1.51 (polyethylene)",
        ),
        Material(
            name="fabric",
            kind="diffuse",
            description="dark-blue dyed cotton fabric",
            source=(
                "model:dyed cotton, dark blue in the visible, dye transparent past 700 nm "
                "(NIR plateau 0.5), cellulose bands at 1200 and 1490 nm"
            ),
            license=MODEL_LICENSE,
            params=_freeze(reflectance=fabric),
            notes="illustrates why visible colour does not predict NIR intensity",
        ),
    ]


def _glass() -> list[Material]:
    ior = float(soda_lime_ior(GLASS_IOR_WAVELENGTH_NM))
    # Blue-tinted float glass: cobalt/iron colouring; Fe2+ band centred near 1050 nm
    # (C. R. Bamford, Colour Generation and Control in Glass, Elsevier 1977).
    tint = absorption_band(logistic(0.85, 0.45, 560.0, 30.0), 1050.0, 500.0, 0.6)
    out = []
    for name, trans, desc, extra in (
        ("glass_clear", None, "clear soda-lime window glass", ""),
        (
            "glass_blue",
            tint,
            "blue-tinted soda-lime glass",
            "; tint: transmittance 0.85 (blue) to 0.45 (red) with an Fe2+ band at 1050 nm "
            "(Bamford 1977, Colour Generation and Control in Glass)",
        ),
    ):
        out.append(
            Material(
                name=name,
                kind="dielectric",
                description=desc,
                source=f"model:{SODA_LIME_SOURCE}{extra}",
                license=MODEL_LICENSE,
                params=_freeze(int_ior=ior, alpha=0.0, transmittance=trans),
                notes=(
                    f"thin pane (thindielectric), n={ior:.4f} (Rubin at "
                    f"{GLASS_IOR_WAVELENGTH_NM:g} nm; Mitsuba's dielectric has no dispersion)"
                ),
            )
        )
    return out


def _retro() -> list[Material]:
    white = logistic(0.55, 0.80, 400.0, 10.0)
    red = logistic(0.04, 0.75, 600.0, 10.0)
    out = []
    for name, rho, desc, src in (
        (
            "retro_sheeting_white",
            white,
            "white retroreflective sheeting",
            "rho 0.80, UV edge at 400 nm",
        ),
        (
            "retro_sheeting_red",
            red,
            "red retroreflective sheeting",
            "rho 0.04 below 600 nm, 0.75 above (red dye, transparent in the NIR)",
        ),
    ):
        out.append(
            Material(
                name=name,
                kind="retroreflector",
                description=desc,
                source=f"model:glass-bead / prismatic sheeting, vMF retro lobe, {src}",
                license=MODEL_LICENSE,
                params=_freeze(reflectance=rho, lobe_width=2.0, diffuse_fraction=0.05),
                notes="retroreflector BSDF, lobe half width 2 deg, 5 % Lambertian base",
            )
        )
    return out


def build_catalog() -> dict[str, Material]:
    """All materials by name (reads earthlib once)."""
    materials = (
        _earthlib_materials()
        + _panels()
        + _metals()
        + _car_paints()
        + _other_models()
        + _glass()
        + _retro()
    )
    catalog = {m.name: m for m in materials}
    if len(catalog) != len(materials):
        raise RuntimeError("duplicate material names in the catalog")
    return catalog
