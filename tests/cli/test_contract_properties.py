"""Property-based tests of the command-line contract (hypothesis).

Random LiDAR XML parameters, ``-D`` values, seeds, and ``assign`` point clouds, calibrations and
images, valid or not. Whatever the input, a command either succeeds (status 0, only ``warning:``
lines on stderr, no NaN or infinity in any output) or refuses it (status 2, exactly one
``error:`` line, no traceback, the output folder byte for byte as it was, no staging folder
left). Commands run in this process on tiny inputs; examples are drawn from a fixed seed
(``derandomize``) so that a run is reproducible, and nothing is stored between runs.
Sizes stay small (at most 400 columns, 64 px images): memory bounds are tested elsewhere.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nidar_mi.io.images import read_exr
from nidar_mi.io.ownership import RECORD
from nidar_mi.io.points import read_npz, read_ply
from nidar_mi.nidar.pipeline import shipped_weights_dir

SETTINGS = settings(
    deadline=None,
    database=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

_TEXT = st.text(alphabet="abcxyz0123456789.,-+e _", max_size=12)
_NUMBER = st.one_of(
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.sampled_from(["nan", "inf", "-inf", "1e400", "", " ", "0x10", "1,5"]),
    _TEXT,
)


def _small(lo, hi):
    """Numbers near a parameter's legal range, and some garbage."""
    return st.one_of(st.floats(lo, hi), st.integers(int(lo) - 2, int(hi) + 2), _NUMBER)


# parameter -> (XML type, strategy of the value text)
LIDAR_PARAMETERS = {
    "preset": ("string", st.sampled_from(["vlp16", "HDL64E", "os1_128", "vlp17", "", "x y"])),
    "elevation_angles": (
        "string",
        st.one_of(
            st.lists(st.floats(-120, 120), min_size=0, max_size=6).map(
                lambda v: ", ".join(f"{a:g}" for a in v)
            ),
            _TEXT,
        ),
    ),
    "horizontal_resolution": ("integer", st.integers(-3, 400)),
    "fov_h": ("float", _small(-10, 400)),
    "wavelength": ("float", _small(200, 2000)),
    "gain": ("float", _small(-1, 10)),
    "range_min": ("float", _small(-1, 30)),
    "range_max": ("float", _small(-1, 200)),
    "atmospheric_extinction": ("float", _small(-0.1, 1)),
    "intensity_mode": ("string", st.sampled_from(["raw", "compensated", "Raw", "log", ""])),
    "noise_intensity_std": ("float", _small(-0.1, 1)),
    "noise_range_std": ("float", _small(-0.1, 1)),
    "detection_threshold": ("float", _small(-0.1, 1)),
    "receiver_noise_std": ("float", _small(-0.1, 1)),
    "dropout": ("float", _small(-0.5, 1.5)),
    "layout": ("string", st.sampled_from(["uniform", "per_laser", "PER_LASER", "grid", ""])),
    "calibration_file": ("string", st.sampled_from(["", "none.xml", "cal.yaml", "a.txt", "x y"])),
    "fov_h_centred": ("boolean", st.sampled_from(["true", "false", "1", "maybe"])),
    "rotation_rate": ("float", _small(-1, 200)),
    "spin": ("string", st.sampled_from(["cw", "ccw", "CW", "left", ""])),
    "scan_start_azimuth": ("float", _small(-400, 400)),
    "beam_divergence": ("float", _small(-1, 120)),
    "beam_sample_quality": ("integer", st.integers(-1, 14)),
    "return_mode": ("string", st.sampled_from(["strongest", "first", "last", "dual", "all", ""])),
    "return_separation": ("float", _small(-1, 5)),
    "seed": ("integer", st.one_of(st.integers(-5, 2**63 - 1), st.integers(-(2**70), 2**70))),
}


def _value_text(v) -> str:
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else str(v)
    return str(v)


