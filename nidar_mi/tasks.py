"""Many independent tasks, run serially in this process or on Ray.

A :class:`Task` is one unit of work: a name (what a failure names: a scene, a frame), a
module-level function with its arguments, the output path it writes, and a skip test (true
when the output already holds this task's result). :func:`run_tasks` runs a list of them:

* serially in this process by default (Ray is not imported);
* ``workers=N``: on a local Ray runtime started for the job (N concurrent tasks, each Dr.Jit
  process given ``cpus // N`` threads), shut down at the end;
* ``address=ADDRESS``: on an existing Ray cluster (one CPU per task; ``workers`` then caps the
  tasks in flight).

Where the Ray runtime has GPUs (a local machine whose CUDA variant works, or a cluster whose
nodes report ``GPU`` resources), every task asks for one GPU (``num_gpus=1``: Ray gives it its
own device through ``CUDA_VISIBLE_DEVICES``, and the worker's default variant is then the CUDA
one) and no more tasks run at once than there are GPUs. Without GPUs nothing changes.

Whatever the mode, the job behaves the same:

* Tasks whose skip test is true are not run (a job resumes where a crashed or interrupted run
  stopped; outputs are written atomically, so an output either exists whole or not at all).
* One progress bar counts every task of the job (skipped ones included).
* A task that fails is reported at once as ``error: <name>: <message>`` while the others go on;
  :meth:`TaskReport.raise_on_failure` then raises one summary line. A worker process that dies
  (killed, out of memory, crashed) has its task retried once on another worker.
* Hidden temporaries a killed writer left beside a task's output (``nidar_mi.io.atomic``'s
  ``.name.partial-*``, ``.name.old-*``, ``.name.tmp-*``) are removed before and after the job.
* Warnings raised in a worker are raised again in this process.

Each worker process runs ``setup(threads)`` before each task (it must be cheap when repeated):
for rendering, :func:`nidar_mi.backend.worker_setup` (``prepare_worker`` with the caller's
variant) sets Dr.Jit's thread count and the Mitsuba variant, whose plugins register per variant
per process. A serial job runs its tasks in the caller's process, whose variant stays as the
caller's entry point chose it. Functions and arguments are
pickled to the workers, so a task function must be importable there (a module-level function
of an installed package) and take plain data (paths, numbers, dicts), never a loaded scene.

Example (one render folder per frame of a sequence)::

    tasks = [
        Task(f"frame {k:06d}", render_frame, (scene, k), output=out / f"{k:06d}",
             skip=functools.partial(is_current, out / f"{k:06d}", request_of(k)))
        for k in range(n)
    ]
    run_tasks(tasks, workers=2, desc="sequence", unit="frame").raise_on_failure("frames")
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
import traceback
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import NidarError

__all__ = [
    "RAY_MISSING",
    "Task",
    "TaskFailure",
    "TaskReport",
    "TasksFailed",
    "check_parallel",
    "run_tasks",
]

#: The one line a user sees when workers are asked for and Ray is not installed.
RAY_MISSING = "`workers` and `ray_address` need Ray: pip install 'nidar_mi[ray]'"
#: Object store of a local runtime: tasks pass paths and small results only.
_OBJECT_STORE_BYTES = 128 * 1024**2
#: How often the driver wakes up while waiting (Ctrl-C and SIGTERM are handled in between).
_POLL_S = 0.2
#: Seconds to wait for a cluster address to accept a connection.
_CONNECT_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class Task:
    """One unit of work.

    Attributes:
        name: what a failure names (e.g. the scene).
        fn: a module-level function, pickled by reference to the worker.
        args: its positional arguments (plain data).
        kwargs: its keyword arguments (plain data).
        output: the file or folder it writes; leftovers of a killed writer beside it are removed.
        skip: evaluated in this process before the job; true when ``output`` is already current.
    """

    name: str
    fn: Callable[..., Any]
    args: tuple = ()
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    output: str | os.PathLike | None = None
    skip: Callable[[], bool] | None = None


@dataclass(frozen=True)
class TaskFailure:
    """A task that failed: its name, a one-line message and, for unexpected errors, the traceback."""

    name: str
    message: str
    detail: str = ""


class TasksFailed(NidarError):
    """Some tasks of a job failed (each was reported on its own line already)."""


@dataclass
class TaskReport:
    """What a job did.

    Attributes:
        results: per task, in task order, the function's return value (None when skipped or
            failed).
        skipped: names of the tasks whose skip test was true.
        failures: the failed tasks, in the order they failed.
        seconds: wall time of the job.
    """

    results: list[Any]
    skipped: list[str]
    failures: list[TaskFailure]
    seconds: float

    @property
    def ran(self) -> int:
        """Tasks run to success."""
        return len(self.results) - len(self.skipped) - len(self.failures)

    def raise_on_failure(self, what: str = "tasks") -> None:
        """Raise :class:`TasksFailed` with one summary line when any task failed.

        Args:
            what: the plural noun of a task in the message (``scenes``, ``frames``).
        """
        if not self.failures:
            return
        names = [f.name for f in self.failures]
        shown = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
        done = len(self.results) - len(names)
        raise TasksFailed(
            f"{len(names)} of {len(self.results)} {what} failed ({shown}); the other {done} are "
            "written; run again to retry the failed ones"
        )


# --------------------------------------------------------------------------- in the worker


@dataclass
class _Outcome:
    """What a task hands back to the driver (pickled from the worker)."""

    value: Any = None
    error: str | None = None
    detail: str = ""
    warnings: list = field(default_factory=list)  # (message, category) of warnings raised


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _call(fn, args, kwargs) -> _Outcome:
    try:
        return _Outcome(value=fn(*args, **kwargs))
    except NidarError as e:
        return _Outcome(error=_one_line(e))
    except Exception as e:  # any failure of one task is reported, the job goes on
        return _Outcome(
            error=f"{type(e).__name__}: {_one_line(e) or 'no message'}",
            detail=traceback.format_exc(),
        )


def _execute(fn, args, kwargs, setup, threads, capture_warnings: bool) -> _Outcome:
    """Run one task; every failure but an interruption becomes an :class:`_Outcome` error."""
    if setup is not None:
        outcome = _call(setup, (threads,), {})
        if outcome.error is not None:
            outcome.error = f"worker set-up: {outcome.error}"
            return outcome
    if not capture_warnings:
        return _call(fn, args, kwargs)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        outcome = _call(fn, args, kwargs)
    outcome.warnings = [(str(w.message), w.category) for w in caught]
    return outcome


# --------------------------------------------------------------------------- leftovers


def _sweep(tasks: Sequence[Task]) -> None:
    """Remove what killed writers left beside the tasks' outputs (one listing per folder); a
    staging folder a live writer still holds stays (:func:`nidar_mi.io.atomic.remove_stale`)."""
    from .io.atomic import leftovers, remove_stale

    by_dir: dict[Path, set[str]] = {}
    for t in tasks:
        if t.output is not None:
            p = Path(t.output).absolute()
            by_dir.setdefault(p.parent, set()).add(p.name)
    for folder, names in by_dir.items():
        for name, path in leftovers(folder):
            if name in names:
                if path.is_dir() and not path.is_symlink():
                    remove_stale(path, str(folder / name))
                else:
                    path.unlink(missing_ok=True)


# --------------------------------------------------------------------------- the driver


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


class _Progress:
    """The job's one progress bar, and the per-task error lines printed above it."""

    def __init__(self, total: int, skipped: int, desc: str, unit: str, enabled: bool):
        from tqdm.auto import tqdm

        from .progress import progress_bar

        self._tqdm = tqdm
        self.bar = progress_bar(total=total, initial=skipped, show=enabled, desc=desc, unit=unit)
        self.skipped, self.failed = skipped, 0
        self._postfix()

    def _postfix(self, note: str = "", refresh: bool = False) -> None:
        parts = [f"{self.skipped} skipped"] if self.skipped else []
        parts += [f"{self.failed} failed"] if self.failed else []
        self.bar.set_postfix_str(", ".join(parts + ([note] if note else [])), refresh=refresh)

    def note(self, text: str) -> None:
        """Show what the job waits for (e.g. Ray starting)."""
        self._postfix(text, refresh=True)

    def done(self, failure: TaskFailure | None) -> None:
        """One more task finished (``failure``: how it failed)."""
        if failure is not None:
            self.failed += 1
            self._tqdm.write(f"error: {failure.name}: {failure.message}", file=sys.stderr)
        self._postfix()
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


