"""Ray jobs on a runtime with GPUs: one GPU per task, no more tasks at once than GPUs.

Ray schedules GPUs as declared resources, so a runtime that declares two GPUs (none need
exist) shows what a GPU machine gets: each task's worker sees only its own device through
``CUDA_VISIBLE_DEVICES``.
"""

from __future__ import annotations

import os
import sys
import time

import pytest

from nidar_mi.tasks import Task, placement, run_tasks


@pytest.mark.parametrize(
    "workers, local, cpus, gpus, expected",
    [
        (2, True, 2, 0, (2, 1, 0)),  # a CPU machine: as before, cpus // workers threads each
        (1, True, 16, 0, (1, 16, 0)),
        (4, True, 16, 2, (2, 8, 1)),  # two GPUs: two tasks at once, one GPU each
        (1, True, 16, 2, (1, 16, 1)),
        (None, False, 64, 0, (64, 1, 0)),  # a cluster: one thread per task
        (8, False, 64, 4, (4, 1, 1)),
        (None, False, 64, 4, (4, 1, 1)),
    ],
)
def test_placement(workers, local, cpus, gpus, expected):
    assert placement(workers, local=local, cpus=cpus, gpus=gpus) == expected


def _device() -> tuple[str, float, float]:
    start = time.time()
    time.sleep(0.5)
    return os.environ.get("CUDA_VISIBLE_DEVICES", ""), start, time.time()


@pytest.fixture(scope="module")
def two_gpu_runtime():
    ray = pytest.importorskip("ray")
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    ray.init(
        num_cpus=4,
        num_gpus=2,
        include_dashboard=False,
        object_store_memory=128 * 1024**2,
        logging_level="ERROR",
        log_to_driver=False,
    )
    yield ray
    ray.shutdown()
    ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


def test_each_task_gets_one_gpu_of_its_own(two_gpu_runtime):
    report = run_tasks([Task(f"t{i}", _device) for i in range(6)], workers=4, progress=False)
    assert report.failures == []
    devices = [d for d, _, _ in report.results]
    assert set(devices) <= {"0", "1"} and all(devices)
    # never two tasks on one device at the same time, never more than two at once
    spans = sorted((s, e, d) for d, s, e in report.results)
    for i, (_s1, e1, d1) in enumerate(spans):
        overlapping = [d2 for s2, _e2, d2 in spans[i + 1 :] if s2 < e1 - 0.05]
        assert d1 not in overlapping and len(overlapping) <= 1
