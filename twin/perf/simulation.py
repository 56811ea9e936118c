"""Benchmarks of the simulation: the map build, the physics step, the traffic
manager in a closed loop, and the whole cosimulation loop of a paper scenario."""

import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from twin.data.empirical import EmpiricalTraffic
from twin.perf.common import (
    DT,
    class_mix,
    dimensions,
    median,
    ms,
    seconds_per_call,
    store_or_default,
    timed,
)

WARM_UP_STEPS = 20  # physics steps before the physics bench times any
SETTLING_STEPS = 200  # closed-loop steps (2 s) before the traffic bench times any
LANE_SPEEDS = (24.0, 27.0, 30.0, 33.0)  # [m/s] one a lane, so that no vehicle catches up


def map_bench(*, repeats: int = 5) -> dict:
    """Time of a full map build (sources to files on disk, no cache) and its size."""
    from mapgen.build import build_map

    seconds = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(repeats):
            bundle, elapsed = timed(build_map, Path(tmp) / "map", seed=seed)
            seconds.append(elapsed)
        glb_mb = (bundle.folder / "scene.glb").stat().st_size / 1e6
    return {
        "median_s": round(median(seconds), 3),
        "target_s": 10,
        "triangles_visual": bundle.description["triangles"]["visual"],
        "triangles_collision": bundle.description["triangles"]["collision"],
        "triangles_per_part": {part.name: part.triangles for part in bundle.parts},
        "glb_mb": round(glb_mb, 2),
        "repeats": repeats,
    }


def physics_bench(*, counts=(100, 200), steps: int = 500, repeats: int = 3) -> dict:
    """Wall time of one physics step (rays, vehicle model, engine step, state read-back)
    with n vehicles of the corridor's class mix in the four lanes of both carriageways
    of the I-24 mesh, holding their speed (a vehicle collision would make the engine's
    contact solver part of the figure)."""
    from mapgen.build import default_map
    from twin.core.vehicle_classes import vehicle_classes

    table = vehicle_classes()
    bundle = default_map()
    figures = {}
    for n in counts:
        medians = []
        for repeat in range(repeats):
            states = _both_carriageways(table, np.random.default_rng(repeat), n)
            medians.append(median(_step_seconds(bundle, states, steps)))
        step = median(medians)
        figures[f"vehicles_{n}"] = {"step_ms": ms(step, 3), "real_time_factor": round(DT / step, 2)}
    figures["targets"] = {"vehicles_100": ">= 10 x (<= 1 ms)", "vehicles_200": ">= 5 x"}
    figures.update({"dt": DT, "steps": steps, "repeats": repeats})
    return figures


