"""Independent units of work (LiDAR tiles) in this process or as tasks on Dask.

:func:`run_tasks` calls one function on every item and returns the results in the items'
order, whatever order they finish in, so an output never depends on the number of workers.
With ``workers=1`` and no scheduler the items run here, one after another, without Dask
(QGIS's in-process runs, small inputs); otherwise on a :class:`distributed.LocalCluster` of
``workers`` single-threaded worker processes, or on the existing cluster at ``scheduler``
(``tcp://host:8786``): the same job on many machines, with a work folder they all see.
BLAS and OpenMP pools are pinned to one thread per task (threadpoolctl): a worker per core.
The local workers start with an interpreter of this process's Python version
(:func:`worker_python`), also when Python is embedded in an application such as QGIS.

Progress reports the tasks done out of the total and an estimate of the time left.
"""
from __future__ import annotations

import contextlib
import os
import pickle
import subprocess
import sys
import time
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Callable, Sequence

from .errors import GisroadsError
from .progress import Progress, report


@dataclass(frozen=True)
class Parallel:
    """Where the tasks of a run go.

    Attributes
    ----------
    workers : int
        Tasks run on a local Dask cluster of this many single-threaded worker processes;
        1 runs them in this process, without Dask.
    scheduler : str, optional
        Address of an existing Dask scheduler to run them on instead (its workers must see
        ``work_dir``).
    work_dir : str or Path, optional
        Folder for the tile store and the finished tasks, keyed by the inputs and the
        parameters: a run stopped midway and started again reuses what was finished. By
        default a temporary folder, removed at the end.
    """

    workers: int = 1
    scheduler: str | None = None
    work_dir: object = None


def default_workers() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


@contextlib.contextmanager
def pinned_threads(limit: int | None = 1):
    """BLAS/OpenMP thread pools limited to ``limit`` threads inside the block (threadpoolctl;
    None leaves them as they are). The eigenproblems of a patch-wise NCut are a few hundred
    nodes: more threads do not speed them up, and on a loaded machine spinning OpenBLAS
    threads made them collapse (an ETH image's segmentation: 21-34 s of CPU unpinned, 0.5 s
    pinned, at load average 5 on 2 cores)."""
    if limit is None:
        yield
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a dependency, and it comes with scikit-learn
        yield
        return
    with threadpool_limits(limits=limit):
        yield


def single_threaded(func: Callable, item):
    """``func(item)`` with the BLAS/OpenMP thread pools pinned to one thread."""
    with pinned_threads(1):
        return func(item)


def _eta(done: int, total: int, started: float) -> str:
    if done == 0:
        return ""
    left = (time.monotonic() - started) / done * (total - done)
    minutes, seconds = divmod(int(round(left)), 60)
    return f", about {minutes}:{seconds:02d} left"


