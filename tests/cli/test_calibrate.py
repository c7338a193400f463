"""``python -m nidar_mi.calibrate``: profiles from KITTI-layout and generic scan folders."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from nidar_mi.cli.calibrate import main
from nidar_mi.profiles import load_profile
from tests.helpers.synthetic_kitti import make_kitti


def test_kitti_folder_to_profile(tmp_path, capsys):
    kitti = make_kitti(tmp_path / "drive", frames=2)
    out = tmp_path / "hdl.json"
    argv = [str(kitti), "-o", str(out), "--sensor", "my HDL-64E", "--form", "gbm", "--no-incidence"]
    assert main(argv) == 0
    p = load_profile(out)
    assert (p.name, p.form, p.input, p.sensor) == ("hdl", "gbm", "nidar:R", "my HDL-64E")
    assert p.provenance["frames"] == 2 and p.provenance["rings"] == "given"
    assert "python -m nidar_mi.calibrate" in p.provenance["command"]
    assert "gbm profile 'hdl' fitted on 2 frames" in capsys.readouterr().out
    assert not p.uses_incidence
    # the profile maps into [0, 1] and is monotone in the value at a fixed range and elevation
    v = np.linspace(0, 1, 50)
    y = p(v, np.full(50, 12.0), elevation_deg=np.full(50, -8.0))
    assert np.all(np.diff(y) >= 0) and 0 <= y.min() and y.max() <= 1
    assert main([str(kitti), "-o", str(out), "--form", "range_ring", "-q"]) == 0
    p = load_profile(out)
    y = p(v, np.full(50, 12.0), ring=np.full(50, 30))
    assert p.form == "range_ring" and np.all(np.diff(y) >= 0)
    # an earlier profile is replaced; another file is not, unless --overwrite
    assert main([str(kitti), "-o", str(out), "--form", "distance_quantile", "-q"]) == 0
    assert load_profile(out).form == "distance_quantile"
    other = tmp_path / "notes.json"
    other.write_text('{"a": 1}')
    assert main([str(kitti), "-o", str(other), "-q", "--form", "gbm"]) == 2
    assert "not a sensor profile" in capsys.readouterr().err and json.loads(other.read_text()) == {
        "a": 1
    }
    assert main([str(kitti), "-o", str(other), "-q", "--overwrite", "--form", "gbm"]) == 0


def test_incidence_aware_profile(tmp_path, capsys):
    """The gbm form reads |cos θ| (estimated on the scans' points) by default, as the former
    kitti-hdl64e did, and is non-decreasing in it; --no-incidence only with the gbm or
    physical form; --incidence is no option."""
    kitti = make_kitti(tmp_path / "drive", frames=2)
    out = tmp_path / "inc.json"
    assert main([str(kitti), "-o", str(out), "--form", "gbm"]) == 0
    assert "(with incidence) fitted on 2 frames" in capsys.readouterr().out
    p = load_profile(out)
    assert p.uses_incidence and p.mapping.features[-1] == "cos_incidence"
    c = np.linspace(0, 1, 50)
    y = p(np.full(50, 0.5), np.full(50, 12.0), elevation_deg=np.full(50, -8.0), cos_incidence=c)
    assert np.all(np.diff(y) >= 0)
    assert main([str(kitti), "-o", str(out), "--no-incidence", "--form", "range_ring", "-q"]) == 2
    assert "--no-incidence needs --form gbm" in capsys.readouterr().err
    assert load_profile(out).uses_incidence  # the earlier file is untouched
    # --no-geometry: the value and the incidence only; range and elevation are not read
    assert main([str(kitti), "-o", str(out), "--form", "gbm", "--no-geometry"]) == 0
    assert "(value and incidence only) fitted on 2 frames" in capsys.readouterr().out
    p = load_profile(out)
    assert p.mapping.features == ("v", "cos_incidence") and not p.mapping.uses_geometry
    v = np.linspace(0.1, 0.9, 9)
    np.testing.assert_array_equal(
        p(v, np.full(9, 5.0), cos_incidence=np.full(9, 0.7)),
        p(v, np.full(9, 50.0), elevation_deg=np.full(9, -20.0), cos_incidence=np.full(9, 0.7)),
    )
    for bad in (["--no-incidence"], ["--form", "range_ring"]):  # the last --form wins
        assert main([str(kitti), "-o", str(out), "--form", "gbm", "--no-geometry", "-q", *bad]) == 2
        assert "--no-geometry needs the incidence" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main([str(kitti), "-o", str(out), "--incidence", "-q"])
    assert exc.value.code == 2 and "unrecognized arguments: --incidence" in capsys.readouterr().err
    assert not load_profile(out).mapping.uses_geometry  # untouched


def test_generic_folder_with_rings_and_0_255_intensity(tmp_path, capsys):
    def inten(rng_m, rng):
        return np.round(255 * np.clip(np.exp(-rng_m / 20) + rng.normal(0, 0.02, len(rng_m)), 0, 1))

    root = _generic_folder(tmp_path / "scans", inten, with_rings=True)
    out = tmp_path / "p.json"
    assert main([str(root), "-o", str(out), "-q", "--form", "range_ring"]) == 0
    assert "dividing them by 255" in capsys.readouterr().err
    p = load_profile(out)
    assert p.provenance["rings"] == "given" and len(p.mapping.gains) == 32
    # the sensor's response falls with range: the profile learnt it from the scans
    near, far = p([0.5, 0.5], [4.0, 24.0], ring=[20, 20])
    assert near > far


@pytest.mark.parametrize(
    "args, message",
    [
        (["/nonexistent"], "no such folder"),
        (["{tmp}"], "not a scan folder"),
    ],
)
def test_bad_input(tmp_path, capsys, args, message):
    out = tmp_path / "p.json"
    assert main([a.format(tmp=tmp_path) for a in args] + ["-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and message in err and err.count("\n") == 1
    assert not out.exists()


def _generic_folder(root, intensity, with_rings=False):
    """A generic scan folder of two frames whose intensities are ``intensity(rng_m, rng)``
    (and a ``ring`` column if ``with_rings``)."""
    from nidar_mi.io.images import write_png
    from nidar_mi.io.points import write_npz
    from tests.helpers.synthetic_kitti import kitti_order_scan

    (root / "points").mkdir(parents=True)
    (root / "images").mkdir()
    cam = {
        "name": "front",
        "width": 320,
        "height": 120,
        "K": [[160.0, 0, 159.5], [0, 160.0, 59.5], [0, 0, 1]],
        "T_cam_lidar": [[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]],
    }
    (root / "calib.yaml").write_text(yaml.safe_dump({"cameras": [cam]}))
    xyz, ring, rng_m = kitti_order_scan(cols=360, front_only=True, rings=32)
    rng = np.random.default_rng(0)
    for k in range(2):
        cols = {"xyz": xyz, "intensity": intensity(rng_m, rng).astype(np.float32)}
        if with_rings:
            cols["ring"] = ring.astype(np.uint16)
        write_npz(root / "points" / f"{k:04d}.npz", cols)
        write_png(root / "images" / f"{k:04d}.png", rng.integers(0, 256, (120, 320, 3), np.uint8))
    return root


def test_non_finite_intensities_are_left_out_with_a_count(tmp_path, capsys):
    def inten(rng_m, rng):
        v = np.clip(np.exp(-rng_m / 20) + rng.normal(0, 0.02, len(rng_m)), 0, 1)
        v[::10] = np.nan  # every tenth return
        return v

    root = _generic_folder(tmp_path / "scans", inten)
    out = tmp_path / "p.json"
    assert main([str(root), "-o", str(out), "--form", "distance_quantile", "-q"]) == 0
    err = capsys.readouterr().err
    n = len(np.load(root / "points" / "0000.npz")["xyz"])
    assert f"{len(range(0, n, 10))} of {n} points with a NaN" in err
    p = load_profile(out)
    assert np.isfinite(p([0.2, 0.8], [5.0, 5.0])).all()


def test_negative_intensities_are_a_user_error(tmp_path, capsys):
    root = _generic_folder(tmp_path / "scans", lambda rng_m, rng: -1000.0 + 0 * rng_m)
    out = tmp_path / "p.json"
    assert main([str(root), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and "negative intensities" in err and err.count("\n") == 1
    assert not out.exists()


def test_a_branch_the_profile_was_not_fitted_on_is_refused(tmp_path):
    from nidar_mi.cloud_intensity import assign_intensity
    from nidar_mi.errors import NidarError

    root = _generic_folder(
        tmp_path / "scans", lambda rng_m, rng: np.clip(np.exp(-rng_m / 20), 0, 1)
    )
    out = tmp_path / "p.json"
    args = [str(root), "-o", str(out), "--form", "distance_quantile", "--branch", "I_hat", "-q"]
    assert main(args) == 0
    with pytest.raises(NidarError, match="maps the I_hat branch"):
        assign_intensity(np.zeros((1, 3)), [], [], profile=str(out), branch="R")


def test_synopsis_and_help_show_overwrite_and_the_incidence_default(capsys):
    """The module synopsis, the README's and ``--help`` all show ``--overwrite`` and that a
    ``gbm`` profile reads the incidence by default."""
    import re

    import nidar_mi.cli.calibrate as cli

    with pytest.raises(SystemExit):
        cli.main(["--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--overwrite" in help_text and "(read by default)" in help_text
    readme = open(Path(cli.__file__).parents[2] / "README.md", encoding="utf-8").read()
    synopsis = re.search(
        r"python -m nidar_mi\.calibrate SCANS\.\.\. -o profile\.json \[.*?```", readme, re.S
    ).group(0)
    for text in (cli.__doc__, synopsis):
        assert "[--overwrite]" in text and "--no-incidence" in text
    assert "reads the incidence by default" in cli.__doc__ + readme


def test_max_frames_and_the_physical_form(tmp_path, capsys):
    """--max-frames K fits on K frames evenly spaced over the scans; --form physical fits the
    generic profiles' closed form."""
    from nidar_mi.datasets.profile_fitting import select_frames
    from nidar_mi.errors import NidarError

    assert select_frames(list("abcdefg"), 3) == ["a", "d", "g"]
    assert select_frames(list("ab"), 5) == ["a", "b"] and select_frames(list("ab"), None) == [
        "a",
        "b",
    ]
    with pytest.raises(NidarError, match="`max_frames` must be at least 1"):
        select_frames(list("ab"), 0)
    kitti = make_kitti(tmp_path / "drive", frames=3)
    out = tmp_path / "k1.json"
    assert main([str(kitti), "-o", str(out), "--max-frames", "1"]) == 0
    assert "fitted on 1 frames" in capsys.readouterr().out
    assert load_profile(out).provenance["frames"] == 1
    assert main([str(kitti), "-o", str(out), "--max-frames", "0", "-q"]) == 2
    assert "--max-frames must be at least 1" in capsys.readouterr().err
    assert main([str(kitti), "-o", str(out), "--form", "physical"]) == 0
    assert "physical profile 'k1' (with incidence) fitted on 3 frames" in capsys.readouterr().out
    p = load_profile(out)
    assert p.form == "physical" and p.uses_incidence and p.mapping.gain > 0


def _simulator_folder(root, *, render_manifest: bool):
    """A generic scan folder of two frames of the simulator's own points (its schema, and
    intensities up to 1.6 as a raw-mode scan has near by); with ``render_manifest`` each cloud
    is a link to ``points.npz`` of a render folder of a gain-0.5 compensated LiDAR."""
    from nidar_mi.io.points import write_npz

    def inten(rng_m, rng):
        return 2.0 * np.exp(-rng_m / 20)

    root = _generic_folder(root, inten)
    for k in range(2):
        path = root / "points" / f"{k:04d}.npz"
        cloud = dict(np.load(path))
        n = len(cloud["xyz"])
        cloud |= {"reflectance": np.full(n, 0.5, np.float32), "return_index": np.zeros(n, np.uint8)}
        cloud["material_names"] = np.asarray(["asphalt"], dtype=np.str_)
        if not render_manifest:
            write_npz(path, cloud)
            continue
        render = root.parent / f"render_{k}"
        (render / "lidar_top").mkdir(parents=True)
        write_npz(render / "lidar_top" / "points.npz", cloud)
        params = {"gain": 0.5, "intensity_mode": "compensated"}
        manifest = {"lidars": {"lidar_top": {"parameters": params}}}
        (render / "manifest.json").write_text(json.dumps(manifest))
        path.unlink()
        path.symlink_to(render / "lidar_top" / "points.npz")
    return root


@pytest.mark.parametrize("render_manifest, scale", [(False, 1.0), (True, 0.5)])
def test_simulator_clouds_are_never_taken_for_8_bit(tmp_path, render_manifest, scale):
    """The simulator's points (by their render folder's manifest, or their schema) are divided
    by the sensor's full scale, never by 255, and without the 8-bit warning."""
    import warnings

    from nidar_mi.datasets.scans import frames_from_generic, simulator_scale

    root = _simulator_folder(tmp_path / "scans", render_manifest=render_manifest)
    cloud = dict(np.load(root / "points" / "0000.npz"))
    assert simulator_scale(root / "points" / "0000.npz", cloud) == scale
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frames = frames_from_generic(root)
    for f in frames:
        raw = 2.0 * np.exp(-np.linalg.norm(f.xyz, axis=1) / 20)
        np.testing.assert_allclose(f.intensity, np.clip(raw / scale, 0, 1), rtol=1e-5, atol=1e-6)
        assert f.intensity.max() == 1.0
    # another tool's cloud is not the simulator's
    assert simulator_scale(tmp_path / "other.npz", {"xyz": cloud["xyz"]}) is None


def test_calibrate_on_the_simulators_points_does_not_rescale(tmp_path, capsys):
    root = _simulator_folder(tmp_path / "scans", render_manifest=False)
    out = tmp_path / "sim.json"
    assert main([str(root), "-o", str(out), "--form", "distance_quantile", "-q"]) == 0
    err = capsys.readouterr().err
    assert "255" not in err, err
    assert load_profile(out).provenance["frames"] == 2


def _striped_folder(root, seed: int):
    """A generic scan folder of two frames whose images are vertical stripes 16 pixels wide,
    each of a random grey, and whose intensities are the grey of the stripe each return
    projects into (plus noise): what the image says at the pixel, and nothing the geometry
    knows."""
    from nidar_mi.geometry import project
    from nidar_mi.io.calib import load_calib
    from nidar_mi.io.images import write_png
    from nidar_mi.io.points import write_npz
    from tests.helpers.synthetic_kitti import kitti_order_scan

    root = _generic_folder(root, lambda r, g: np.zeros(len(r)), with_rings=True)
    (cam,) = load_calib(root / "calib.yaml")
    xyz, ring, _ = kitti_order_scan(cols=360, front_only=True, rings=32)
    u = project(xyz, cam)[0][:, 0]
    rng = np.random.default_rng(seed)
    for k in range(2):
        grey = rng.integers(0, 256, 20)
        img = np.repeat(np.repeat(grey, 16)[None, :, None], 120, axis=0).repeat(3, axis=2)
        write_png(root / "images" / f"{k:04d}.png", img.astype(np.uint8))
        stripe = np.clip(np.nan_to_num(np.rint(u), nan=0).astype(int) // 16, 0, 19)
        inten = np.clip(grey[stripe] / 255.0 + rng.normal(0, 0.02, len(xyz)), 0, 1)
        cols = {"xyz": xyz, "intensity": inten.astype(np.float32), "ring": ring.astype(np.uint16)}
        write_npz(root / "points" / f"{k:04d}.npz", cols)
    return root


def test_a_context_profile_reads_the_image_where_the_intensity_comes_from(tmp_path, capsys):
    """Fitted on two frames, a context profile ranks the returns of frames of other images
    by the image at their pixel; without the image inputs it cannot. It refuses to run
    without the image."""
    from nidar_mi.datasets.scans import load_scans
    from nidar_mi.errors import NidarError
    from nidar_mi.eval.metrics import spearman
    from nidar_mi.nidar.pipeline import NidarModel

    train = _striped_folder(tmp_path / "train", seed=0)
    test = load_scans([_striped_folder(tmp_path / "test", seed=1)], progress=False)[0]
    model = NidarModel.load(device="cpu")
    rho, profiles = {}, {}
    for inputs in ("return,ring,geometry,image,nidar", "return,ring,geometry"):
        out = tmp_path / f"{len(inputs)}.json"
        assert main([str(train), "-o", str(out), "--form", "context", "--inputs", inputs]) == 0
        assert "context profile" in capsys.readouterr().out
        p = profiles[inputs] = load_profile(out)
        res = model.point_intensity(test.xyz, test.cameras, test.images, profile=p, ring=test.ring)
        assert res.observed.all()  # the scan's returns are the visible ones
        rho[p.needs_image] = spearman(res.intensity, test.intensity)
    assert rho[True] > 0.95 and rho[False] < 0.45  # geometry: the training stripes by azimuth
    maps = [model.predict_image(im) for im in test.images]
    p = profiles["return,ring,geometry,image,nidar"]
    with pytest.raises(NidarError, match="reads the camera image"):
        model.point_intensity(test.xyz, test.cameras, [None], maps=maps, profile=p)
    x = str(tmp_path / "x.json")
    assert main([str(train), "-o", x, "--form", "gbm", "--inputs", "image", "-q"]) == 2
    assert "--inputs needs --form context" in capsys.readouterr().err


def test_balance_weighs_each_folder_alike_or_each_frame(tmp_path, capsys):
    """Two recordings that disagree on the same geometry: six frames of a folder read 0.2, two
    of another 0.8. Least squares on the intensity (``--target intensity``) gives their weighted
    mean: 0.5 with each folder weighing the same (the default), (6·0.2 + 2·0.8) / 8 = 0.35 with
    each frame. The trees' default target is the blend of the intensity and its rank."""
    import shutil

    from nidar_mi.datasets.scans import load_scans
    from nidar_mi.profiles.inputs import return_inputs

    a = _generic_folder(tmp_path / "a", lambda r, g: np.full(len(r), 0.2), with_rings=True)
    b = _generic_folder(tmp_path / "b", lambda r, g: np.full(len(r), 0.8), with_rings=True)
    for k in (2, 3, 4, 5):
        shutil.copy(a / "points" / "0000.npz", a / "points" / f"{k:04d}.npz")
        shutil.copy(a / "images" / "0000.png", a / "images" / f"{k:04d}.png")
    scan = load_scans([b], progress=False)[0]
    for balance, want in ((None, 0.5), ("frame", 0.35)):
        out = tmp_path / f"{balance}.json"
        argv = [str(a), str(b), "-o", str(out), "--form", "context", "--inputs", "return", "-q"]
        argv += ["--target", "intensity"]
        assert main(argv + (["--balance", balance] if balance else [])) == 0
        p = load_profile(out)
        assert p.mapping.params["balance"] == (balance or "group")
        assert p.mapping.target == "intensity"
        assert p.mapping.params["groups"] == 2 and p.provenance["frames"] == 8
        ctx = return_inputs(scan.xyz, scan.ring)
        pred = p(np.zeros(len(scan.xyz)), scan.range_m, context=ctx)
        assert np.median(pred) == pytest.approx(want, abs=0.02), balance
    assert (
        main([str(a), "-o", str(tmp_path / "g.json"), "--form", "gbm", "--balance", "frame"]) == 2
    )
    assert "--balance needs --form context" in capsys.readouterr().err
    assert main([str(a), "-o", str(tmp_path / "g.json"), "--form", "gbm", "--target", "rank"]) == 2
    assert "--target needs --form context" in capsys.readouterr().err
    out = tmp_path / "default.json"
    assert main([str(a), str(b), "-o", str(out), "--inputs", "return", "-q"]) == 0
    assert load_profile(out).mapping.target == "blend"
