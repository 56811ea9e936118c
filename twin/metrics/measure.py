"""The measurements of a finished episode: ``metrics.json`` of a run, the figures
``twin eval``, the paired benchmark and the env read (through
:mod:`twin.metrics.table`).

Sections: ``ego`` (the simulated ego against its recording), ``traffic`` (speeds and
the speed field against the recording), ``energy`` (:mod:`twin.metrics.economy`),
``control`` (:mod:`twin.metrics.wave_dampening`), ``counts``, ``lane_flows``
(:mod:`twin.metrics.lane_flow_fidelity`), ``handover`` (the ghost-cell boundary's
jumps, :mod:`twin.metrics.handover`), ``continuity`` (every record's track, whatever
it is drawn as: :mod:`twin.metrics.continuity`), ``physics`` and ``timing``.
"""

import math

import numpy as np

from twin import __version__
from twin.cosim.cosimulator import Cosimulator
from twin.data.store import TrajectoryStore
from twin.metrics import economy, fidelity, lane_flow_fidelity, wave_dampening
from twin.metrics.collisions import collision_section
from twin.metrics.continuity import continuity_section
from twin.metrics.handover import handover_section
from twin.metrics.merges import merge_section
from twin.metrics.recorded_changes import recorded_lane_changes

RUN_FORMAT = "i24-twin-run"


def measure(sim: Cosimulator, store: TrajectoryStore, loop_s: float, reset_s: float):
    """The metrics of a finished episode (``metrics.json``), and the log's frames
    (vehicles, windows, ghosts, the recorded ego, the ego's rows) for the pictures.

    Args:
        sim: the cosimulation, run to its end. store: its recording.
        loop_s, reset_s: [s] wall time of the loop and of the reset (``timing``).
    """
    cfg, log = sim.config, sim.log
    vehicles, windows, ghosts = log.vehicles(), log.windows(), log.ghosts()
    # the fidelity and control figures judge the visible window, as the recording is
    # judged there: vehicles relaxing outside it (twin.cosim.core.relax) are left out
    inside = fidelity.in_moving_window(vehicles["time"], vehicles["x"], windows)
    visible = vehicles[inside | (vehicles["role"] == 0).to_numpy()]
    recorded_ego = sim.traffic.track(cfg.road, sim.ego.tid)
    ego_rows = vehicles[vehicles["role"] == 0]
    every = max(1, round(fidelity.SAMPLE_PERIOD / cfg.dt))
    step_of = np.round(visible["time"].to_numpy() / cfg.dt).astype(np.int64)
    sampled = visible[step_of % every == 0]
    sampled_windows = windows[np.round(windows["time"] / cfg.dt).astype(np.int64) % every == 0]
    sim_s = sim.sim_time
    lengths = store.trajectory_arrays["length"]
    recorded_changes = recorded_lane_changes(store, cfg.road, sim.t0, sim.t0 + sim_s)
    figures = {
        "format": RUN_FORMAT,
        "version": __version__,
        "scenario": cfg.scenario,
        "behaviour": sim.behaviour.name,
        "road": cfg.road.value,
        "t0": sim.t0,
        "simulated_s": round(sim_s, 6),
        "ended_early": sim.counters.ended or None,
        "ego": _ego(sim, ego_rows, recorded_ego),
        "traffic": {
            **fidelity.traffic_speed_error(
                sampled[sampled["role"] == 1], sim.traffic, sim.t0, cfg.road
            ),
            "speed_field": fidelity.speed_field_metrics(
                sampled, sampled_windows, sim.traffic, cfg.road, sim.t0, sim_s
            ),
        },
        **control_sections(sim, visible, ghosts, lengths),
        "counts": _counts(sim, recorded_changes, visible, windows, sampled),
        "lane_flows": lane_flow_fidelity.episode_section(
            lane_flow_fidelity.simulated_changes(visible, cfg.dt),
            lane_flow_fidelity.recorded_changes_in_window(recorded_changes, windows, sim.t0),
            windows,
        ),
        "merges": merge_section(
            visible, lengths, [r.x_end for r in sim.world.road.ramps if r.road == cfg.road]
        ),
        "handover": handover_section(
            vehicles,
            windows,
            sim.traffic,
            cfg.road,
            sim.t0,
            cfg.dt,
            sim.limits,
            cfg.relax and cfg.anchor,
        ),
        "continuity": continuity_section(
            vehicles,
            ghosts,
            windows,
            sim.traffic,
            cfg.road,
            sim.t0,
            cfg.dt,
            1.0 / cfg.ghost_log_rate,
            sim.limits,
            store.trajectory_arrays["id"],
        ),
        "physics": _physics(sim, vehicles),
        "timing": {
            "reset_s": round(reset_s, 3),
            "loop_s": round(loop_s, 3),
            "real_time_factor": round(sim_s / loop_s, 3) if loop_s > 0 else None,
            **{k: round(v, 4) for k, v in sim.times.per_step().items()},
        },
    }
    return figures, (vehicles, windows, ghosts, recorded_ego, ego_rows)


