"""The trajectory log of a run: every simulated vehicle every step, ghosts at a lower rate.

Rows are appended per step as arrays (no per-vehicle Python work in the loop) and
joined once at the end into one table, ``trajectories.parquet`` of the run folder:

========== ======= ==========================================================
column     type    meaning
========== ======= ==========================================================
time       float64 [s] since t0 (the ego's recorded time)
id         int64   the twin's vehicle id (-1 for ghosts, which have no body)
record_id  string  I-24 MOTION ``_id`` of the recorded vehicle it stands for
role       string  ``ego``, ``visible`` or ``ghost``
road       int8    +1 eastbound, -1 westbound
lane       int8    -1 (HOV) .. -4 (0: outside the lanes)
x, y       float64 [m] road frame: back centre along travel, centre from the median
z          float64 [m] world elevation of the centre of mass (ghosts: of the box centre)
speed      float64 [m/s] along the heading
accel      float64 [m/s^2] measured (speed change over the last step; NaN on a
                   vehicle's first row and for ghosts)
accel_cmd  float64 [m/s^2] what the driver commanded (NaN for ghosts)
grade      float64 [-] the road's grade under the vehicle's centre along travel (rise
                   over run, from the map)
drive_power float64 [W] what the twin's powertrain delivered at the wheels in the
                   step (drive torque times wheel spin; NaN for ghosts)
fuel_rate  float64 [g/s] fuel of the CIRCLES RAV4 model at the realised speed,
                   acceleration and grade (:mod:`twin.physics.energy`; NaN where ``accel`` is)
fuel_feasible bool the acceleration is within what that powertrain can deliver (null
                   for ghosts)
heading    float64 [rad] world yaw (ghosts: the road's)
vehicle_class int8 index into ``twin.core.i24.VEHICLE_CLASSES``
length, width, height float32 [m]
========== ======= ==========================================================
"""

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from twin.physics import energy

ROLES = ("ego", "visible", "ghost")
_VEHICLE = (
    "time", "id", "tid", "role", "lane", "x", "y", "z", "speed", "accel_cmd", "heading",
    "drive_power",
)  # fmt: skip
_GHOST = ("time", "tid", "lane", "x", "y", "speed")