def _finish(task: Task, outcome: _Outcome, index: int, report: TaskReport, bar: _Progress):
    import logging

    for message, category in outcome.warnings:
        warnings.warn(message, category, stacklevel=2)
    failure = None
    if outcome.error is not None:
        failure = TaskFailure(task.name, outcome.error, outcome.detail)
        report.failures.append(failure)
        if outcome.detail:
            logging.getLogger("nidar_mi.tasks").debug("%s failed:\n%s", task.name, outcome.detail)
    else:
        report.results[index] = outcome.value
    bar.done(failure)


def _run_serial(pending, setup, report, bar) -> None:
    for index, task in pending:
        outcome = _execute(task.fn, task.args, dict(task.kwargs), setup, None, False)
        _finish(task, outcome, index, report, bar)


def _import_ray():
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    try:
        import ray
    except ImportError:
        raise NidarError(RAY_MISSING) from None
    return ray


def _check_address(address: str) -> None:
    """Fail fast with one line when nothing, or something that is not a Ray cluster, answers at
    ``host:port``.

    Ray has no call that only checks an address: ``ray.init`` retries an address where nothing
    answers for minutes, and with its reconnect timeout shortened (``RAY_gcs_rpc_server_
    reconnect_timeout_s``) its core ends the process instead of raising; run in a child
    process, a probe by ``ray.init`` takes over 10 s here even with 3 s timeouts. So the address
    is checked at the protocol Ray speaks there: a Ray cluster (GCS or Ray Client server) is a
    gRPC server, which answers an HTTP/2 client's preface with its SETTINGS frame.
    """
    import socket

    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host:  # "auto", or a form Ray resolves itself
        return
    try:
        with socket.create_connection(
            (host.strip("[]"), int(port)), timeout=_CONNECT_TIMEOUT_S
        ) as conn:
            conn.sendall(_HTTP2_PREFACE)
            header = _read_exactly(conn, 9)
    except (OSError, ValueError) as e:
        raise NidarError(f"`ray_address` {address}: no Ray cluster answers there ({e})") from None
    if len(header) < 9 or header[3] != _HTTP2_SETTINGS:
        raise NidarError(
            f"`ray_address` {address}: something answers there, but not a Ray cluster (no gRPC)"
        )