def _scene_xml(lidar_params: dict[str, tuple[str, str]], camera: bool) -> str:
    props = "\n".join(
        f"<{kind} name={quoteattr(name)} value={quoteattr(value)}/>"
        for name, (kind, value) in lidar_params.items()
    )
    cam = (
        """<sensor type="perspective" id="cam"><float name="fov" value="90"/>
        <transform name="to_world"><lookat origin="0, 0, 1" target="1, 0, 1" up="0, 0, 1"/></transform>
        <film type="hdrfilm"><integer name="width" value="$width"/>
        <integer name="height" value="$height"/></film></sensor>"""
        if camera
        else ""
    )
    return f"""<?xml version="1.0"?>
<scene version="3.0.0">
    <default name="cols" value="36"/>
    <default name="width" value="8"/>
    <default name="height" value="6"/>
    <sensor type="lidar" id="lidar">
        {props if props else '<integer name="horizontal_resolution" value="$cols"/>'}
        <transform name="to_world"><translate z="1"/></transform>
    </sensor>
    {cam}
    <emitter type="constant"><spectrum name="radiance" value="360:1, 1700:1"/></emitter>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.3, 1700:0.6"/></bsdf>
    <shape type="sphere" id="dome"><float name="radius" value="20"/><ref id="grey"/>
        <boolean name="flip_normals" value="true"/></shape>
</scene>
"""


def _tree(folder: Path) -> dict[str, bytes]:
    if not folder.exists():
        return {}
    return {
        str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else b"/")
        for p in sorted(folder.rglob("*"))
    }


def _check_contract(status: int, err: str, out: Path, before: dict[str, bytes]) -> bool:
    """The contract of one call; returns whether it succeeded."""
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert not [p.name for p in out.parent.iterdir() if ".partial-" in p.name or ".old-" in p.name]
    if status == 0:
        assert all(ln.startswith("warning: ") for ln in lines), err
        return True
    assert status == 2, (status, err)
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert _tree(out) == before, "a refused call changed its output folder"
    return False


def _assert_finite_render(out: Path) -> None:
    for npz in out.glob("*/points.npz"):
        for key, value in read_npz(npz).items():
            if value.dtype.kind == "f":
                assert np.isfinite(value).all(), (npz, key)
    for exr in out.glob("*/*.exr"):
        for name, channel in read_exr(exr).items():
            assert np.isfinite(channel).all(), (exr, name)


@pytest.fixture(scope="module")
def earlier_render(tmp_path_factory, variant):
    """An earlier render folder: a refused call must leave it as it was."""
    from nidar_mi.cli.render import main

    root = tmp_path_factory.mktemp("earlier")
    scene = root / "s.xml"
    scene.write_text(_scene_xml({}, camera=True))
    assert main([str(scene), "-o", str(root / "out"), "-q", "--spp", "1"]) == 0
    return root / "out"


