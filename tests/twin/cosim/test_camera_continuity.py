"""The cameras see the boundary as the log does (issue 76): one instance id per
recorded vehicle all episode long, simulated or replayed, and its labelled box moving
as its speed allows through both edges of the visible window (physics world, the
TinyRenderer)."""

from itertools import pairwise

import numpy as np
import pytest

from sensors.camera import CameraRig, CameraSpec
from sensors.labels import frame_labels, model_triangles
from sensors.replay import FrameTraffic
from tests.twin.cosim.scenes import EGO_X, T0, tid_of, vehicle
from twin.core import i24

# a narrow camera: the windows' edges (30 m ahead, the ghost window 50 m beyond) are
# many pixels wide at this resolution
CAMERA = CameraSpec(width=192, height=96, hfov_deg=30.0, far=150.0, rate_hz=10.0)
JUMP = 0.5  # [m] beyond the labelled motion


def _dipping(n: int, lane: int, x: float, speed: float, dip: float):
    """A document at ``speed`` [m/s] but for a dip to ``dip`` from T0 + 0.5 s: down at
    4 m/s^2, held 1 s, back up at 2 m/s^2 (its back at ``x`` [m] at T0 all the same;
    ``dip == speed``: none)."""
    doc = vehicle(n, lane, x, speed)
    t = np.asarray(doc["timestamp"]) - T0
    down, up = (speed - dip) / 4.0 + 1e-6, (speed - dip) / 2.0 + 1e-6
    v = np.interp(t, [0.5, 0.5 + down, 1.5 + down, 1.5 + down + up], [speed, dip, dip, speed])
    travelled = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    travelled -= np.interp(0.0, t, travelled)
    x_ft = np.asarray(doc["x_position"])
    at_t0 = np.interp(0.0, t, x_ft + np.sign(x_ft[-1] - x_ft[0]) * speed * t / i24.FT)
    doc["x_position"] = (at_t0 + np.sign(x_ft[-1] - x_ft[0]) * travelled / i24.FT).tolist()
    doc["starting_x"], doc["ending_x"] = doc["x_position"][0], doc["x_position"][-1]
    return doc


def _tracks(sim, bundle):
    """Per record, its labels over the run: (sim time, world position, speed, id, replayed)."""
    rig = CameraRig(sim.world, bundle, (CAMERA,), "tiny", sim.config.dt, sun="noon", shadows=False)
    traffic = FrameTraffic(sim, bundle.road, CAMERA.far)
    models = model_triangles(bundle)
    tracks: dict[str, list] = {}
    try:
        while not sim.done:
            if rig.due(sim.step_index):
                (frame,) = rig.capture(sim.ego_id, time=sim.t, sim_time=sim.sim_time,
                                       traffic=traffic)  # fmt: skip
                labels = frame_labels(frame, models)
                vehicles = frame.vehicles
                for i, vid in enumerate(labels.id.tolist()):
                    (k,) = np.flatnonzero(vehicles.id == vid)
                    where = frame.world_from_camera @ np.append(labels.location[i], 1.0)
                    tracks.setdefault(vehicles.record_id[k], []).append(
                        (frame.sim_time, where[:3], float(labels.speed[i]), vid,
                         bool(vehicles.replayed[k]))
                    )  # fmt: skip
            sim.step()
    finally:
        rig.close()
    return tracks


@pytest.mark.parametrize(
    "anchor, dip",
    [
        (False, 26.0),  # no dip: it drives as recorded, handed back on its recording
        (True, 16.0),  # ends 20 m past the window, anchored tens of metres off it
    ],
)
def test_a_vehicle_keeps_its_instance_id_and_its_motion_through_both_edges(
    cosim, built_map, anchor, dip
):
    # the ego held at 20 m/s. One recorded vehicle in the visible window (30 m each
    # way) at 26 m/s, where its simulated driver wants 26 m/s: it passes the ego and
    # leaves the window's front edge. Its recording dips to ``dip`` while it is
    # simulated, which its driver does not see: it leaves far ahead of its recording
    # and relaxes toward it, and ends at the simulated region's edge (20 m on),
    # anchored. One in the ghost cell at 15 m/s, which the window reaches: spawned
    sim = cosim(
        [vehicle(1, -2, EGO_X, 20.0), _dipping(2, -3, EGO_X - 20.0, 26.0, dip),
         vehicle(3, -4, EGO_X + 60.0, 15.0)],
        world="physics", t_max=16.0, w_visible=30.0, w_ghost=20.0, anchor=anchor,
        vel_default=26.0,
    )  # fmt: skip
    assert sim.config.relax
    tracks = _tracks(sim, built_map)
    records = sim.traffic.store.trajectory_arrays["id"]
    leaving, entering = (tracks[records[tid_of(sim, n)]] for n in (2, 3))
    for track, before, after in ((leaving, False, True), (entering, True, False)):
        sources = [replayed for *_, replayed in track]
        assert sources[0] is before and sources[-1] is after  # it crossed an edge
        assert len({vid for *_, vid, _ in track}) == 1  # one instance id throughout
        for (t1, p1, v1, *_), (t2, p2, v2, *_) in pairwise(track):
            if t2 - t1 > 1.5 / CAMERA.rate_hz:
                continue  # not labelled between (hidden behind another, out of view)
            moved = float(np.linalg.norm(p2 - p1))
            assert moved - 0.5 * (v1 + v2) * (t2 - t1) <= JUMP, (t1, moved)
    assert sim.counters.anchored == (1 if anchor else 0)
