"""Compiling the batched core's kernels for a first run, in two other processes.

A new machine has no compiled kernels: the first ``twin run`` compiled them on its first
step (Numba, 40 to 55 s of one core), after building the embedded data and the map on
that same core while the other idled. :func:`start` has them compiled by two other
processes instead, while the run builds the data and the map: on a few hand-made
vehicles (not the run's data: the kernels' types depend only on the code) and the
default map, in the run's world, so that every kernel the run calls is in the kernel
cache (:mod:`twin.core.jit`) when it starts, and it loads each in a fraction of a second.

::

    compiling = start("physics")          # None when the cache already holds them
    store, bundle = ..., ...              # the data and the map, meanwhile
    if compiling:
        seconds = compiling.wait()        # then the run loads every kernel from the cache

The work is shared by two processes, one a core: the ``episode`` part runs the
episode, the ``step`` part compiles the kernels of a step for the same state without
running them while the ``episode`` part compiles the reset, which then waits for it and
loads them. ``python -m twin.runners.precompile WORLD PART STEPS_DONE`` is one of them.
"""

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

WORLDS = ("physics", "kinematic")


def marker(world: str) -> Path:
    """The file that says the kernels a run in ``world`` calls are in the cache: written
    in the cache folder of this version of the kernels (``numba.config.CACHE_DIR``, which
    :mod:`twin.core.jit` names by the digest of their sources) once they are."""
    import numba

    import twin.core.jit  # noqa: F401  (sets numba.config.CACHE_DIR)

    return Path(numba.config.CACHE_DIR) / f"compiled-{world}"


def compiled(world: str) -> bool:
    """Whether this machine's kernel cache holds what a run in ``world`` calls."""
    return marker(world).is_file()


class Compilation:
    """The processes compiling the kernels of ``world`` (see the module doc): the
    ``episode`` part and the ``step`` part, one a core, started at once."""

    def __init__(self, world: str):
        if world not in WORLDS:
            raise ValueError(f"world must be one of {WORLDS}, got {world!r}")
        self.world = world
        self.error = ""
        self.cache = marker(world).parent
        self.started = time.perf_counter()
        self._parts = []
        self._folder = tempfile.TemporaryDirectory(prefix="twin-compiling-")
        steps_done = str(Path(self._folder.name) / "steps-done")
        for part in PARTS:
            log = tempfile.TemporaryFile()  # noqa: SIM115  (as long as the process)
            process = subprocess.Popen(
                [sys.executable, "-m", "twin.runners.precompile", world, part, steps_done],
                stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
            )  # fmt: skip
            self._parts.append((part, process, log))

    def wait(self) -> float | None:
        """Wait for the processes; the seconds since they started, or None where the
        ``episode`` part failed (the run then compiles what it calls itself, as it would
        have without them, and :attr:`error` holds the last line that part printed). A
        failed ``step`` part costs only time: the ``episode`` part compiles everything."""
        codes = {}
        for part, process, log in self._parts:
            codes[part] = process.wait()
            log.seek(0)
            lines = log.read().decode(errors="replace").strip().splitlines()
            log.close()
            if codes[part] != 0 and part == "episode":
                self.error = lines[-1] if lines else f"exit status {codes[part]}"
        self._folder.cleanup()
        if codes["episode"] != 0:
            return None
        return time.perf_counter() - self.started

    def stop(self) -> None:
        """End the processes that still run (the run failed or was interrupted)."""
        for _, process, log in self._parts:
            if process.poll() is None:
                process.kill()
                process.wait()
            if not log.closed:
                log.close()
        self._folder.cleanup()


def start(world: str) -> Compilation | None:
    """A :class:`Compilation` of the kernels of ``world``, or None where the cache holds
    them already."""
    return None if compiled(world) else Compilation(world)


# -- the second process --------------------------------------------------------------

WAIT_S = 180.0  # [s] the longest the episode part waits for the step part
_SPEED = 25.0  # [m/s] the hand-made vehicles' constant speed
_SECONDS = 12.0  # [s] each vehicle's recording
_RATE = 25.0  # [Hz] samples a second, as I-24 MOTION records