def _render(call, scene_xml: str, argv: list[str], earlier: Path, then=None) -> bool:
    """Render into a copy of ``earlier``; check the contract; ``then(out)`` on success."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        scene = tmp / "scene.xml"
        scene.write_text(scene_xml)
        out = tmp / "out"
        shutil.copytree(earlier, out)
        before = _tree(out)
        status, _, err = call("render", [scene, "-o", out, "-q", "--spp", "1", *argv])
        ok = _check_contract(status, err, out, before)
        if ok:
            _assert_finite_render(out)
            manifest = json.loads((out / "manifest.json").read_text())
            listed = sorted([*manifest["files"], RECORD])
            assert sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()) == listed
            if then is not None:
                then(out)
        return ok


@settings(SETTINGS, max_examples=60)
@given(
    params=st.dictionaries(
        st.sampled_from(sorted(LIDAR_PARAMETERS)),
        st.just(None),
        min_size=1,
        max_size=5,
    ).flatmap(
        lambda keys: st.fixed_dictionaries(
            {k: LIDAR_PARAMETERS[k][1].map(_value_text) for k in keys}
        )
    )
)
def test_lidar_parameters(params, call, earlier_render, variant):
    lidar = {k: (LIDAR_PARAMETERS[k][0], v) for k, v in params.items()}
    lidar.setdefault("horizontal_resolution", ("integer", "36"))
    ok = _render(call, _scene_xml(lidar, camera=False), ["--no-cameras"], earlier_render)
    if ok:
        assert int(lidar["horizontal_resolution"][1]) >= 1


@settings(SETTINGS, max_examples=40)
@given(
    defines=st.dictionaries(
        st.sampled_from(["cols", "width", "height", "spp", "nosuch", ""]),
        st.one_of(st.integers(-3, 64).map(str), _TEXT, st.sampled_from(["1e3", "nan", "-0"])),
        max_size=3,
    )
)
def test_define_values(defines, call, earlier_render, variant):
    argv = []
    for name, value in defines.items():
        argv += ["-D", f"{name}={value}"]

    def film_width(out):
        calib = json.loads((out / "cam" / "calib.json").read_text())
        assert calib["width"] == int(defines.get("width", 8))

    ok = _render(call, _scene_xml({}, camera=True), argv, earlier_render, film_width)
    if ok:
        assert not (set(defines) - {"cols", "width", "height"})  # unknown names are refused


_SEED = st.one_of(
    st.integers(-(2**40), 2**40),
    st.sampled_from([0, 2**32 - 1, 2**32, -1]),
    st.sampled_from(["1.5", "x", "", "0x10", " 3"]),
)


@settings(SETTINGS, max_examples=30)
@given(seed=_SEED)
def test_render_seeds(seed, call, earlier_render, variant):
    def recorded(out):
        manifest = json.loads((out / "manifest.json").read_text())
        assert manifest["seed"] == int(seed) and manifest["seed_source"] == "--seed"

    ok = _render(call, _scene_xml({}, camera=True), ["--seed", str(seed)], earlier_render, recorded)
    legal = isinstance(seed, int) and 0 <= seed < 2**32
    assert ok == legal or (isinstance(seed, str) and seed.strip().isdigit())


@settings(SETTINGS, max_examples=25)
@given(seed=_SEED, command=st.sampled_from(["dataset", "scenegen", "train"]))
def test_seeds_of_the_other_commands(seed, command, call, synthetic_data):
    """Illegal seeds are refused before any work (legal ones are exercised elsewhere)."""
    legal = isinstance(seed, int) and 0 <= seed < 2**32
    if legal or (isinstance(seed, str) and seed.strip().isdigit()):
        return
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        argv = {
            "dataset": ["--scenes", tmp, "-o", out],
            "scenegen": ["--count", "1", "-o", out],
            "train": [synthetic_data, out, "--reduced"],
        }[command]
        status, _, err = call(command, [*argv, "--seed", str(seed)])
        assert not _check_contract(status, err, out, {})
        assert "--seed" in err


# ------------------------------------------------------------------------ assign


_FLOAT = st.one_of(
    st.floats(-50, 50, width=32),
    st.sampled_from([0.0, float("nan"), float("inf"), -float("inf"), 1e30]),
)


@st.composite
def _assign_inputs(draw):
    n = draw(st.integers(0, 40))
    xyz = np.array(
        draw(st.lists(st.tuples(_FLOAT, _FLOAT, _FLOAT), min_size=n, max_size=n)),
        dtype=np.float32,
    ).reshape(n, 3)
    width = draw(st.sampled_from([16, 24, 0, -4]))
    height = draw(st.sampled_from([12, 16, 0]))
    calib = {
        "name": "cam",
        "fx": draw(st.one_of(st.sampled_from([12.0, 0.0, -5.0, float("nan")]), _FLOAT)),
        "fy": draw(st.sampled_from([12.0, 1e-9, float("inf")])),
        "cx": draw(st.sampled_from([7.5, -100.0, float("nan")])),
        "cy": 5.5,
        "width": width,
        "height": height,
        "T_cam_lidar": draw(
            st.sampled_from(
                [
                    [[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]],
                    [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
                    [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
                    [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1]],
                    [[1, 0, 0, float("nan")], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
                    [[1, 0, 0], [0, 1, 0]],
                ]
            )
        ),
    }
    image = (
        draw(st.sampled_from([(12, 16, 3), (12, 16), (12, 16, 4), (16, 24, 3), (3, 5, 3)])),
        draw(st.sampled_from(["u8", "u16"])),
    )
    return xyz, calib, image


@pytest.mark.skipif(
    not (shipped_weights_dir() / "irnet.safetensors").is_file(), reason="no shipped weights"
)
@settings(SETTINGS, max_examples=40)
@given(inputs=_assign_inputs(), fmt=st.sampled_from(["ply", "npz", "bin", "las"]))
def test_assign_inputs(inputs, fmt, call):
    from PIL import Image

    from nidar_mi.io.kitti import write_kitti_bin
    from nidar_mi.io.las import write_las
    from nidar_mi.io.points import write_npz, write_ply

    xyz, calib, (shape, depth) = inputs
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        points = tmp / f"cloud.{fmt}"
        try:
            {
                "ply": lambda: write_ply(points, {"xyz": xyz}),
                "npz": lambda: write_npz(points, {"xyz": xyz}),
                "bin": lambda: write_kitti_bin(points, xyz, np.zeros(len(xyz), np.float32)),
                "las": lambda: write_las(points, {"xyz": xyz}),
            }[fmt]()
        except Exception:  # LAS cannot hold non-finite coordinates: nothing to feed then
            return
        (tmp / "calib.json").write_text(json.dumps({"cameras": [calib]}))
        rng = np.random.default_rng(len(xyz))
        img = rng.integers(0, 256 if depth == "u8" else 65536, shape)
        if depth == "u16" and len(shape) == 2:
            Image.fromarray(img.astype(np.uint16)).save(tmp / "cam.png")
        else:
            Image.fromarray(img.astype(np.uint8)).save(tmp / "cam.png")
        out = tmp / "out"
        argv = ["--points", points, "--calib", tmp / "calib.json", "--image", tmp / "cam.png"]
        status, _, err = call("assign", [*argv, "-o", out])
        if not _check_contract(status, err, out, {}):
            return
        got = read_npz(out / "points.npz")
        finite = np.isfinite(xyz).all(axis=1)
        assert len(got["xyz"]) == finite.sum()
        for key, value in got.items():
            if value.dtype.kind == "f":
                assert np.isfinite(value).all(), key
        assert np.all((got["intensity_nidar"] >= 0) & (got["intensity_nidar"] <= 1))
        ply = read_ply(out / "points.ply")
        assert np.isfinite(ply["intensity_nidar"]).all()


# ------------------------------------------------------------------ outputs that hold inputs


def _inputs_of(command: str, where: Path, synthetic_data) -> tuple[list, Path]:
    """The argv of ``command`` with one input file or folder at ``where`` (``-o`` left out),
    and that input."""
    from nidar_mi.io.images import write_png
    from tests.cli.conftest import TINY_SCENE

    where.mkdir(parents=True)
    image = where / "photo.png"
    write_png(image, np.full((24, 32, 3), 128, np.uint8))
    if command in ("render", "dataset"):
        (where / "tiny.xml").write_text(TINY_SCENE)
        if command == "render":
            return [where / "tiny.xml", "-q"], where / "tiny.xml"
        return ["--scenes", where, "-q"], where
    if command == "train":
        shutil.copytree(synthetic_data, where, dirs_exist_ok=True)
        return [where, "--reduced", "-q"], where
    return {
        "pseudo_nir": ([image, "-q"], image),
        "evaluate": (["--photos", where, "-q"], where),
        "calibrate": ([where, "-q"], where),
        "drive": (["--weights", where, "-q", "--blocks", "2,1"], where),
        "assign": (
            ["--points", where / "c.ply", "--image", image, "--calib", where / "c.yaml"],
            image,
        ),
    }[command]


@settings(SETTINGS, max_examples=40)
@given(
    command=st.sampled_from(
        ["render", "dataset", "assign", "pseudo_nir", "evaluate", "train", "calibrate", "drive"]
    ),
    up=st.integers(0, 2),
    overwrite=st.booleans(),
)
def test_outputs_never_hold_an_input(command, up, overwrite, call, synthetic_data):
    """``-o`` equal to an input, or a folder above one, is refused with ``--overwrite`` or not,
    before anything is read or written: every file stays as it was."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        argv, given_input = _inputs_of(command, root / "a" / "b", synthetic_data)
        out = given_input
        for _ in range(up):
            out = out.parent
        if command == "train":
            argv = [argv[0], out, *argv[1:]]
        else:
            argv = [*argv, "-o", out]
        before = _tree(root / "a")
        status, _, err = call(command, [*argv] + ["--overwrite"] * overwrite)
        assert not _check_contract(status, err, root / "a", before)
        assert ("is the input" if out == given_input else "holds the input") in err, err
        assert _tree(root / "a") == before


