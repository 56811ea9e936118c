"""Engines that run many independent episodes: this process, a pool of processes, or Ray.

The dataset runner (``twin dataset``) and the evaluation runner (``twin eval``) hand
their episodes here as jobs, ``fn(*job)`` with ``fn`` a module-level function (so it
pickles), and receive each result as it completes (``on_done(job_index, result)``), in
the calling process, which owns the output folder and writes results atomically:

* ``local``: in this process (one worker) or a pool of fresh processes (``spawn``:
  no forked threads or pybullet state) that die with their parent;
* ``ray``: the same jobs as Ray tasks on a local Ray instance or a cluster.

Workers report progress with :func:`tick`; the driver's ``on_tick`` receives it.
A job that raises a :class:`TwinError` stops the run with it; any other exception is
turned into ``error_type(describe(job) + ...)`` naming the job.
"""

import logging
import os
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from functools import cache
from pathlib import Path

from twin.core.errors import TwinError
from twin.data.store import TrajectoryStore, open_store

ENGINES = ("local", "ray")
POLL_S = 0.2  # [s] how often the local engine passes workers' progress on

_TICKS = None  # a pool worker's queue of progress counts


def tick(n: int) -> None:
    """Report ``n`` units of progress from a worker (ignored outside a pool)."""
    if _TICKS is not None:
        _TICKS.put(n)


def run_jobs(
    fn: Callable,
    jobs: Sequence[tuple],
    *,
    engine: str = "local",
    workers: int = 1,
    ray_address: str | None = None,
    on_done: Callable[[int, object], None],
    on_tick: Callable[[int], None] | None = None,
    describe: Callable[[tuple], str] = repr,
    error_type: type[TwinError] = TwinError,
    ray_hint: str = "",
) -> None:
    """Run ``fn(*job)`` for every job with ``engine`` and ``workers``; ``on_done`` gets
    each result in this process as it completes.

    Raises:
        error_type: a job failed (the jobs done stay done), or Ray is missing.
    """
    if engine not in ENGINES:
        raise error_type(f"--engine must be one of {ENGINES}, got {engine!r}")
    if not jobs:
        return
    if engine == "ray":
        _run_ray(fn, jobs, workers, ray_address, on_done, on_tick, describe, error_type, ray_hint)
    else:
        _run_local(fn, jobs, workers, on_done, on_tick, describe, error_type)


def _checked(call, job, describe, error_type, *args):
    try:
        return call(*args)
    except TwinError:
        raise
    except Exception as error:
        raise error_type(
            f"{describe(job)} failed: {type(error).__name__}: {error}; what is complete is "
            "kept, rerun the same command to resume"
        ) from error


def _run_local(fn, jobs, workers, on_done, on_tick, describe, error_type) -> None:
    global _TICKS
    if workers == 1 or len(jobs) <= 1:
        _TICKS = None
        for k, job in enumerate(jobs):
            on_done(k, _checked(_call_with_ticks, job, describe, error_type, fn, job, on_tick))
        return
    import multiprocessing

    context = multiprocessing.get_context("spawn")  # no fork of threads or pybullet
    ticks = context.SimpleQueue()
    pool = ProcessPoolExecutor(
        max_workers=min(workers, len(jobs)),
        mp_context=context,
        initializer=_start_worker,
        initargs=(ticks,),
    )

    def drain():
        while not ticks.empty():
            n = ticks.get()
            if on_tick is not None:
                on_tick(n)

    try:
        futures = {pool.submit(fn, *job): k for k, job in enumerate(jobs)}
        pending = set(futures)
        while pending:
            done, pending = wait(pending, timeout=POLL_S, return_when=FIRST_COMPLETED)
            drain()
            for future in done:
                k = futures[future]
                on_done(k, _checked(future.result, jobs[k], describe, error_type))
    except BaseException:
        # on an error the jobs running finish and the others are cancelled; on
        # Ctrl-C the workers are interrupted with the run
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
    drain()


def _call_with_ticks(fn, job, on_tick):
    """In this process: a worker's ticks go straight to ``on_tick``."""
    global _TICKS
    _TICKS = _Direct(on_tick)
    try:
        return fn(*job)
    finally:
        _TICKS = None


class _Direct:
    def __init__(self, on_tick):
        self.on_tick = on_tick

    def put(self, n: int) -> None:
        if self.on_tick is not None:
            self.on_tick(n)


def _start_worker(ticks) -> None:
    """Pool worker set-up: report progress to ``ticks``; die with the parent."""
    global _TICKS
    _TICKS = ticks
    _die_with_parent()


def _die_with_parent() -> None:
    """Ask Linux to kill this process when its parent dies (a killed run must not
    leave workers writing)."""
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return  # not Linux: workers end when they find the pool gone
    if os.getppid() == 1:
        os._exit(1)


def _run_ray(fn, jobs, workers, address, on_done, on_tick, describe, error_type, hint) -> None:
    try:
        import ray
    except ImportError:
        raise error_type(
            f"--engine ray needs Ray: pip install 'i24-twin[ray]' (or use --engine local){hint}"
        ) from None
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(
                address=address,
                num_cpus=None if address else workers,
                include_dashboard=False,
                log_to_driver=False,
                logging_level=logging.WARNING,
            )
        except Exception as error:
            where = f"the Ray cluster at {address}" if address else "a local Ray instance"
            raise error_type(f"cannot start or join {where}: {error}") from None
    try:
        task = ray.remote(num_cpus=1)(fn)
        refs = {task.remote(*job): k for k, job in enumerate(jobs)}
        while refs:
            (ready,), _ = ray.wait(list(refs), num_returns=1)
            k = refs.pop(ready)
            on_done(k, _checked(ray.get, jobs[k], describe, error_type, ready))
    finally:
        if started:
            ray.shutdown()


def where(store: TrajectoryStore, bundle) -> tuple[str, str, str]:
    """How a worker finds the data and the map: store folder, map folder and key."""
    return str(store.path), str(bundle.folder), bundle.key


@cache
def worker_data(location: tuple[str, str, str]):
    """The store and map of a worker. On a node without the map folder the default
    map is built there, and used if it is the same map (same key).

    Raises:
        TwinError: the node's map is another map.
    """
    from mapgen.build import default_map, is_map, load_map

    store_path, map_folder, key = location
    bundle = load_map(Path(map_folder)) if is_map(Path(map_folder)) else default_map()
    if bundle.key != key:
        raise TwinError(f"this node has no map {key} (looked in {map_folder})")
    return open_store(store_path), bundle