def _both_carriageways(table, rng: np.random.Generator, n: int):
    """Spawn states of ``n`` vehicles, four a carriageway in turn, spread over 1900 m
    from station -350 m, each lane at its own speed."""
    from twin.core.i24 import LANE_WIDTH
    from twin.physics.states import SpawnStates

    lane = np.arange(n) % 4
    classes = class_mix(table, rng, n)
    return SpawnStates.make(
        np.where(np.arange(n) % 8 < 4, 1, -1),
        -350.0 + (np.arange(n) // 8) * (1900.0 / max(1, n // 8)),
        (1.5 + lane) * LANE_WIDTH,
        np.array(LANE_SPEEDS)[lane],
        classes,
        *dimensions(table, classes),
    )


def _step_seconds(bundle, states, steps: int) -> np.ndarray:
    """Wall time [s] of each of ``steps`` physics steps with their state read-back, after
    a warm-up, of the vehicles of ``states`` holding their speed: shape (steps,)."""
    from twin.physics.world import PhysicsWorld

    with PhysicsWorld(bundle) as world:
        world.spawn(states)
        world.set_controls(accel=np.zeros(states.x.size))
        for _ in range(WARM_UP_STEPS):
            _step_and_read(world)
        return seconds_per_call(_step_and_read, [(world,)] * steps)


def _step_and_read(world) -> None:
    world.step()
    world.states()


def traffic_bench(*, vehicles: int = 100, steps: int = 3000, repeats: int = 3) -> dict:
    """The traffic manager's decision step and the closed loop (manager, controls,
    physics, state read-back) for ``vehicles`` on the I-24 mesh, in a circuit.

    Each repeat runs ``steps`` closed-loop steps after 2 s of settling; the figures
    are medians over steps, then over repeats. The decision step is also given as a
    mean and 99th percentile, since MOBIL runs only on the steps where a driver is
    due to decide.
    """
    from mapgen.build import default_map

    bundle = default_map()
    headings = {r: bundle.road.heading(r) for r in (1, -1)}
    decision, loop, means, p99 = [], [], [], []
    for repeat in range(repeats):
        manager_s, loop_s, lane_changes = _closed_loop(bundle, headings, vehicles, steps, repeat)
        decision.append(median(manager_s))
        means.append(float(np.mean(manager_s)))
        p99.append(float(np.percentile(manager_s, 99)))
        loop.append(median(loop_s))
    step = median(loop)
    return {
        "vehicles": vehicles,
        "decision_ms": ms(median(decision), 3),
        "decision_mean_ms": ms(median(means), 3),
        "decision_p99_ms": ms(median(p99), 3),
        "closed_loop_ms": ms(step, 3),
        "real_time_factor": round(DT / step, 2),
        "lane_changes_per_repeat": lane_changes,
        "targets": {"decision_ms": "<= 0.3", "real_time_factor": ">= 5"},
        "dt": DT,
        "steps": steps,
        "repeats": repeats,
    }


def _closed_loop(bundle, headings: dict, vehicles: int, steps: int, seed: int):
    """One repeat of the traffic bench: the wall times [s] of the manager's decision and
    of the whole closed-loop step, shape (steps,) each, and the lane changes made."""
    from twin.physics.world import PhysicsWorld
    from twin.traffic.circuit import Circuit, CircuitSpec
    from twin.traffic.manager import TrafficConfig, TrafficManager

    with PhysicsWorld(bundle) as world:
        manager = TrafficManager(TrafficConfig(seed=seed), headings)
        circuit = Circuit(world, manager, CircuitSpec(vehicles=vehicles, seed=seed))
        manager_s, loop_s = np.empty(steps), np.empty(steps)
        for k in range(-SETTLING_STEPS, steps):
            start = time.perf_counter()
            states = world.states()
            middle = time.perf_counter()
            commands = manager.step(states)
            end = time.perf_counter()
            world.set_controls(commands.id, accel=commands.accel, steer=commands.steer)
            world.step()
            circuit.recycle(states)
            if k >= 0:
                manager_s[k] = end - middle
                loop_s[k] = time.perf_counter() - start
    return manager_s, loop_s, manager.lane_changes


def run_bench(store=None, *, scenario: str = "B", repeats: int = 3, world: str = "physics",
              duration: float | None = None, sumo: bool = False) -> dict:  # fmt: skip
    """The whole cosimulation loop of a paper scenario on the embedded data, without
    cameras or output files: data queries, desired speeds, traffic manager, physics,
    despawns, spawns, ghost reload and the trajectory log, per step (medians of the
    repeats' means, each repeat a fresh episode with its own seed), in the ``world``
    (its default step) over ``duration`` [s] (default: the scenario's). The loop's wall
    time is ``loop_s``; the kinematic world's step is one kernel call, so its parts
    (ghosts, physics, manager) are not timed apart.

    With ``sumo``, the first repeat's episode is also written as a run folder, exported
    to SUMO (``twin export --format sumo``: the same vehicles entering where and when
    they do in the twin) and run by ``sumo`` (eclipse-sumo) from start-up to its end;
    ``sumo_s`` is SUMO's wall time and ``sumo_over_twin`` its ratio to the twin's loop."""
    from mapgen.build import default_map
    from twin.cosim.config import PRESETS, switch_world

    traffic = EmpiricalTraffic(store_or_default(store))
    bundle = default_map()
    base = switch_world(PRESETS[scenario], world)
    if duration is not None:
        base = replace(base, t_max=float(duration))
    figures = [_episode(replace(base, seed=repeat), traffic, bundle) for repeat in range(repeats)]

    def median_of(name):
        return median([f[name] for f in figures])

    step = median_of("step_ms")
    out = {
        "scenario": scenario,
        "world": world,
        "step_ms": round(step, 3),
        "loop_s": float(f"{median_of('loop_s'):.4g}"),  # figures, not decimals: ~2 ms here
        "real_time_factor": round(median_of("real_time_factor"), 2),
        "vehicles_mean": round(median_of("vehicles_mean"), 1),
        "targets": {"real_time_factor": ">= 3"},
        "dt": base.dt,
        "t_max": base.t_max,
        "repeats": repeats,
    }
    if world == "physics":
        out.update({
            "ghost_reload_ms": round(median_of("ghost_reload_ms"), 4),
            "ghost_reload_share": round(median_of("ghost_reload_ms") / step, 4),
            "physics_ms": round(median_of("physics_ms"), 3),
            "manager_ms": round(median_of("manager_ms"), 3),
        })  # fmt: skip
        out["targets"]["ghost_reload_share"] = "<= 0.05"
    else:
        out["targets"]["loop_s"] = "<= 0.1"
    if sumo:
        out.update(_against_sumo(replace(base, seed=0), traffic.store, bundle))
        ratio = out["sumo_s"] / median_of("loop_s")  # the loop unrounded
        out["sumo_over_twin"] = float(f"{ratio:.3g}")  # three figures at any size
    return out


def _against_sumo(config, store, bundle) -> dict:
    """[s] SUMO's wall time for the episode of ``config`` exported (module doc of
    :func:`run_bench`), and the vehicles it drove."""
    import subprocess

    from twin.export.sumo import export_run, sumo_home
    from twin.runners.run import run_episode

    with tempfile.TemporaryDirectory(prefix="twin-bench-sumo-") as tmp:
        run_episode(config, store, Path(tmp) / "run", bundle=bundle, progress=False)
        exported = export_run(Path(tmp) / "run", Path(tmp) / "sumo", bundle)
        home = sumo_home()
        command = [str(home / "bin" / "sumo"), "-c", str(Path(tmp) / "sumo" / "i24.sumocfg"),
                   "--no-step-log", "true", "--no-warnings", "true"]  # fmt: skip
        start = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True,
                              env={"SUMO_HOME": str(home)})  # fmt: skip
        seconds = time.perf_counter() - start
        if done.returncode != 0:
            raise RuntimeError(f"sumo failed: {done.stderr.strip()[-500:]}")
    return {"sumo_s": round(seconds, 4), "sumo_vehicles": exported["vehicles"]}


def _episode(config, traffic, bundle) -> dict:
    """One repeat of the run bench: the cosimulator's mean times per step [ms], the real
    time factor and the mean number of vehicles of an episode of ``config``."""
    from twin.cosim.cosimulator import Cosimulator

    with Cosimulator(config, traffic, bundle) as sim:
        sim.reset()
        _, wall = timed(sim.run)
        figures = sim.times.per_step()
        figures["loop_s"] = wall
        figures["real_time_factor"] = sim.sim_time / wall
        figures["vehicles_mean"] = float(np.mean(sim.log.vehicles().groupby("time").size()))
    return figures