def _installation(executable: str) -> str | None:
    """Version and installation (``sys.base_prefix``) of the interpreter at
    ``executable``, ``"3.11 /usr"``; None when it does not run."""
    try:
        done = subprocess.run(
            [executable, "-c", "import sys; print('%d.%d' % sys.version_info[:2], "
                               "sys.base_prefix)"],
            capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def worker_python() -> str:
    """The interpreter that local worker processes start with: one of this process's
    Python installation and version.

    ``sys.executable`` when it is one (the command line, a venv). In an application that
    embeds Python it need not be: QGIS sets it to the first ``python3`` on PATH, which may
    be another installation (a pyenv build of the same version, whose workers then fail
    to load the embedded installation's modules), or to QGIS itself. Workers then start
    with the installation's own ``{sys.base_prefix}/bin/python3.X``. They take this
    process's ``sys.path`` (multiprocessing's spawn passes it), so they import the same
    packages.
    """
    version = "{}.{}".format(*sys.version_info[:2])
    ours = f"{version} {sys.base_prefix}"
    candidates = [sys.executable, os.path.join(sys.base_prefix, "bin", f"python{version}")]
    for candidate in filter(None, candidates):
        if os.access(candidate, os.X_OK) and _installation(candidate) == ours:
            return candidate
    raise GisroadsError(f"no interpreter of this Python ({ours}) found to start Dask workers "
                        f"with (tried {', '.join(filter(None, candidates))}); use one worker")


@contextlib.contextmanager
def _spawning_with(executable: str):
    """multiprocessing's spawn (how Dask's nannies start workers) runs ``executable``."""
    import multiprocessing.spawn as spawn

    before = spawn.get_executable()
    spawn.set_executable(executable)
    try:
        yield
    finally:
        spawn.set_executable(before)


_SHARED: ContextVar[dict | None] = ContextVar("gisroads_shared_workers", default=None)


@contextlib.contextmanager
def shared_workers():
    """Within the block, the rounds of tasks :func:`for_each_result` runs with the same
    ``workers`` (or ``scheduler``) share one Dask client and local cluster, started by the
    first round and closed when the block ends: a local cluster takes seconds to start (its
    workers import the library), and a job runs two rounds (the reading pass, the tiles).
    Nested blocks use the outermost one."""
    if _SHARED.get() is not None:
        yield
        return
    with contextlib.ExitStack() as stack:
        token = _SHARED.set({"stack": stack, "clients": {}})
        try:
            yield
        finally:
            _SHARED.reset(token)


def _client(stack: contextlib.ExitStack, workers: int, scheduler: str | None, tasks: int):
    """A Dask client of a new local cluster of ``workers`` (at most ``tasks``) workers or
    of ``scheduler``, closed with ``stack``; inside :func:`shared_workers`, that block's."""
    shared = _SHARED.get()
    if shared is not None:
        key = (workers, scheduler)
        if key not in shared["clients"]:
            shared["clients"][key] = _connect(shared["stack"], workers, scheduler)
        return shared["clients"][key]
    return _connect(stack, min(workers, tasks), scheduler)


def _connect(stack: contextlib.ExitStack, workers: int, scheduler: str | None):
    from distributed import Client, LocalCluster

    if scheduler is not None:
        return stack.enter_context(Client(scheduler))
    import dask

    # Dask sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which makes glibc return
    # every freed block over 64 KiB to the system: the tiles' numpy temporaries then
    # cost 1.7x the CPU seconds they take in this process (measured, 6 tiles: 10.4 s
    # against 6.1 s). The workers keep the other variables (one BLAS/OpenMP thread).
    environ = {k: v for k, v in (dask.config.get("distributed.nanny.pre-spawn-environ",
                                                 None) or {}).items()
               if k != "MALLOC_TRIM_THRESHOLD_"}
    stack.enter_context(dask.config.set({"distributed.nanny.pre-spawn-environ": environ}))
    # for the cluster's lifetime: a nanny restarts a lost worker the same way
    stack.enter_context(_spawning_with(worker_python()))
    cluster = stack.enter_context(LocalCluster(
        n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0"))
    return stack.enter_context(Client(cluster))



def progress_message(done: int, total: int, started: float, what: str = "tiles") -> str:
    """``"12 of 25 tiles done, about 1:05 left"``."""
    return f"{done} of {total} {what} done{_eta(done, total, started)}"


def run_tasks(func: Callable, items: Sequence, *, workers: int = 1, scheduler: str | None = None,
              progress: Progress = None, what: str = "tiles") -> list:
    """``[func(item) for item in items]``, here or on Dask (module docstring); the
    parameters are those of :func:`for_each_result`."""
    results = [None] * len(items)

    def keep(i, result):
        results[i] = result
    for_each_result(func, items, keep, workers=workers, scheduler=scheduler,
                    progress=progress, what=what)
    return results


def for_each_result(func: Callable, items: Sequence, on_result: Callable, *, workers: int = 1,
                    scheduler: str | None = None, progress: Progress = None,
                    what: str = "tiles") -> None:
    """Call ``on_result(i, func(items[i]))`` for every item as soon as its result is here,
    in the order the tasks finish, and keep nothing: the caller keeps what it needs of each
    result (placed by ``i``, so that its output does not depend on the order), and a task's
    result is released on the worker and here as soon as it was handed over.

    Parameters
    ----------
    func : callable
        Picklable (a module-level function or a ``functools.partial`` of one) when run on
        Dask; it is called with its BLAS threads pinned to one.
    items : sequence
    on_result : callable
        ``on_result(index of the item, result)``.
    workers : int
        Worker processes of a local cluster; 1 (with no scheduler) runs in this process.
    scheduler : str, optional
        Address of an existing Dask scheduler; ``workers`` is then ignored.
    progress : callable, optional
        ``progress(fraction, message)`` after each task; it may raise to cancel, which
        cancels the tasks not yet finished.
    """
    items = list(items)
    if workers < 1:
        raise GisroadsError(f"workers must be at least 1, got {workers}")
    started = time.monotonic()
    if scheduler is None and (workers == 1 or len(items) <= 1):
        for i, item in enumerate(items):
            on_result(i, single_threaded(func, item))
            report(progress, (i + 1) / len(items), progress_message(i + 1, len(items),
                                                                    started, what))
        return
    try:
        from distributed import as_completed
    except ImportError:
        raise GisroadsError("running tiles on several workers or a scheduler needs Dask "
                            "(pip install 'dask[distributed]', or Debian's "
                            "python3-distributed); use one worker") from None

    with contextlib.ExitStack() as stack:
        client = _client(stack, workers, scheduler, len(items))
        report(progress, 0.0, f"{len(items)} {what} on "
                              f"{len(client.scheduler_info()['workers'])} Dask workers")
        live = {}
        for i, item in enumerate(items):
            future = client.submit(single_threaded, func, item, pure=False)
            live[future.key] = (i, future)
        done = 0
        try:
            for future in as_completed([f for _, f in live.values()]):
                i, _ = live.pop(future.key)
                result = future.result()
                future.release()  # the worker may forget it: memory of one task per worker
                del future
                on_result(i, result)
                del result  # the caller kept what it needs
                done += 1
                report(progress, done / len(items), progress_message(done, len(items),
                                                                     started, what))
        except BaseException:
            client.cancel([f for _, f in live.values()])
            raise


NOT_KEPT = object()


def kept_result(path: Path | None) -> Any:
    """The result a finished task left at ``path`` in a work folder (:func:`keep_result`),
    or :data:`NOT_KEPT` when there is none (or no work folder: ``path`` None). The work
    folder is the user's own, so its pickles are trusted as their own files."""
    if path is None or not path.exists():
        return NOT_KEPT
    with open(path, "rb") as f:
        return pickle.load(f)


def keep_result(path: Path | None, result) -> None:
    """Write a finished task's result to ``path`` atomically (a temporary file renamed),
    so a run killed mid-write leaves no half file to resume from; nothing without
    ``path``."""
    if path is None:
        return
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        pickle.dump(result, f, protocol=pickle.HIGHEST_PROTOCOL)
    os.replace(tmp, path)
