"""The dataset's motion check: a labelled vehicle's box never moves between two frames
of one camera by more than its speed allows (the ``motion`` block of
``manifest.json``).

A vehicle is followed by its recording (``record_id``), as its instance id follows it
too (one per recorded vehicle all episode long, simulated or replayed:
:meth:`sensors.camera.CameraRig.capture`). Between two frames of one camera in
which it is labelled, its box's bottom centre moves (in the world, from
``location_m`` through ``world_from_camera``) by at most ``max(v1, v2) dt +
ALLOWED_ACCEL dt^2 / 2 + SLACK_M``, with its labelled speeds
``v1``, ``v2`` [m/s] and the time ``dt`` between the frames: more than that is a jump
no vehicle can make, such as the seam of the ghost-cell boundary (``docs/cosim.md``).
"""

from itertools import pairwise

import numpy as np

ALLOWED_ACCEL = 10.0  # [m/s^2] beyond any tyre's grip
SLACK_M = 0.1  # [m] the labels' rounding and the box's pitch on a grade


def motion_check(labels: list[dict]) -> dict:
    """The motion check over a dataset's label records (one per frame and camera:
    ``episode``, ``camera``, ``sim_time`` [s], ``world_from_camera`` (4 x 4) and
    ``vehicles`` with ``record_id``, ``location_m`` and ``speed_mps``).

    Returns:
        ``pairs`` (consecutive labels of one vehicle checked), ``violations`` (those
        that moved more than allowed), ``max_excess_m`` (the largest move beyond what
        was allowed; negative where every move was allowed; None without pairs).
    """
    tracks: dict[tuple, list] = {}
    for record in labels:
        world_from_camera = np.asarray(record["world_from_camera"], dtype=np.float64)
        for vehicle in record["vehicles"]:
            if vehicle.get("record_id") is None:
                continue
            key = (record["episode"], record["camera"], vehicle["record_id"])
            where = world_from_camera @ np.append(np.asarray(vehicle["location_m"], float), 1.0)
            tracks.setdefault(key, []).append(
                (float(record["sim_time"]), where[:3], float(vehicle["speed_mps"]))
            )
    pairs, violations, worst = 0, 0, -np.inf
    for track in tracks.values():
        track.sort(key=lambda sample: sample[0])
        for (t1, p1, v1), (t2, p2, v2) in pairwise(track):
            dt = t2 - t1
            if dt <= 0.0:
                continue
            allowed = max(v1, v2) * dt + 0.5 * ALLOWED_ACCEL * dt * dt + SLACK_M
            excess = float(np.linalg.norm(p2 - p1)) - allowed
            pairs += 1
            violations += excess > 0.0
            worst = max(worst, excess)
    return {
        "pairs": pairs,
        "violations": int(violations),
        "max_excess_m": round(worst, 3) if pairs else None,
    }