#: An HTTP/2 client's connection preface and an empty SETTINGS frame: a Ray cluster (GCS or
#: Ray Client server) is a gRPC server and answers with its own SETTINGS frame (type 4).
_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + b"\x00\x00\x00\x04\x00\x00\x00\x00\x00"
_HTTP2_SETTINGS = 4


def _read_exactly(conn, n: int) -> bytes:
    """Up to ``n`` bytes from a socket (fewer when the peer closes first)."""
    data = b""
    while len(data) < n:
        chunk = conn.recv(n - len(data))
        if not chunk:
            break
        data += chunk
    return data


def _connect(ray, workers: int | None, address: str | None, after_init: Callable[[], None]) -> bool:
    """Connect to a cluster or start a local runtime; True when this job must shut it down.

    ``ray.init`` installs its own SIGTERM handler (exit at once); ``after_init`` puts the job's
    back, so that SIGTERM unwinds like Ctrl-C and the job shuts Ray down itself.
    """
    if ray.is_initialized():  # e.g. a notebook that connected already
        return False
    try:
        _init(ray, workers, address)
    finally:
        after_init()
    return True


#: Added to a failed connection when the command's environment does not enable Ray's token
#: authentication, which Ray never does by itself for an explicit address.
_AUTH_HINT = (
    "; a cluster with token authentication (the default of clusters Ray starts) also needs "
    "RAY_AUTH_MODE=token and its token (RAY_AUTH_TOKEN or ~/.ray/auth_token)"
)


