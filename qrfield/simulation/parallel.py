"""Spread a study's tasks over worker processes (concurrent.futures), one thread per process.

A study is cut into tasks (:func:`qrfield.simulation.runner.plan_tasks`: whole sweeps of grid
points of one or more combinations); each worker computes whole tasks
(:func:`qrfield.simulation.runner.compute_task`). The calling process is one of the workers: it
computes tasks itself between handing them out, merges the results as they come back, reports
progress, and stops handing out work when asked to.

Processes, not threads: the solvers are numpy code holding the GIL between many small operations.
Workers start from a fork server (Linux: cheap forks of a process that has already imported numpy
and the solvers, shared by every run of this process) or by spawning (macOS); never by a plain
fork, which is unsafe in a multi-threaded process such as the app. Each worker runs one thread of
numpy's BLAS and of OpenCV: the variables of WORKER_ENVIRONMENT are set for the processes the pool
starts (restored in this process afterwards), since OpenBLAS reads them only when numpy is
imported, and cv2.setNumThreads(1) is called in each worker. The caller's main module is not run
again in the workers (see :func:`starting_workers`), so a script need not guard its study with
``if __name__ == "__main__"``. Workers ignore SIGINT: Ctrl-C in a
terminal reaches the whole process group, and the calling process, not the workers, decides what
a stop means (see ``qrfield simulate``).
"""

from __future__ import annotations

import collections
import contextlib
import multiprocessing
import os
import signal
import sys
import threading
import types
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from qrfield.simulation.runner import Block, TaskResult, compute_task
from qrfield.simulation.study import StudyConfig

#: Below this many poses a study runs in the calling process: starting workers and shipping
#: results costs more than it saves (the app's small study, 4,680 poses, takes well under a second).
PARALLEL_MIN_POSES = 20_000
#: Environment of the worker processes: one thread per library (OpenBLAS, OpenMP, MKL, OpenCV).
WORKER_ENVIRONMENT = {
    "OPENBLAS_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "OPENCV_FOR_THREADS_NUM": "1",
}
#: How often (s) the calling process looks at the stop request while waiting for tasks.
POLL_S = 0.05
#: Modules the fork server imports once, so that its forked workers start without importing them.
PRELOAD = ["qrfield.simulation.parallel", "qrfield.solvers"]

_environment_lock = threading.Lock()


def cpu_count() -> int:
    """Cores this process may run on (the affinity mask where the platform has one)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def auto_workers(total_poses: int) -> int:
    """Workers for a study of ``total_poses``: every core, or 1 (this process) for a small study."""
    if total_poses < PARALLEL_MIN_POSES:
        return 1
    return cpu_count()


def _context() -> multiprocessing.context.BaseContext:
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        return ctx
    return multiprocessing.get_context("spawn")


@contextlib.contextmanager
def starting_workers() -> Iterator[None]:
    """The state in which this process starts workers, undone afterwards.

    - WORKER_ENVIRONMENT is set (the workers inherit it when they start);
    - ``__main__`` is a bare stand-in: multiprocessing would otherwise run the caller's main
      module again in every worker (a user's unguarded script would start its study again, and
      the app would import Qt in each worker). The workers need only qrfield, imported by name.
    """
    with _environment_lock:
        saved = {name: os.environ.get(name) for name in WORKER_ENVIRONMENT}
        main = sys.modules.get("__main__")
        os.environ.update(WORKER_ENVIRONMENT)
        sys.modules["__main__"] = types.ModuleType("__main__")
        try:
            yield
        finally:
            if main is not None:
                sys.modules["__main__"] = main
            for name, value in saved.items():
                if value is None:
                    os.environ.pop(name, None)
                else:
                    os.environ[name] = value


def _init_worker() -> None:
    """In each worker: Ctrl-C is the caller's to handle; one OpenCV thread."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import cv2

    cv2.setNumThreads(1)


def _run(config: StudyConfig, task: list[Block]) -> TaskResult:
    result = compute_task(config, task)
    assert result is not None  # no stop request inside a worker
    return result


def run_tasks(
    config: StudyConfig,
    tasks: list[list[Block]],
    workers: int,
    merge: Callable[[TaskResult], None],
    should_stop: Callable[[], bool],
) -> bool:
    """Compute ``tasks`` on ``workers`` processes, this one included, calling ``merge`` here.

    This process is one of the workers: it computes a task itself whenever the others are busy,
    so a run is never slower than in this process alone by more than the hand-over of results,
    even when the worker processes are still starting or the machine's other cores are taken.
    The other ``workers - 1`` processes each keep one task queued ahead. Returns True when
    ``should_stop`` became true first: tasks not yet handed out are dropped, those running are
    waited for and dropped (a task is at most runner.CHUNK_POSES poses). A worker's exception is
    raised here; a worker that died (killed, out of memory) raises RuntimeError saying so.
    """
    queue = collections.deque(tasks)
    helpers = min(workers - 1, len(tasks) - 1)
    if helpers < 1:
        return _run_here(config, queue, merge, should_stop)
    ctx = _context()
    with starting_workers():
        executor = ProcessPoolExecutor(max_workers=helpers, mp_context=ctx, initializer=_init_worker)
    in_flight: set[Future[TaskResult]] = set()

    def hand_out() -> None:
        while queue and len(in_flight) < 2 * helpers:
            task = queue.popleft()
            with starting_workers():  # the pool starts its processes inside submit()
                in_flight.add(executor.submit(_run, config, task))

    def collect(done: set[Future[TaskResult]]) -> None:
        for future in done:
            in_flight.discard(future)
            try:
                merge(future.result())
            except BrokenProcessPool as exc:
                raise RuntimeError(
                    f"a simulation worker process died ({exc}); the study was not finished"
                ) from None

    stopped = False
    try:
        hand_out()
        while queue or in_flight:
            if should_stop():
                stopped = True
                break
            collect({f for f in in_flight if f.done()})
            hand_out()
            if queue:
                result = compute_task(config, queue.popleft(), stop=should_stop)
                if result is None:
                    stopped = True
                    break
                merge(result)
            elif in_flight:
                done, _ = wait(in_flight, timeout=POLL_S, return_when=FIRST_COMPLETED)
                collect(done)
    finally:
        for future in in_flight:
            future.cancel()
        executor.shutdown(wait=True, cancel_futures=True)
    return stopped


def _run_here(
    config: StudyConfig,
    queue: collections.deque[list[Block]],
    merge: Callable[[TaskResult], None],
    should_stop: Callable[[], bool],
) -> bool:
    while queue:
        if should_stop():
            return True
        result = compute_task(config, queue.popleft(), stop=should_stop)
        if result is None:
            return True
        merge(result)
    return False