class TrajectoryLog:
    """Per-step records of a run (see the module doc).

    Args:
        t0: [s] unix time of the run's start.
        road: +1 or -1, the carriageway of the run.
        dt: [s] the step (to tell consecutive rows of a vehicle).
    """

    def __init__(self, t0: float, road: int, dt: float):
        self.t0, self.road, self.dt = t0, road, dt
        self._vehicles = {name: [] for name in _VEHICLE}
        self._ghosts = {name: [] for name in _GHOST}
        self._windows = []  # (time, ghost_back0, visible0, visible1, ghost_front1) per step

    def add_rows(self, *, time, id, tid, ego_id, lane, x, y, z, speed, accel_cmd, heading,
                 drive_power) -> None:  # fmt: skip
        """Append vehicles' rows at ``time`` [s since t0] from arrays (n,) (the core's
        log; ``id`` in increasing order)."""
        n = np.asarray(id).size
        v = self._vehicles
        v["time"].append(np.full(n, time))
        v["id"].append(np.asarray(id, dtype=np.int64))
        v["tid"].append(np.asarray(tid, dtype=np.int64))
        v["role"].append(np.where(np.asarray(id) == ego_id, 0, 1).astype(np.int8))
        v["lane"].append(np.asarray(lane, dtype=np.int8))
        for name, value in (("x", x), ("y", y), ("z", z), ("speed", speed),
                            ("accel_cmd", accel_cmd), ("heading", heading),
                            ("drive_power", drive_power)):  # fmt: skip
            v[name].append(np.asarray(value, dtype=np.float64))

    def add_window_bounds(self, time: float, g0: float, x0: float, x1: float, g1: float) -> None:
        """Append the windows in force at ``time``: rear ghost start, visible start and
        end, front ghost end [m]."""
        self._windows.append((time, float(g0), float(x0), float(x1), float(g1)))

    def add_ghost_rows(self, time: float, tid, lane, x, y, speed) -> None:
        """Append the ghost set at ``time`` from arrays (k,)."""
        g = self._ghosts
        g["time"].append(np.full(np.asarray(tid).size, time))
        for name, value in (("tid", tid), ("lane", lane), ("x", x), ("y", y), ("speed", speed)):
            g[name].append(np.asarray(value))

    def windows(self) -> pd.DataFrame:
        """Per step: ``time``, ``g0`` (back end of the rear ghost window), ``x0``, ``x1``
        (the visible window), ``g1`` (front end of the front ghost window), [m]."""
        return pd.DataFrame(self._windows, columns=["time", "g0", "x0", "x1", "g1"])

    def vehicles(self) -> pd.DataFrame:
        """The simulated vehicles' rows, with the measured acceleration."""
        frame = pd.DataFrame({k: _join(v, k) for k, v in self._vehicles.items()})
        order = np.lexsort((frame["time"].to_numpy(), frame["id"].to_numpy()))
        ids, times = frame["id"].to_numpy()[order], frame["time"].to_numpy()[order]
        speed = frame["speed"].to_numpy()[order]
        accel = np.full(len(frame), np.nan)
        follows = np.r_[False, (ids[1:] == ids[:-1]) & (np.diff(times) < 1.5 * self.dt)]
        accel_sorted = np.full(len(frame), np.nan)
        accel_sorted[1:] = np.diff(speed) / np.maximum(np.diff(times), 1e-12)
        accel[order] = np.where(follows, accel_sorted, np.nan)
        frame["accel"] = accel
        return frame

    def ghosts(self) -> pd.DataFrame:
        """The ghost rows (at the configured rate)."""
        return pd.DataFrame({k: _join(v, k) for k, v in self._ghosts.items()})

    def table(self, record_ids: np.ndarray, road_model, vehicle_meta: dict) -> pa.Table:
        """The log as one Arrow table (the module doc's columns).

        Args:
            record_ids: I-24 ``_id`` per store tid.
            road_model: the map's ``RoadModel`` (ghosts' elevation and heading).
            vehicle_meta: per store tid arrays ``vehicle_class``, ``length``,
                ``width``, ``height``.
        """
        sim = self.vehicles()
        ghosts = self.ghosts()
        tid = sim["tid"].to_numpy()
        ghost_tid = ghosts["tid"].to_numpy().astype(np.int64)
        n = len(ghosts)
        road = np.full(n, self.road, dtype=np.int8)
        if n:
            center = ghosts["x"].to_numpy() + 0.5 * vehicle_meta["length"][ghost_tid]
            ground, heading, pitch = road_model.to_world(road, center, ghosts["y"].to_numpy())
            ghost_z = ground[:, 2] + 0.5 * vehicle_meta["height"][ghost_tid]
        else:
            ghost_z, heading, pitch = np.empty(0), np.empty(0), np.empty(0)
        fuel = energy.log_rows(sim, road_model, self.road, vehicle_meta["length"])
        role = np.concatenate([sim["role"].to_numpy(), np.full(n, 2, np.int8)])
        columns = {
            "time": np.concatenate([sim["time"], ghosts["time"]]),
            "id": np.concatenate([sim["id"], np.full(n, -1)]).astype(np.int64),
            "record_id": record_ids[np.concatenate([tid, ghosts["tid"]]).astype(np.int64)],
            "role": pa.DictionaryArray.from_arrays(
                pa.array(role.astype(np.int32)), pa.array(list(ROLES))
            ),
            "road": np.full(len(sim) + n, self.road, dtype=np.int8),
            "lane": np.concatenate([sim["lane"], ghosts["lane"]]).astype(np.int8),
            "x": np.concatenate([sim["x"], ghosts["x"]]),
            "y": np.concatenate([sim["y"], ghosts["y"]]),
            "z": np.concatenate([sim["z"], ghost_z]),
            "speed": np.concatenate([sim["speed"], ghosts["speed"]]),
            "accel": np.concatenate([sim["accel"], np.full(n, np.nan)]),
            "accel_cmd": np.concatenate([sim["accel_cmd"], np.full(n, np.nan)]),
            "heading": np.concatenate([sim["heading"], heading]),
            "grade": np.concatenate([fuel["grade"], np.tan(pitch)]),
            "drive_power": np.concatenate([sim["drive_power"], np.full(n, np.nan)]),
            "fuel_rate": np.concatenate([fuel["fuel_rate"], np.full(n, np.nan)]),
            "fuel_feasible": pa.array(
                np.concatenate([fuel["feasible"].to_numpy(), np.ones(n, dtype=bool)]),
                mask=np.r_[np.zeros(len(sim), dtype=bool), np.ones(n, dtype=bool)],
            ),
        }
        all_tid = np.concatenate([tid, ghosts["tid"]]).astype(np.int64)
        columns["vehicle_class"] = vehicle_meta["vehicle_class"][all_tid].astype(np.int8)
        for name in ("length", "width", "height"):
            columns[name] = vehicle_meta[name][all_tid].astype(np.float32)
        table = pa.table(
            {k: v if isinstance(v, pa.Array) else pa.array(v) for k, v in columns.items()}
        )
        order = np.lexsort((table["id"].to_numpy(), role, table["time"].to_numpy()))
        return table.take(pa.array(order))


def write_parquet(table: pa.Table, path, metadata: dict[str, str]) -> None:
    """Write ``table`` with file-level key/value ``metadata`` (zstd, row groups of 1M)."""
    schema_meta = {
        **(table.schema.metadata or {}),
        **{k.encode(): v.encode() for k, v in metadata.items()},
    }
    pq.write_table(
        table.replace_schema_metadata(schema_meta),
        path,
        compression="zstd",
        row_group_size=1_000_000,
    )


def _join(parts: list, name: str) -> np.ndarray:
    if parts:
        return np.concatenate(parts)
    return np.empty(0, dtype=np.int64 if name in ("id", "tid") else np.float64)