@contextmanager
def _stderr_to_log():
    """Send what Ray's C++ core writes straight to file descriptor 2 while it connects (a
    warning a second while a cluster refuses it) to the debug log instead of the terminal."""
    import logging
    import tempfile

    sys.stderr.flush()
    with tempfile.TemporaryFile(mode="w+b") as capture:
        saved = os.dup(2)
        os.dup2(capture.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            capture.seek(0)
            text = capture.read().decode("utf-8", "replace").strip()
            if text:
                logging.getLogger("nidar_mi.tasks").debug("ray while connecting:\n%s", text)


def _init(ray, workers: int | None, address: str | None) -> None:
    quiet = dict(logging_level="ERROR", log_to_driver=False, configure_logging=True)
    if address is not None:
        try:
            with _stderr_to_log():
                ray.init(address=address, **quiet)
        except (ConnectionError, RuntimeError, ValueError) as e:
            hint = "" if os.environ.get("RAY_AUTH_MODE") else _AUTH_HINT
            raise NidarError(f"`ray_address` {address}: {_one_line(e)}{hint}") from None
        return
    from .backend import cuda_available

    ray.init(
        num_cpus=workers,
        num_gpus=None if cuda_available() else 0,  # None: Ray counts the devices
        include_dashboard=False,
        object_store_memory=_OBJECT_STORE_BYTES,
        **quiet,
    )


class _LogLines:
    """A text stream whose lines go to the debug log (what Ray's driver prints while a job
    runs)."""

    def __init__(self, log) -> None:
        self.log, self._part = log, ""

    def write(self, text: str) -> int:
        *lines, self._part = (self._part + text).split("\n")
        for line in lines:
            if line.strip():
                self.log.debug("ray: %s", line)
        return len(text)

    def flush(self) -> None:
        pass


@contextmanager
def _ray_prints_to_log():
    """Send what the driver prints to stdout while the job runs to the debug log.

    With ``log_to_driver=False`` Ray still prints the raylet's error messages (several lines per
    killed worker) to stdout from its listener thread; each task's failure is reported here in
    one line instead. Ray has no option for it; nothing else prints while a job runs (the
    progress bar and the failures go to stderr), so stdout itself is sent to the log.
    """
    import logging

    lines = _LogLines(logging.getLogger("nidar_mi.tasks"))
    with contextlib.redirect_stdout(lines):
        yield


def _ray_error(ray, err: Exception, retries: int) -> str:
    if isinstance(err, ray.exceptions.WorkerCrashedError | ray.exceptions.OutOfMemoryError):
        times = f", {retries + 1} times" if retries else ""
        return f"its worker process died (killed, out of memory or crashed{times})"
    if isinstance(err, ray.exceptions.NodeDiedError):
        return "its node died"
    text = str(err).strip().splitlines()
    return _one_line(text[-1] if text else type(err).__name__)


@contextmanager
def _sigterm_through_ray():
    """Keep the caller's SIGTERM handler, and the exception it raises, while Ray runs.

    ``ray.init`` replaces the handler, and an exception a handler raises while Ray waits comes
    out as a plain :class:`KeyboardInterrupt`; this puts the handler back after ``ray.init``
    (the yielded function) and raises the handler's own exception again (e.g. the commands'
    ``Terminated``, exit status 143).
    """
    import signal
    import threading

    previous = signal.getsignal(signal.SIGTERM)
    if not callable(previous) or threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    received = []

    def handler(signum, frame):
        received.append(signum)
        previous(signum, frame)

    signal.signal(signal.SIGTERM, handler)
    try:
        yield lambda: signal.signal(signal.SIGTERM, handler)
    except KeyboardInterrupt:
        if received:
            previous(signal.SIGTERM, None)
        raise
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run_ray(pending, setup, report, bar, where, started) -> None:
    """``where``: (workers, address, retries) of :func:`run_tasks`."""
    ray = _import_ray()
    address = where[1]
    bar.note("starting Ray" if address is None else f"connecting to {address}")
    with _ray_prints_to_log(), _sigterm_through_ray() as after_init:
        _run_on(ray, pending, setup, report, bar, where, after_init, started)


def _run_on(ray, pending, setup, report, bar, where, after_init, started) -> None:
    workers, address, retries = where
    owned = _connect(ray, workers, address, after_init)
    inflight: dict = {}
    try:
        started()
        resources = ray.cluster_resources()
        concurrency, threads, gpus = placement(
            workers,
            local=address is None,
            cpus=_cpus() if address is None else int(resources.get("CPU", 1)),
            gpus=int(resources.get("GPU", 0)),
        )
        remote = ray.remote(_execute).options(num_cpus=1, num_gpus=gpus, max_retries=retries)
        bar.note("")
        queue = iter(pending)
        exhausted = False
        while True:
            while not exhausted and len(inflight) < 2 * concurrency:
                item = next(queue, None)
                if item is None:
                    exhausted = True
                    break
                index, task = item
                ref = remote.remote(task.fn, task.args, dict(task.kwargs), setup, threads, True)
                inflight[ref] = item
            if not inflight:
                break
            ready, _ = ray.wait(list(inflight), num_returns=1, timeout=_POLL_S)
            for ref in ready:
                index, task = inflight.pop(ref)
                try:
                    outcome = ray.get(ref)
                except ray.exceptions.RayError as e:
                    outcome = _Outcome(error=_ray_error(ray, e, retries))
                _finish(task, outcome, index, report, bar)
    finally:
        for ref in inflight:  # interrupted: stop what still runs
            try:
                ray.cancel(ref, force=True)
            except Exception:  # noqa: BLE001 - best effort while unwinding
                pass
        if owned:
            ray.shutdown()


def placement(workers: int | None, *, local: bool, cpus: int, gpus: int) -> tuple[int, int, int]:
    """How a Ray job runs its tasks: ``(tasks at once, CPU threads per task, GPUs per task)``.

    Args:
        workers: the job's ``workers`` (>= 1; None only with a cluster: as many as it holds).
        local: a runtime started for this job (``cpus`` are this machine's, shared out as
            threads) rather than a cluster (one thread per task).
        cpus: CPUs of the runtime (>= 1).
        gpus: GPUs of the runtime (0: none).

    Every task takes one GPU when there are any, so no more run at once than there are GPUs.
    """
    if gpus > 0:
        concurrency = min(workers or gpus, gpus)
        return concurrency, (max(1, cpus // concurrency) if local else 1), 1
    if local:
        return workers, max(1, cpus // workers), 0
    return min(workers or cpus, max(cpus, 1)), 1, 0


def check_parallel(workers: int | None, address: str | None) -> None:
    """Check ``workers`` and ``address`` as :func:`run_tasks` takes them, that Ray imports when
    they ask for it, and that something answers at ``address``: a command calls it before it
    touches its output.

    Raises:
        NidarError: ``workers`` < 1, an empty address, Ray missing (:data:`RAY_MISSING`), or
            nothing listening at ``address``.
    """
    if workers is not None and (isinstance(workers, bool) or workers < 1):
        raise NidarError(f"`workers` must be >= 1 (got {workers})")
    if address is not None and not str(address).strip():
        raise NidarError("`ray_address` must not be empty")
    if workers is not None or address is not None:
        _import_ray()
    if address is not None:
        _check_address(address)


def run_tasks(
    tasks: Iterable[Task],
    *,
    workers: int | None = None,
    address: str | None = None,
    setup: Callable[[int | None], Any] | None = None,
    progress: bool = True,
    desc: str = "tasks",
    unit: str = "task",
    retries: int = 1,
    started: Callable[[], None] | None = None,
) -> TaskReport:
    """Run the tasks serially (default) or on Ray; see the module docstring.

    Args:
        tasks: the job.
        workers: tasks at once on a local Ray runtime (>= 1); with ``address``, a cap on the
            tasks in flight. None and no address: serially in this process.
        address: an existing Ray cluster (``host:port``, ``ray://host:port`` or ``auto``).
        setup: called in each worker process before each task with the number of CPU threads
            the task may use (None: all of this machine's; serial mode).
        progress: show the progress bar (errors are printed either way).
        desc: the bar's label.
        unit: what one task is called on the bar (``scene``, ``frame``).
        retries: how often a task whose worker process died is run again (Ray only).
        started: called once before the first task runs, when the runtime is up (after Ray
            connected or started): a caller removes what the job replaces only then.

    Returns:
        The report; call :meth:`TaskReport.raise_on_failure` to turn failures into an error.

    Raises:
        NidarError: ``workers`` < 1, Ray missing, or no cluster at ``address``.
        KeyboardInterrupt: Ctrl-C or SIGTERM; tasks in flight are cancelled, finished outputs
            stay (a later run skips them).
    """
    check_parallel(workers, address)
    tasks = list(tasks)
    t0 = time.perf_counter()
    report = TaskReport(results=[None] * len(tasks), skipped=[], failures=[], seconds=0.0)
    pending = []
    for index, task in enumerate(tasks):
        if task.skip is not None and task.skip():
            report.skipped.append(task.name)
        else:
            pending.append((index, task))
    _sweep(tasks)
    bar = _Progress(len(tasks), len(report.skipped), desc, unit, progress)
    started = started or (lambda: None)
    finished = False
    try:
        if not pending:
            started()
        elif workers is None and address is None:
            started()
            _run_serial(pending, setup, report, bar)
        else:
            _run_ray(pending, setup, report, bar, (workers, address, retries), started)
        finished = True
    finally:
        bar.close()
        if finished or address is None:  # a cluster's cancelled workers may still be writing
            _sweep(tasks)
    report.seconds = time.perf_counter() - t0
    return report