def _tracks(t0: float) -> list:
    """(t [s unix], x [m], y [m]) of cars in the four westbound lanes, 140 m apart around
    the ego's place at ``t0``, each at a constant speed from 2 s before it."""
    from twin.core.i24 import LANE_WIDTH

    t = t0 - 2.0 + np.arange(int(_SECONDS * _RATE)) / _RATE
    return [
        (t, x + _SPEED * (t - t0), np.full(t.size, (-lane + 0.5) * LANE_WIDTH))
        for lane in (-1, -2, -3, -4)
        for x in (420.0, 560.0, 700.0, 840.0, 980.0)
    ]


def _simulator(world: str, folder: Path):
    """A cosimulator in ``world`` on a few hand-made vehicles (a store in ``folder``),
    not reset, and its store."""
    from mapgen.build import default_map
    from twin.core.i24 import SCENARIO_TIME, Road
    from twin.cosim.config import CosimConfig
    from twin.cosim.cosimulator import Cosimulator
    from twin.data.day_files import write_day
    from twin.data.empirical import EmpiricalTraffic
    from twin.data.ingest import ingest
    from twin.data.store import TrajectoryStore

    tracks = _tracks(SCENARIO_TIME)
    n = len(tracks)
    day = write_day(folder / "day.json", Road.WESTBOUND, SCENARIO_TIME, np.arange(1, n + 1),
                    tracks, np.zeros(n, np.int64), np.tile([4.6, 1.85, 1.5], (n, 1)))  # fmt: skip
    ingest([day], folder / "store", progress=False)
    store = TrajectoryStore(folder / "store")
    config = CosimConfig(road="westbound", lane=-2, x=700.0, time=SCENARIO_TIME,
                         world=world, t_max=1.0)  # fmt: skip
    return Cosimulator(config, EmpiricalTraffic(store), default_map(progress=False)), store


def _episode(world: str, folder: Path, steps_done: Path) -> None:
    """Part ``episode``: one second of a run in ``world``, measured as a run is, so that
    every kernel a run calls is compiled on the way. It resets (compiling the reset),
    then waits until the ``step`` part says it is done (``steps_done`` exists; at most
    :data:`WAIT_S`), so that it loads the step's kernels instead of compiling them too."""
    from twin.metrics.measure import measure

    sim, store = _simulator(world, folder)
    with sim:
        sim.reset()
        deadline = time.monotonic() + WAIT_S
        while not steps_done.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        sim.run()
        measure(sim, store, 1.0, 1.0)


def _step(world: str, folder: Path, steps_done: Path) -> None:
    """Part ``step``: the kernels of a step in ``world``, compiled for the cosimulator's
    packed state without running them, while the ``episode`` part compiles the reset;
    ``steps_done`` is made when it ends, done or not."""
    import numba

    from twin.cosim.core import step

    try:
        sim, _ = _simulator(world, folder)
        with sim:
            core = numba.typeof(sim.core)
            if world == "physics":
                for kernel in (step.before_world, step.after_world):
                    kernel.compile((numba.typeof(0), core))
            else:
                step.step_batch.compile((core,))
    finally:
        steps_done.touch()


PARTS = {"episode": _episode, "step": _step}


def main(argv: list[str] | None = None) -> int:
    args = argv if argv is not None else sys.argv[1:]
    if len(args) != 3 or args[0] not in WORLDS or args[1] not in PARTS:
        print(f"usage: python -m twin.runners.precompile {{{','.join(WORLDS)}}} "
              f"{{{','.join(PARTS)}}} STEPS_DONE", file=sys.stderr)  # fmt: skip
        return 2
    world, part, steps_done = args
    with tempfile.TemporaryDirectory(prefix="twin-compile-") as folder:
        PARTS[part](world, Path(folder), Path(steps_done))
    if part == "episode":
        done = marker(world)
        partial = done.with_name(f".{done.name}.{os.getpid()}")
        partial.write_text(f"{time.time():.0f}\n")
        partial.replace(done)
    return 0


if __name__ == "__main__":
    sys.exit(main())
