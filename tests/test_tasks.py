"""nidar_mi.tasks: serial and Ray runs of the same job agree, failures are named, the job resumes.

The Ray tests share one local runtime (module fixture; started once, shut down at the end) and
kill real worker processes. Task functions are defined here and pickled by value to the workers.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import warnings
from functools import partial

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.tasks import RAY_MISSING, Task, TasksFailed, run_tasks

pytestmark = pytest.mark.timeout(300)  # a Ray test that hangs fails instead

# --------------------------------------------------------------------------- task functions


def _noise(seed: int, path: str) -> float:
    """Write 1000 seeded normal draws to ``path``; return their sum."""
    from nidar_mi.io.atomic import atomic_path

    x = np.random.default_rng(seed).normal(size=1000)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.save(f, x)
    return float(x.sum())


def _fail(kind: str) -> None:
    if kind == "nidar":
        raise NidarError("scene.xml: no lidar sensor")
    raise ValueError("bad\nvalue")


def _warn() -> int:
    warnings.warn("RGB reflectance past 830 nm", UserWarning, stacklevel=1)
    return 7


def _record_setup(threads):
    os.environ["NIDAR_TEST_THREADS"] = str(threads)


def _setup_seen() -> tuple[int, str]:
    return os.getpid(), os.environ.get("NIDAR_TEST_THREADS", "")


def _die_once(marker: str, out: str) -> str:
    """SIGKILL this worker in the middle of writing ``out`` the first time; write it the next."""
    from nidar_mi.io.atomic import staged_directory
    from nidar_mi.io.ownership import Owner

    with staged_directory(out, owner=Owner("test", "run")) as stage:
        (stage / "data.txt").write_text("half")
        if not os.path.exists(marker):
            open(marker, "w").close()
            os.kill(os.getpid(), signal.SIGKILL)
        (stage / "data.txt").write_text("whole")
    return "written"


def _noise_tasks(tmp_path, n=6):
    return [
        Task(
            f"scene_{i}",
            _noise,
            (100 + i, str(tmp_path / f"{i}.npy")),
            output=str(tmp_path / f"{i}.npy"),
            skip=partial(os.path.isfile, str(tmp_path / f"{i}.npy")),
        )
        for i in range(n)
    ]


# --------------------------------------------------------------------------- serial


def test_serial_runs_every_task_and_skips_done_ones(tmp_path):
    tasks = _noise_tasks(tmp_path)
    _noise(102, str(tmp_path / "2.npy"))  # done by an earlier run
    report = run_tasks(tasks, progress=False)
    expected = [float(np.random.default_rng(100 + i).normal(size=1000).sum()) for i in range(6)]
    assert report.skipped == ["scene_2"] and report.ran == 5 and report.failures == []
    assert report.results == [v if i != 2 else None for i, v in enumerate(expected)]
    report.raise_on_failure()  # nothing failed: no error


def test_serial_failures_are_named_and_the_rest_completes(tmp_path, capsys):
    tasks = _noise_tasks(tmp_path, 3)
    tasks.insert(1, Task("broken", _fail, ("nidar",)))
    tasks.append(Task("buggy", _fail, ("other",)))
    report = run_tasks(tasks, progress=False)
    assert [f.name for f in report.failures] == ["broken", "buggy"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["0.npy", "1.npy", "2.npy"]
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "error: broken: scene.xml: no lidar sensor",
        "error: buggy: ValueError: bad value",
    ]
    assert "Traceback" in report.failures[1].detail
    with pytest.raises(TasksFailed) as e:
        report.raise_on_failure("scenes")
    assert str(e.value) == (
        "2 of 5 scenes failed (broken, buggy); the other 3 are written; "
        "run again to retry the failed ones"
    )
    assert isinstance(e.value, NidarError)  # the commands print it as one error line, exit 2


def test_leftovers_of_the_job_outputs_are_removed_and_no_others(tmp_path):
    (tmp_path / ".0.npy.tmp-0123abcd.npy").write_bytes(b"half")
    (tmp_path / ".1.npy.partial-x7_k2q9a").mkdir()
    (tmp_path / ".other.partial-x7_k2q9a").mkdir()  # not an output of this job
    run_tasks(_noise_tasks(tmp_path, 2), progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        ".other.partial-x7_k2q9a",
        "0.npy",
        "1.npy",
    ]


def test_bad_options_and_missing_ray_are_one_line_errors(tmp_path, monkeypatch):
    with pytest.raises(NidarError, match=r"`workers` must be >= 1 \(got 0\)"):
        run_tasks(_noise_tasks(tmp_path), workers=0)
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` fails as if not installed
    with pytest.raises(NidarError) as e:
        run_tasks(_noise_tasks(tmp_path), workers=2, progress=False)
    assert str(e.value) == RAY_MISSING
    assert list(tmp_path.iterdir()) == []


def _variant_in_task() -> str:
    import mitsuba as mi

    return mi.variant()


@pytest.fixture()
def caller_variant(variant):
    """The caller's variant for one test: ``scalar_spectral``, not the default one (which a
    worker without a variant of its own would take); the session's variant back afterwards,
    its plugins registered again (``nidar_mi.plugins.<name>`` that variant's modules)."""
    import mitsuba as mi

    from nidar_mi.backend import set_variant

    mi.set_variant("scalar_spectral")
    yield "scalar_spectral"
    set_variant(variant)


def test_a_serial_job_keeps_the_callers_variant(caller_variant):
    """A serial job runs its tasks in the caller's process: the rendering set-up, with or
    without the caller's variant named, renders in it and leaves it active."""
    import mitsuba as mi

    from nidar_mi.backend import prepare_worker, worker_setup

    for setup in (prepare_worker, worker_setup()):
        report = run_tasks([Task("t", _variant_in_task)], setup=setup, progress=False)
        assert report.results == [caller_variant] and report.failures == []
        assert mi.variant() == caller_variant


def test_serial_mode_never_imports_ray(tmp_path):
    code = textwrap.dedent(
        f"""
        import sys
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        import nidar_mi.cli.dataset, nidar_mi.cli.evaluate, nidar_mi.render_dataset
        from nidar_mi.tasks import Task, run_tasks
        report = run_tasks([Task("a", divmod, (7, 2))], progress=False)
        assert report.results == [(3, 1)], report
        assert "ray" not in sys.modules
        """
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_no_cluster_at_the_address_fails_fast():
    with pytest.raises(NidarError, match=r"`ray_address` 127\.0\.0\.1:1: no Ray cluster answers"):
        run_tasks([Task("a", divmod, (7, 2))], address="127.0.0.1:1", progress=False)


# --------------------------------------------------------------------------- Ray


@pytest.fixture(scope="module")
def ray_runtime():
    """One local Ray runtime (2 CPUs) for the tests below; this module's functions by value."""
    ray = pytest.importorskip("ray")  # a dev dependency: installed by scripts/setup.sh
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    ray.init(
        num_cpus=2,
        num_gpus=0,
        include_dashboard=False,
        object_store_memory=128 * 1024**2,
        logging_level="ERROR",
        log_to_driver=False,
    )
    yield ray
    ray.shutdown()
    ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


def test_ray_gives_the_serial_results(ray_runtime, tmp_path):
    serial, parallel = tmp_path / "serial", tmp_path / "ray"
    a = run_tasks(_noise_tasks(serial), progress=False)
    b = run_tasks(_noise_tasks(parallel), workers=2, progress=False)
    assert b.results == a.results and b.failures == [] and b.skipped == []
    for i in range(6):
        assert (serial / f"{i}.npy").read_bytes() == (parallel / f"{i}.npy").read_bytes()
    c = run_tasks(_noise_tasks(parallel), workers=2, progress=False)  # resumed: all done
    assert c.skipped == [f"scene_{i}" for i in range(6)] and c.ran == 0


def test_ray_workers_run_the_setup_with_their_cpu_share(ray_runtime):
    tasks = [Task(f"t{i}", _setup_seen) for i in range(4)]
    report = run_tasks(tasks, workers=2, setup=_record_setup, progress=False)
    cpus = len(os.sched_getaffinity(0))
    assert {threads for _, threads in report.results} == {str(max(1, cpus // 2))}
    assert os.getpid() not in {pid for pid, _ in report.results}


def test_ray_workers_render_in_the_callers_variant_and_leave_it(ray_runtime, caller_variant):
    import mitsuba as mi

    from nidar_mi.backend import worker_setup

    tasks = [Task(f"t{i}", _variant_in_task) for i in range(3)]
    report = run_tasks(tasks, workers=2, setup=worker_setup(), progress=False)
    assert report.results == [caller_variant] * 3 and report.failures == []
    assert mi.variant() == caller_variant


def test_ray_failures_are_named_and_warnings_come_back(ray_runtime, tmp_path, capsys):
    tasks = _noise_tasks(tmp_path, 3) + [Task("broken", _fail, ("nidar",)), Task("w", _warn)]
    with pytest.warns(UserWarning, match="RGB reflectance past 830 nm"):
        report = run_tasks(tasks, workers=2, progress=False)
    assert [f.name for f in report.failures] == ["broken"] and report.results[4] == 7
    assert len(list(tmp_path.glob("*.npy"))) == 3
    assert capsys.readouterr().err.splitlines() == ["error: broken: scene.xml: no lidar sensor"]


def test_a_killed_worker_is_retried_and_its_leftovers_removed(ray_runtime, tmp_path):
    out, marker = tmp_path / "out", tmp_path / "killed"
    tasks = [Task("victim", _die_once, (str(marker), str(out)), output=str(out))]
    tasks += _noise_tasks(tmp_path, 3)
    report = run_tasks(tasks, workers=2, progress=False)
    assert marker.exists()  # the first attempt's worker was killed mid-write...
    assert report.failures == [] and report.results[0] == "written"  # ...the retry wrote it
    assert (out / "data.txt").read_text() == "whole"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no partial folder


def test_a_worker_killed_for_good_fails_its_task_and_a_rerun_resumes(ray_runtime, tmp_path, capsys):
    out, marker = tmp_path / "out", tmp_path / "killed"
    victim = Task(
        "victim",
        _die_once,
        (str(marker), str(out)),
        output=str(out),
        skip=partial(os.path.isdir, str(out)),
    )
    first = run_tasks([victim, *_noise_tasks(tmp_path, 3)], workers=2, retries=0, progress=False)
    assert [f.name for f in first.failures] == ["victim"] and first.ran == 3
    printed = capsys.readouterr()
    assert "worker process died" in printed.err
    assert printed.out == ""  # Ray's own lines about the dead worker went to the debug log
    assert not out.exists()
    second = run_tasks([victim, *_noise_tasks(tmp_path, 3)], workers=2, progress=False)
    assert second.ran == 1 and second.results[0] == "written" and len(second.skipped) == 3
    assert (out / "data.txt").read_text() == "whole"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


_CLUSTER = """
import sys, ray
ray.init(num_cpus=2, num_gpus=0, include_dashboard=False, object_store_memory=128 * 1024**2,
         logging_level="ERROR", log_to_driver=False)
print(ray.get_runtime_context().gcs_address, flush=True)
sys.stdin.read()  # until the test closes stdin
ray.shutdown()
"""

_DRIVER = """
import json, os, sys
from nidar_mi.tasks import Task, run_tasks

def setup(threads):
    os.environ["NIDAR_TEST_THREADS"] = str(threads)

def ancestors():
    pid, out = os.getpid(), []
    while pid > 1:
        with open(f"/proc/{pid}/stat") as f:
            pid = int(f.read().rsplit(")", 1)[1].split()[1])
        out.append(pid)
    return out

def where(i):
    return os.getpid(), os.environ.get("NIDAR_TEST_THREADS", ""), i * i, ancestors()

from nidar_mi.errors import NidarError
try:
    report = run_tasks([Task(f"t{i}", where, (i,)) for i in range(4)], address=sys.argv[1],
                       setup=setup, progress=False)
except NidarError as e:
    print(f"error: {e}", file=sys.stderr)
    sys.exit(2)
import ray
print(json.dumps({"results": report.results, "connected": ray.is_initialized()}))
"""


def test_an_existing_cluster_runs_the_tasks(tmp_path):
    """``address=``: the tasks run in the cluster's workers (one thread each); the driver only
    connects, and disconnects at the end without stopping the cluster. The cluster uses Ray's
    token authentication (its default): a driver without ``RAY_AUTH_MODE=token`` is refused in
    one line that says so, and nothing else on the terminal."""
    import json

    pytest.importorskip("ray")
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_AUTH")}
    cluster = subprocess.Popen(
        [sys.executable, "-c", _CLUSTER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env=env,
    )
    try:
        address = cluster.stdout.readline().strip()
        assert address, "the cluster did not start"
        refused = subprocess.run(
            [sys.executable, "-c", _DRIVER, address],
            capture_output=True,
            text=True,
            timeout=240,
            cwd=tmp_path,
            env=env,
        )
        assert refused.returncode == 2
        assert refused.stderr.count("\n") == 1 and "needs RAY_AUTH_MODE=token" in refused.stderr
        driver = subprocess.run(
            [sys.executable, "-c", _DRIVER, address],
            capture_output=True,
            text=True,
            timeout=240,
            cwd=tmp_path,
            env=dict(env, RAY_AUTH_MODE="token"),
        )
        assert driver.returncode == 0, driver.stderr
        out = json.loads(driver.stdout)
        assert [r[2] for r in out["results"]] == [0, 1, 4, 9] and not out["connected"]
        assert {r[1] for r in out["results"]} == {"1"}
        assert driver.stderr == ""  # nothing from Ray on the terminal
        for pid, _, _, parents in out["results"]:  # the cluster's processes ran them
            assert cluster.pid in parents and pid != cluster.pid
        assert cluster.poll() is None  # still up after the driver left
    finally:
        cluster.stdin.close()
        try:
            cluster.wait(timeout=60)
        except subprocess.TimeoutExpired:
            cluster.kill()
            cluster.wait()
