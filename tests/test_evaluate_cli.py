"""``python -m nidar_mi.evaluate``: user errors are one line, exit 2, and write nothing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from nidar_mi.cli.evaluate import main
from nidar_mi.io.ownership import RECORD


def _dataset(root, scenes):
    root.mkdir()
    (root / "meta.json").write_text(json.dumps({"intensity_scale": 1.0, "scenes": scenes}))
    return root


@pytest.mark.parametrize(
    "case, message",
    [
        ("no_data", "meta.json"),
        ("no_test", "has no 'test' scenes"),
        ("not_rendered", "scene b is not rendered"),
    ],
)
def test_user_errors(tmp_path, capsys, case, message):
    data = tmp_path / "data"
    if case == "no_test":
        _dataset(data, {"train": ["a"], "test": []})
    elif case == "not_rendered":
        _dataset(data, {"train": ["a"], "test": ["b"]})
    out = tmp_path / "out"
    assert main(["--data", str(data), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err
    assert not out.exists()


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory, variant):
    """Three hand-made scenes rendered tiny (one per split) and a reduced model trained on them."""
    import dataclasses
    import shutil
    from pathlib import Path

    from nidar_mi.datasets.profile_fitting import fit_split_calibration
    from nidar_mi.nidar.config import TrainConfig
    from nidar_mi.nidar.pipeline import NidarModel
    from nidar_mi.nidar.training import train
    from nidar_mi.render_dataset import build_dataset

    root = tmp_path_factory.mktemp("e2e")
    repo = Path(__file__).resolve().parents[1]
    (root / "scenes").mkdir()
    for name in ("street", "park", "warehouse"):
        shutil.copy(repo / "scenes" / f"{name}.xml", root / "scenes")
    params = {"width": "64", "height": "48", "cols": "256"}
    build_dataset(
        str(root / "scenes"),
        str(root / "data"),
        seed=0,
        spp=1,
        params=params,
        progress=False,
        fractions=(1, 1, 1),
    )
    red = TrainConfig.reduced()
    one = dataclasses.replace(red.stn_optim, batch_size=1)  # a single training frame
    cfg = dataclasses.replace(red, device="cpu", stn_optim=one, irnet_optim=one)
    train(cfg, root / "data", root / "run", progress=False)
    model = NidarModel.load(root / "run", device="cpu")
    fit_split_calibration(model, root / "data").mapping.save_json(root / "run" / "calibration.json")
    return root


def test_end_to_end_tables(tiny_run, tmp_path):
    import csv

    from nidar_mi.eval.rendered import METHODS

    out = tmp_path / "out"
    argv = ["--data", str(tiny_run / "data"), "--weights", str(tiny_run / "run"), "-o", str(out)]
    argv += ["--kitti", str(tmp_path / "no_kitti"), "--figures", "1", "-q"]
    assert main(argv) == 0
    payload = json.loads((out / "results.json").read_text())
    (test_scene,) = payload["groups"]["generated"]["scenes"]
    rows = payload["groups"]["generated"]["rows"]
    assert [r["method"] for r in rows] == list(METHODS)  # one frame, every method (a)-(g)
    assert all(r["scene"] == test_scene and r["n_points"] > 0 for r in rows)
    carla = next(r for r in rows if r["method"] == "carla")
    mean = next(r for r in payload["groups"]["generated"]["mean"] if r["method"] == "carla")
    assert mean["map_ssim"] == carla["map_ssim"]  # one frame: the mean is that frame
    assert "no KITTI frames" in payload["kitti"]["skipped"]
    with open(out / "results.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 2 * len(METHODS)  # the frame rows and the mean rows
    assert float(table[3]["map_rmse"]) == pytest.approx(carla["map_rmse"])
    md = (out / "results.md").read_text()
    assert "## Held-out generated scenes" in md and "Skipped: no KITTI frames" in md
    assert {p.name for p in (out / "figures").iterdir()} == {
        f"generated_{test_scene}_cam_front_maps.png",
        "generated_scatter.png",
    }


def test_lpips_without_lpips_is_an_error(tiny_run, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(
        "nidar_mi.eval.metrics.lpips_unavailable_reason", lambda: "the lpips package is absent"
    )
    out = tmp_path / "out"
    argv = ["--data", str(tiny_run / "data"), "--weights", str(tiny_run / "run"), "-o", str(out)]
    assert main(argv + ["--lpips", "--no-twin", "-q"]) == 2
    err = capsys.readouterr().err
    assert err == "error: --lpips: LPIPS is unavailable: the lpips package is absent\n"
    assert not out.exists()


def test_out_is_published_whole_and_caches_stay_outside(tiny_run, tmp_path, capsys):
    """Hand-made scenes render into the cache (reused by a rerun), never into OUT; a rerun
    replaces OUT whole; a file evaluate did not write is never removed."""
    import os
    import shutil

    scenes = tmp_path / "handmade"
    scenes.mkdir()
    shutil.copy(Path(__file__).resolve().parents[1] / "scenes" / "park.xml", scenes)
    out, cache = tmp_path / "out", tmp_path / "cache"
    argv = ["--data", str(tiny_run / "data"), "--weights", str(tiny_run / "run"), "-o", str(out)]
    argv += ["--scenes", str(scenes), "--cache", str(cache), "--no-twin", "--figures", "0", "-q"]
    assert main(argv) == 0, capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == [
        RECORD,
        "figures",
        "results.csv",
        "results.json",
        "results.md",
    ]
    manifest = cache / "renders" / "park" / "manifest.json"
    stamp = os.path.getmtime(manifest)
    (out / "results.md").write_text("an earlier run's")
    assert main(argv) == 0
    assert os.path.getmtime(manifest) == stamp  # the cached render was reused
    assert (out / "results.md").read_text() != "an earlier run's"  # OUT replaced whole
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    (out / "figures" / "mine.png").write_bytes(b"x")  # a file evaluate did not write: kept
    capsys.readouterr()
    assert main([*argv, "--overwrite"]) == 2
    assert (
        "holds 1 file(s) that 'evaluate' did not write (figures/mine.png)"
        in capsys.readouterr().err
    )
    assert (out / "figures" / "mine.png").read_bytes() == b"x"


def test_late_failure_leaves_no_output(tiny_run, tmp_path, capsys):
    """A broken KITTI frame fails after the figures were drawn: nothing is published."""
    kitti = tmp_path / "kitti"
    for sub in ("velodyne", "image_2", "calib"):
        (kitti / sub).mkdir(parents=True)
    (kitti / "velodyne" / "000000.bin").write_bytes(b"")
    (kitti / "image_2" / "000000.png").write_bytes(b"")
    (kitti / "calib" / "000000.txt").write_text("P2: not numbers\n")
    out = tmp_path / "out"
    argv = ["--data", str(tiny_run / "data"), "--weights", str(tiny_run / "run"), "-o", str(out)]
    assert main(argv + ["--kitti", str(kitti), "--no-twin", "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1
    assert not out.exists()


def test_nothing_to_evaluate_and_flags_that_need_data(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["-o", str(out), "-q"]) == 2
    assert "nothing to evaluate" in capsys.readouterr().err
    assert main(["--kitti", str(tmp_path), "--ablation", "-o", str(out), "-q"]) == 2
    assert "--ablation needs --data" in capsys.readouterr().err
    assert not out.exists()


def test_real_data_tables(tmp_path):
    """KITTI leave-one-out and the photo table on synthetic stand-ins, shipped weights."""
    import numpy as np

    from nidar_mi.io.images import write_png
    from tests.helpers.synthetic_kitti import make_kitti

    kitti = make_kitti(tmp_path / "kitti", frames=3)
    photos = tmp_path / "rgbnir"
    rng = np.random.default_rng(0)
    for cat in ("a", "b", "c"):
        (photos / cat).mkdir(parents=True)
        for i in range(5):
            write_png(
                photos / cat / f"{i:04d}_rgb.png", rng.integers(0, 256, (24, 32, 3), np.uint8)
            )
            write_png(photos / cat / f"{i:04d}_nir.png", rng.integers(0, 256, (24, 32), np.uint8))
    out = tmp_path / "out"
    assert main(["--kitti", str(kitti), "--photos", str(photos), "-o", str(out), "-q"]) == 0
    payload = json.loads((out / "results.json").read_text())
    loo = payload["kitti"]
    assert loo["folds"] == ["kitti__000000", "kitti__000001", "kitti__000002"]
    assert loo["train_frames"] == 2
    keys = [m["method"] for m in loo["mean"]]
    for needed in (
        "lin9",
        "linnir_dq",
        "carla",
        "nidar_R_distance_quantile",
        "nidar_R_range_ring",
        "nidar_R_gbm",
        "geometry_gbm",
        "lum_gbm_free",
        "geometry_gbm_inc",
        "linnir_gbm_inc",
        "nidar_R_gbm_inc",
        "nidar_pseudo_nir_gbm",
        "nidar_pseudo_nir_gbm_inc",
    ):
        assert needed in keys
    assert len(loo["rows"]) == 3 * len(keys)
    # the incidence rows read something the plain rows do not: their predictions differ
    by = {(r["frame"], r["method"]): r for r in loo["rows"]}
    assert any(
        by[(f, "geometry_gbm_inc")]["rmse"] != by[(f, "geometry_gbm")]["rmse"] for f in loo["folds"]
    )
    # the pseudo-NIR rows read the STN's map, not R's
    assert any(
        by[(f, "nidar_pseudo_nir_gbm")]["rmse"] != by[(f, "nidar_R_gbm")]["rmse"]
        for f in loo["folds"]
    )
    assert all(np.isfinite(r["spearman"]) and 0 <= r["rmse"] <= 1 for r in loo["rows"])
    ph = payload["photos"]
    assert {m["method"] for m in ph["mean"]} == {"luminance", "linear", "stn"}
    assert len(ph["images"]) == 3 and all(-1 <= r["r"] <= 1 for r in ph["rows"])
    md = (out / "results.md").read_text()
    assert (
        "## Real data: KITTI, leave one frame out" in md
        and "## Pseudo-NIR against real NIR photos" in md
    )
    assert "; data: none;" in md and "None" not in md  # no --data: said so, not `None`
    assert not (out / "figures").exists()  # no figure of real data


def test_the_command_line_becomes_evaluate_options():
    from nidar_mi.cli.evaluate import _parser, options

    argv = ["--data", "d", "--kitti", "k1", "--kitti", "k2", "--no-twin", "-q", "-o", "o"]
    opts = options(_parser().parse_args(argv), "python -m nidar_mi.evaluate ...")
    assert (opts.data, opts.kitti, opts.out) == ("d", ("k1", "k2"), "o")
    assert not opts.twin and not opts.progress and not opts.scans_scenes
    assert opts.command == "python -m nidar_mi.evaluate ..."
    opts = options(_parser().parse_args(["--data", "d", "-o", "o"]), "")
    assert opts.twin and opts.scans_scenes and opts.figures == 3
    assert not opts.progress  # stderr is not a terminal here: no bars unless asked for
    assert options(_parser().parse_args(["--data", "d", "-o", "o", "--progress"]), "").progress


def test_the_library_names_parameters_and_the_command_flags(tmp_path, capsys):
    from nidar_mi.errors import NidarError
    from nidar_mi.eval.suite import EvaluateOptions, run_evaluation

    with pytest.raises(NidarError, match="`heldout_materials` needs `data`"):
        run_evaluation(
            EvaluateOptions(out=str(tmp_path / "o"), photos="p", heldout_materials=str(tmp_path))
        )
    argv = ["--photos", "p", "--heldout-materials", str(tmp_path), "-o", str(tmp_path / "o")]
    assert main(argv) == 2
    assert "error: --heldout-materials needs --data" in capsys.readouterr().err