# ------------------------------------------------------------------ options that interplay

_DRIVE_VALUES = {
    "--blocks": st.sampled_from(["2,1", "2,2", "1,1", "x"]),
    "--frames": st.sampled_from(["2", "7", "1", "-3"]),
    "--rate": st.sampled_from(["10", "0", "-1", "inf", "nan", "1e-3"]),
    "--speed": st.sampled_from(["5", "0", "inf", "-inf", "nan", "1e9"]),
}


@settings(SETTINGS, max_examples=40)
@given(
    kind=st.sampled_from([None, "urban", "vegetated", "city", "suburb"]),
    options=st.dictionaries(st.sampled_from(sorted(_DRIVE_VALUES)), st.none(), max_size=4).flatmap(
        lambda d: st.fixed_dictionaries({k: _DRIVE_VALUES[k] for k in d})
    ),
)
def test_scenegen_drive_options(kind, options, call):
    """The drive options act with a city or suburb, are refused with any other kind, and a
    value out of range (a rate or speed that is not finite and positive) is refused before
    anything is written."""
    legal = kind in ("city", "suburb") or not options
    if kind in ("city", "suburb"):
        blocks = options.get("--blocks", "4,3").split(",")
        legal = (
            blocks != ["x"]
            and int(blocks[0]) >= 2
            and int(options.get("--frames", "500")) >= 2
            and all(0 < float(options.get(k, "10")) < math.inf for k in ("--rate", "--speed"))
        )
        if legal:
            return  # generating a city is exercised in tests/scenegen
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "gen"
        argv = ["--count", "1", "-o", out, "-q"] + (["--kind", kind] if kind else [])
        argv += [a for kv in options.items() for a in kv]
        status, _, err = call("scenegen", argv)
        assert _check_contract(status, err, out, {}) == legal, err
        if not legal:
            assert not out.exists()
            assert any(flag in err for flag in options), err


