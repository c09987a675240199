"""Independent units of work (LiDAR tiles) in this process or as tasks on Dask.

:func:`run_tasks` calls one function on every item and returns the results in the items'
order, whatever order they finish in, so an output never depends on the number of workers.
With ``workers=1`` and no scheduler the items run here, one after another, without Dask
(QGIS's in-process runs, small inputs); otherwise on a :class:`distributed.LocalCluster` of
``workers`` single-threaded worker processes, or on the existing cluster at ``scheduler``
(``tcp://host:8786``): the same job on many machines, with a work folder they all see.
BLAS and OpenMP pools are pinned to one thread per task (threadpoolctl): a worker per core.

Progress reports the tasks done out of the total and an estimate of the time left.
"""
from __future__ import annotations

import os
import pickle
import time
from pathlib import Path
from typing import Any, Callable, Sequence

from .progress import Progress, report


def default_workers() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def single_threaded(func: Callable, item):
    """``func(item)`` with the BLAS/OpenMP thread pools pinned to one thread."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        return func(item)
    with threadpool_limits(limits=1):
        return func(item)


def _eta(done: int, total: int, started: float) -> str:
    if done == 0:
        return ""
    left = (time.monotonic() - started) / done * (total - done)
    minutes, seconds = divmod(int(round(left)), 60)
    return f", about {minutes}:{seconds:02d} left"


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
        raise ValueError(f"workers must be at least 1, got {workers}")
    started = time.monotonic()
    if scheduler is None and (workers == 1 or len(items) <= 1):
        for i, item in enumerate(items):
            on_result(i, single_threaded(func, item))
            report(progress, (i + 1) / len(items), progress_message(i + 1, len(items),
                                                                    started, what))
        return
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise ValueError("running tiles on several workers or a scheduler needs Dask "
                         "(pip install 'dask[distributed]', or Debian's python3-distributed);"
                         " use one worker") from None

    cluster = None
    if scheduler is None:
        import dask

        # Dask sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which makes glibc return
        # every freed block over 64 KiB to the system: the tiles' numpy temporaries then
        # cost 1.7x the CPU seconds they take in this process (measured, 6 tiles: 10.4 s
        # against 6.1 s). The workers keep the other variables (one BLAS/OpenMP thread).
        environ = {k: v for k, v in (dask.config.get("distributed.nanny.pre-spawn-environ",
                                                     None) or {}).items()
                   if k != "MALLOC_TRIM_THRESHOLD_"}
        with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
            cluster = LocalCluster(n_workers=min(workers, len(items)), threads_per_worker=1,
                                   processes=True, dashboard_address=":0")
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
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
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


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
