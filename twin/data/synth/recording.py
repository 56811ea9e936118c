"""A synthetic day recorded as I-24 MOTION records one: the vehicles in view,
resampled at the camera rate with tracking noise, written in the real JSON layout."""

import math
import os
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from twin.core.progress import progress_bar
from twin.data.day_files import write_day
from twin.data.synth.config import SynthConfig
from twin.data.synth.simulation import Simulation
from twin.traffic.drivers import DriverTraits


@dataclass
class SynthResult:
    """Recorded trajectories (struct-of-arrays per vehicle) and counters."""

    config: SynthConfig
    vid: np.ndarray  # (m,) vehicle ids
    tracks: list  # per vehicle: (t, x, y) arrays at the recording rate, noise added
    vehicle_class: np.ndarray
    dimensions: np.ndarray  # (m, 3) [m]
    drivers: DriverTraits  # (m,) each: the traits drawn for each vehicle
    lane_changes: int
    collisions: int


def synthesize(config: SynthConfig, *, progress: bool = False) -> SynthResult:
    """Run the microsimulation and return the recorded tracks (deterministic by seed)."""
    rng = np.random.default_rng(config.seed)
    sim = Simulation(config, rng)
    t0 = config.start - config.warmup
    sim.populate()
    n_steps = math.ceil((config.end - t0) / config.dt) + 1
    events = sorted(config.slowdowns, key=lambda s: s.t)
    lo, hi = config.x_record
    rec_vid, rec_step, rec_x, rec_y = [], [], [], []
    record_from = math.floor((config.start - t0) / config.dt) - 1
    for k in progress_bar(
        range(n_steps), progress=progress, desc=f"synth {config.road.value}", leave=False
    ):
        sim.t = t0 + k * config.dt
        while events and config.anchor + events[0].t <= sim.t:
            sim.trigger(events.pop(0))
        if k >= record_from:
            veh = sim.vehicles
            seen = (veh.x >= lo) & (veh.x <= hi)
            rec_vid.append(veh.vid[seen])
            rec_step.append(np.full(int(seen.sum()), k, np.int32))
            rec_x.append(veh.x[seen])
            rec_y.append(sim.lateral()[seen].astype(np.float32))
        sim.step()
    vid = np.concatenate(rec_vid)
    order = np.argsort(vid, kind="stable")
    vid, step = vid[order], np.concatenate(rec_step)[order]
    x, y = np.concatenate(rec_x)[order], np.concatenate(rec_y)[order]
    return _resample(config, sim, rng, t0, vid, step, x, y)


def _resample(config, sim, rng, t0, vid, step, x, y) -> SynthResult:
    """Tracks at the recording rate with a per-vehicle phase and tracking noise."""
    starts = np.flatnonzero(np.r_[True, vid[1:] != vid[:-1]])
    ends = np.r_[starts[1:], len(vid)]
    ids, tracks = [], []
    for a, b in zip(starts, ends, strict=True):
        track = camera_track(config, rng, t0 + step[a:b] * config.dt, x[a:b], y[a:b])
        if track is not None:
            ids.append(int(vid[a]))
            tracks.append(track)
    ids = np.array(ids, dtype=np.int64)
    drivers = DriverTraits(
        *(
            np.concatenate([getattr(batch, name) for batch in sim.registry_drivers])[ids]
            for name in (f.name for f in fields(DriverTraits))
        )
    )
    return SynthResult(
        config=config,
        vid=ids,
        tracks=tracks,
        vehicle_class=np.concatenate(sim.registry_class)[ids],
        dimensions=np.concatenate(sim.registry_dims)[ids],
        drivers=drivers,
        lane_changes=sim.lane_changes,
        collisions=sim.collisions,
    )


def camera_track(config: SynthConfig, rng, t_steps, x, y):
    """One vehicle's simulated positions (x, y [m] at unix ``t_steps`` [s]) as the cameras
    record them: at ``config.sample_rate`` with a phase of its own inside the recorded
    times, with ``config.position_noise``; (t, x, y), or None where fewer than two
    samples fall inside."""
    period = 1.0 / config.sample_rate
    phase = rng.uniform(0, period)
    first = math.ceil((max(t_steps[0], config.start) - config.start - phase) / period)
    last = math.floor((min(t_steps[-1], config.end) - config.start - phase) / period)
    if last - first < 1:
        return None
    t = config.start + phase + np.arange(first, last + 1) * period
    xs = np.interp(t, t_steps, x) + config.position_noise * rng.standard_normal(len(t))
    ys = np.interp(t, t_steps, y) + config.position_noise * rng.standard_normal(len(t))
    return t, xs, ys


def write_i24_json(result: SynthResult, path: str | os.PathLike, *, progress: bool = False) -> Path:
    """Write the tracks as an I-24 MOTION day file (a JSON array of documents;
    :func:`twin.data.day_files.write_day`)."""
    cfg = result.config
    return write_day(path, cfg.road, cfg.anchor, result.vid, result.tracks,
                     result.vehicle_class, result.dimensions, progress=progress)  # fmt: skip