@settings(SETTINGS, max_examples=30)
@given(
    modes=st.dictionaries(
        st.sampled_from(["points", "kitti", "frame", "lidar"]), st.none(), max_size=4
    ),
)
def test_assign_input_modes(modes, call, assign_inputs):
    """``--points --image --calib`` and ``--kitti --frame`` exclude each other; ``--frame``
    needs ``--kitti``, ``--lidar`` needs ``--calib``."""
    argv = list(assign_inputs) if "points" in modes else []
    if "kitti" in modes:
        argv += ["--kitti", Path(assign_inputs[1]).parent]
    argv += ["--frame", "000000"] * ("frame" in modes) + ["--lidar", "l"] * ("lidar" in modes)
    kitti_ok = set(modes) == {"kitti", "frame"}
    points_ok = "points" in modes and not ({"kitti", "frame"} & set(modes))
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        status, _, err = call("assign", [*argv, "-o", out])
        if points_ok and "lidar" not in modes:
            assert _check_contract(status, err, out, {}), err
            return
        assert not _check_contract(status, err, out, {})
        if not kitti_ok and not points_ok:  # the mode itself is refused, not a file
            want = ("--kitti", "--frame", "--points", "--lidar")
            assert any(f in err for f in want), err


@settings(SETTINGS, max_examples=30)
@given(
    form=st.sampled_from(["gbm", "range_ring", "distance_quantile"]),
    incidence=st.sampled_from([None, "--no-incidence"]),
    no_geometry=st.booleans(),
)
def test_calibrate_form_options(form, incidence, no_geometry, call):
    """``--no-incidence`` and ``--no-geometry`` act with the gbm form only (``--no-geometry``
    also needs the incidence); otherwise refused before any scan is read."""
    reads_incidence = form == "gbm" and incidence != "--no-incidence"
    legal = (incidence is None or form == "gbm") and (not no_geometry or reads_incidence)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "p.json"
        argv = [Path(tmp) / "no_scans", "-o", out, "--form", form, "-q"]
        argv += [incidence] * bool(incidence) + ["--no-geometry"] * no_geometry
        status, _, err = call("calibrate", argv)
        assert not _check_contract(status, err, Path(tmp) / "x", {})  # no scans: refused anyway
        assert not out.exists()
        option_refused = "needs --form gbm" in err or "--no-geometry needs" in err
        assert option_refused == (not legal), err


@settings(SETTINGS, max_examples=30)
@given(split=st.lists(_small(-1, 2), min_size=1, max_size=4))
def test_dataset_split_fractions(split, call):
    """``--split``: three fractions in [0, 1] that sum to 1, or one refusal naming it."""
    text = ",".join(map(str, split))
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    legal = len(values) == 3 and all(0 <= v <= 1 for v in values) and abs(sum(values) - 1) <= 1e-6
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "data"
        status, _, err = call("dataset", ["--scenes", tmp, "-o", out, "--split", text, "-q"])
        assert not _check_contract(status, err, out, {})  # no scene there: refused anyway
        assert ("--split" in err) == (not legal), err
        assert not out.exists()


@settings(SETTINGS, max_examples=20)
@given(figures=st.integers(-5, 5))
def test_evaluate_figures(figures, call):
    """``--figures`` below 0 is refused before anything else is looked at."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        argv = ["--photos", tmp, "--figures", str(figures), "-o", out, "-q"]
        status, _, err = call("evaluate", argv)
        assert not _check_contract(status, err, out, {})  # no photos there: refused anyway
        assert ("--figures" in err) == (figures < 0), err
        assert not out.exists()
