"""Spectral regimes: ``earthlib`` gives scenes measured spectra from families no held-out
material comes from, deterministically, and keeps everything else of the scene."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.materials import get_material
from nidar_mi.materials.earthlib_data import earthlib_row_spectrum, load_earthlib
from nidar_mi.materials.spectra import Spectrum
from nidar_mi.scenegen.generate import generate, generate_scene
from nidar_mi.scenegen.objects import HELDOUT_MATERIALS
from nidar_mi.scenegen.spectral_regimes import (
    FAMILIES,
    REPLACED_FRACTION,
    draw_spectra,
    pool_classes,
)


def test_the_pool_holds_no_spectrum_of_a_held_out_family():
    lib = load_earthlib()
    classes = dict(pool_classes())
    held = [get_material(m).source for m in HELDOUT_MATERIALS]
    held = [s.split(":", 1)[1].split("/") for s in held if s.startswith("earthlib:")]
    assert len(held) >= 7  # asphalt, dirt, sand, yellow paint, dry grass, brick, tile, red paint
    for level_2, level_3, name in held:
        assert (level_2, level_3) not in classes
        row = lib.index(level_2, level_3, name)
        assert all(row not in rows for rows in classes.values())
    # every row listed is of its class; the big classes are there
    for (level_2, level_3), rows in classes.items():
        assert all(lib.level_2[i] == level_2 and lib.level_3[i] == level_3 for i in rows)
    assert ("bare", "soil") in classes and ("vegetation", "canopy") in classes
    assert ("built", "glass") not in classes


def test_earthlib_keeps_the_scene_and_changes_three_quarters_of_the_surfaces():
    base, base_text = generate_scene(4, 1, "urban", materials="train", lighting="varied")
    kw = {"materials": "train", "lighting": "varied", "spectra": "earthlib"}
    layout, text = generate_scene(4, 1, "urban", **kw)
    assert layout == base and text != base_text
    assert generate_scene(4, 1, "urban", **kw)[1] == text
    drawn = draw_spectra(layout.materials(), 4, 1, "earthlib")
    root = ET.fromstring(text)
    for m in layout.materials():
        el = root.find(f"bsdf[@id='mat_{m}']/spectrum[@name='reflectance']")
        assert (el is not None) == (m in drawn)
        if el is not None:
            s = Spectrum.parse_xml_value(el.get("value"))
            np.testing.assert_allclose(s.values, drawn[m].spectrum.values, atol=1e-6)
    # over many scenes: only diffuse, road and paint materials, about 3/4 of them
    n = hits = 0
    for k in range(40):
        materials = generate_scene(8, k, materials="train")[0].materials()
        drawn = draw_spectra(materials, 8, k, "earthlib")
        for m in materials:
            kind = get_material(m).kind
            if kind in ("diffuse", "rough_diffuse", "plastic"):
                n, hits = n + 1, hits + (m in drawn)
            else:
                assert m not in drawn
    p = REPLACED_FRACTION
    assert abs(hits / n - p) < 4 * math.sqrt(p * (1 - p) / n)


def test_a_drawn_spectrum_is_the_earthlib_measurement():
    lib = load_earthlib()
    drawn = draw_spectra(["concrete", "grass", "wood_pallet", "soil_dry"], 2, 0, "earthlib")
    assert drawn
    for s in drawn.values():
        level_2, level_3, name = s.source.split(":", 1)[1].split("/", 2)
        rows = [i for i in dict(pool_classes())[(level_2, level_3)] if lib.names[i] == name]
        assert any(np.allclose(earthlib_row_spectrum(i).values, s.spectrum.values) for i in rows)
        measured = np.interp(905.0, lib.wavelengths_nm, lib.data[rows[0]])
        if len(rows) == 1:
            np.testing.assert_allclose(s.spectrum(905.0), measured, rtol=1e-5)


def test_library_draws_nothing_and_an_unknown_regime_is_an_error():
    assert draw_spectra(["concrete"], 0, 0, "library") == {}
    with pytest.raises(NidarError, match="spectra must be one of"):
        draw_spectra(["concrete"], 0, 0, "usgs")


def test_the_index_records_each_drawn_spectrum(tmp_path):
    generate(str(tmp_path), 2, 6, kind="urban", progress=False, spectra="earthlib")
    for entry in json.loads((tmp_path / "index.json").read_text())["scenes"]:
        text = (tmp_path / entry["file"]).read_text()
        assert entry["spectra"]
        for m, source in entry["spectra"].items():
            assert f"<!-- mat_{m}: the spectrum of {source} -->" in text


def test_earthlib_family_keeps_what_each_surface_is():
    """``earthlib-family``: a material of :data:`FAMILIES` takes a spectrum of one of its own
    family's classes, about 3/4 of the time; every other material keeps its own."""
    pool = dict(pool_classes())
    assert all(c in pool for classes in FAMILIES.values() for c in classes)
    n = hits = 0
    for k in range(40):
        materials = generate_scene(9, k, materials="train")[0].materials()
        drawn = draw_spectra(materials, 9, k, "earthlib-family")
        for m in materials:
            if m not in FAMILIES:
                assert m not in drawn
                continue
            n, hits = n + 1, hits + (m in drawn)
            if m in drawn:
                level_2, level_3, _ = drawn[m].source.split(":", 1)[1].split("/", 2)
                assert (level_2, level_3) in FAMILIES[m]
    p = REPLACED_FRACTION
    assert n > 50 and abs(hits / n - p) < 4 * math.sqrt(p * (1 - p) / n)