def control_sections(sim: Cosimulator, vehicles=None, ghosts=None, lengths=None) -> dict:
    """The ``energy`` and ``control`` sections of a finished episode's metrics (what a
    controller is judged by; :func:`measure` holds them with the rest). The log's
    frames and the store's lengths are read from ``sim`` where not given."""
    cfg = sim.config
    vehicles = sim.log.vehicles() if vehicles is None else vehicles
    ghosts = sim.log.ghosts() if ghosts is None else ghosts
    lengths = sim.traffic.store.trajectory_arrays["length"] if lengths is None else lengths
    return {
        "energy": economy.run_figures(
            vehicles,
            sim.ego_id,
            sim.world.road,
            cfg.road.direction,
            lengths,
            cfg.dt,
            avs=sorted(sim.av_ids),
        ),
        "control": {
            **wave_dampening.control_figures(
                vehicles,
                ghosts,
                sim.ego_id,
                economy.followers(vehicles, sim.ego_id),
                lengths,
                cfg.dt,
            ),
            # time the baselines' safety layer overrode the ego's controller
            "safety_override_s": round(sim.manager.safety_overrides * cfg.dt, 3),
        },
    }


def _ego(sim: Cosimulator, ego_rows, recorded_ego) -> dict:
    """Who the ego is, where it was asked for and found, and how it drove against its
    recording."""
    cfg = sim.config
    return {
        "id": sim.ego_id,
        "record_id": sim.ego.id,
        "requested": {"lane": cfg.lane, "x_m": cfg.x, "time": cfg.time},
        "selected": {
            "lane": sim.ego.lane,
            "x_m": round(sim.ego.x, 3),
            "time": sim.ego.t,
            "speed_mps": round(sim.ego.speed, 3),
        },
        **fidelity.ego_metrics(ego_rows, recorded_ego, sim.t0),
        "position_error_m": fidelity.ego_position_errors(ego_rows, recorded_ego, sim.t0),
        "slow_spells": fidelity.slow_spell_timing(ego_rows, recorded_ego, sim.t0),
    }


def _counts(sim: Cosimulator, recorded_changes, vehicles, windows, sampled) -> dict:
    """Vehicles spawned and removed, and lane changes simulated against recorded."""
    counters = sim.counters
    return {
        "visible_at_start": counters.spawned_initially,
        "spawned": counters.spawned,
        "despawned": counters.despawned,
        "spawns_skipped_overlap": counters.skipped_overlap,
        "spawns_skipped_invalid": counters.skipped_invalid,
        "ghosts_yielded": counters.yielded,
        "ghosts_held": counters.held,
        "anchored": counters.anchored,
        "anchors_full": counters.anchors_full,
        "ghosts_braked": counters.ghosts_braked,
        "visible_max": int(vehicles.groupby("time").size().max()) - 1,
        "lane_changes": sim.manager.lane_changes,
        "lane_changes_recorded_in_window": fidelity.recorded_lane_changes_in_window(
            recorded_changes.time, recorded_changes.x, windows, sim.t0
        ),
        "stalled_across_lines": fidelity.stalled_across_lines(sampled, fidelity.SAMPLE_PERIOD),
        "stalled_as_recorded": fidelity.stalled_as_recorded(
            sampled, fidelity.SAMPLE_PERIOD, sim.traffic, sim.t0, sim.config.road
        ),
    }


def _physics(sim: Cosimulator, vehicles) -> dict:
    """The physical checks: spawn speeds, collisions (explained,
    :mod:`twin.metrics.collisions`), vehicles off the road."""
    counters = sim.counters
    errors = np.array(counters.spawn_speed_error)
    return {
        "spawns_checked": int(errors.size),
        "spawn_speed_error_max": _round(errors.max()) if errors.size else None,
        "spawn_speed_error_median": _round(np.median(errors)) if errors.size else None,
        "spawns_above_0.5_percent": int(np.count_nonzero(errors > 0.005)),
        **collision_section(
            counters.collisions, vehicles, counters.contacts, counters.collisions_unlisted
        ),
        "vehicles_off_road": counters.off_road,
    }


def _round(value: float) -> float:
    return round(float(value), 6) if math.isfinite(value) else None
