"""Write nidar_mi/materials/data/earthlib_catalog.json: the earthlib spectra the material
catalogue names, copied from the installed earthlib package (MIT licence).

The catalogue's materials (``nidar_mi.materials.catalog``) need 20 of earthlib's 7261 spectra;
shipping them lets a render run without earthlib (whose import pulls pandas). Every value is
the library's float32, written as the shortest decimal that reads back to the same float32;
the script checks that it does.

    .venv/bin/python -m pip install 'nidar_mi[earthlib]'
    .venv/bin/python scripts/extract_earthlib_spectra.py
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(REPO, "nidar_mi", "materials", "data", "earthlib_catalog.json")


def _f32(value: float) -> float | None:
    v = np.float32(value)
    if not np.isfinite(v):
        return None
    text = np.format_float_positional(v, unique=True, trim="-")
    assert np.float32(float(text)) == v, (value, text)
    return float(text)


def _dumps(doc: dict) -> str:
    lines = [f" {json.dumps(k)}: {json.dumps(v)}" for k, v in doc.items() if k != "spectra"]
    rows = ",\n".join(f"  {json.dumps(s)}" for s in doc["spectra"])
    return "{\n" + ",\n".join(lines) + ',\n "spectra": [\n' + rows + "\n ]\n}\n"


def main() -> int:
    sys.path.insert(0, REPO)
    from nidar_mi.materials.catalog import catalog_spectra
    from nidar_mi.materials.earthlib_data import load_earthlib

    lib = load_earthlib()
    spectra = []
    for level_2, level_3, name in catalog_spectra():
        i = lib.index(level_2, level_3, name)
        spectra.append(
            {
                "level_2": level_2,
                "level_3": level_3,
                "level_4": lib.level_4[i],
                "name": name,
                "source": lib.sources[i],
                "notes": lib.notes[i],
                "reflectance": [_f32(v) for v in lib.data[i]],
            }
        )
    doc = {
        "about": "earthlib spectra named by nidar_mi.materials.catalog, copied from earthlib's "
        "data/spectra.sli and data/spectra.csv by scripts/extract_earthlib_spectra.py",
        "earthlib_version": importlib.metadata.version("earthlib"),
        "license": "MIT (earthlib, https://github.com/earth-chris/earthlib)",
        "wavelengths_nm": [float(w) for w in lib.wavelengths_nm],
        "spectra": spectra,
    }
    with open(OUT, "w", encoding="utf-8") as f:  # one line per key and per spectrum
        f.write(_dumps(doc))
    print(f"wrote {len(spectra)} spectra x {len(lib.wavelengths_nm)} bands to {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
