"""The kinematic world's motion, the footprint collisions and the fuel model as compiled
kernels over struct-of-arrays with a leading episode axis (the batched core's
physics; :mod:`twin.physics.kinematic` is the same model behind the
:class:`~twin.physics.worlds.World` interface, and its doc gives the model).

* :data:`Bodies` (B, N): each slot's pose and motion in the road frame (``x`` the back
  centre, ``y``, ``yaw`` against travel, ``speed``, ``yaw_rate``), what the map puts
  under it (``z`` of the centre of mass, the ``grade`` [-] along travel), its lane, the power its
  drive delivered over the last step, and its physical parameters (from
  :class:`~twin.physics.vehicle.VehicleParams`, :func:`body_columns`).
* :data:`Profile`: the road's elevation profile along the segment and its frame.

:func:`integrate` steps one episode's bodies by dt under their commanded
accelerations and steering angles; :func:`place` sets ``z``, ``grade`` and ``lane``
from the pose; :func:`overlaps` finds the footprints that overlap.
"""

import math
from collections import namedtuple

import numpy as np

from twin.core.i24 import SEGMENT_LENGTH
from twin.core.jit import kernel
from twin.core.ramps import lane_of_y as lane_of
from twin.physics.energy import RAV4_2019, FuelModel
from twin.physics.vehicle import (
    AIR_DENSITY,
    BRAKE_LOCK_MARGIN,
    GRAVITY,
    POWER_SPEED_MIN,
    ROLLING_SPEED,
    VehicleParams,
)

#: Parameter columns of a body, in :data:`Bodies` after the state's fields.
PARAMETERS = (
    "vehicle_class", "length", "width", "height", "mass", "eff_mass", "max_power",
    "drag_area", "rolling", "mu", "driven_share", "wheelbase", "cg_height", "wheel_radius",
)  # fmt: skip
STATE = (
    "valid", "top", "id", "x", "y", "yaw", "speed", "yaw_rate", "z", "grade", "lane", "drive_power"
)  # fmt: skip
Bodies = namedtuple("Bodies", STATE + PARAMETERS)
Profile = namedtuple("Profile", "road stations heights slopes spacing")


def bodies(b: int, n: int) -> Bodies:
    """Empty bodies of ``b`` episodes with ``n`` slots."""
    ints = ("id", "lane", "vehicle_class")
    arrays = {
        name: np.zeros((b, n), bool if name == "valid" else (np.int64 if name in ints else float))
        for name in Bodies._fields
    }
    arrays["top"] = np.zeros(b, np.int64)  # one past the highest valid slot
    return Bodies(**arrays)


def body_columns(params: VehicleParams) -> dict[str, np.ndarray]:
    """(n,) each of :data:`PARAMETERS` of vehicles with ``params``."""
    return {
        "vehicle_class": np.asarray(params.vehicle_class, np.int64),
        "length": params.length,
        "width": params.width,
        "height": params.height,
        "mass": params.mass,
        "eff_mass": params.effective_mass,
        "max_power": params.max_power,
        "drag_area": params.drag_area,
        "rolling": params.rolling,
        "mu": params.mu,
        "driven_share": params.driven.sum(axis=1) / 4.0,
        "wheelbase": params.mounts[:, 0, 0] - params.mounts[:, 2, 0],
        "cg_height": params.cg_height,
        "wheel_radius": params.wheel_radius,
    }


def profile(road_model, road: int) -> Profile:
    """The elevation profile of the map's ``road_model`` for carriageway ``road`` (+1/-1)."""
    stations = np.asarray(road_model.profile_s, dtype=np.float64)
    heights = np.asarray(road_model.profile_z, dtype=np.float64)
    steps = np.diff(stations)
    spacing = float(steps[0]) if np.allclose(steps, steps[0], rtol=0, atol=1e-9) else 0.0
    slopes = np.diff(heights) / steps
    return Profile(int(road), stations, heights, slopes, spacing)


def fuel_coefficients(model: FuelModel = RAV4_2019) -> np.ndarray:
    """(17,) a fuel model's coefficients in the order :func:`fuel_rate` reads them."""
    names = ("c0", "c1", "c2", "c3", "p0", "p1", "p2", "q0", "q1", "z0", "z1", "beta0",
             "idle_speed", "b1", "b2", "b3", "mass")  # fmt: skip
    return np.array([getattr(model, name) for name in names], dtype=np.float64)


@kernel(inline=True)
def fuel_rate(c, v, a, g):
    """[g/s] the polynomial fuel model ``c`` (:func:`fuel_coefficients`) at speed ``v``
    [m/s] >= 0, acceleration ``a`` [m/s^2] and grade ``g`` [-]
    (:meth:`twin.physics.energy.FuelModel.rate`)."""
    push = max(a, 0.0) ** 2
    f = (
        c[0] + c[1] * v + c[2] * v**2 + c[3] * v**3 + c[4] * a + c[5] * a * v
        + c[6] * a * v**2 + c[7] * push + c[8] * push * v + c[9] * g + c[10] * g * v
    )  # fmt: skip
    return max(f, c[11] if v <= c[12] else 0.0)


@kernel(inline=True)
def _piece(stations, spacing, s):
    """The index j of the profile piece [stations[j], stations[j+1]] holding ``s``
    (within the profile): found directly where the stations are evenly ``spacing``
    apart, else by bisection."""
    last = stations.size - 1
    if spacing > 0.0:
        j = min(max(int((s - stations[0]) / spacing), 0), last - 1)
        if s < stations[j] and j > 0:  # rounding at a station
            j -= 1
        elif s >= stations[j + 1] and j < last - 1:
            j += 1
        return j
    lo, hi = 0, last
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if stations[mid] <= s:
            lo = mid
        else:
            hi = mid
    return lo


@kernel(inline=True)
def ground(road, stations, heights, slopes, spacing, centre_x):
    """(height [m], grade [-] along travel) of the pavement of ``road`` (+1, -1) under
    road-frame ``centre_x``, from the profile (``stations``, ``heights``, ``slopes``,
    even ``spacing`` or 0; :meth:`mapgen.road.RoadModel.to_world`: it extends flat
    beyond its ends). On a profile point, eastbound drives onto the piece after it,
    westbound onto the piece before."""
    last = stations.size - 1
    s = centre_x if road > 0 else SEGMENT_LENGTH - centre_x
    if s < stations[0] or s > stations[last]:
        return (heights[0] if s < stations[0] else heights[last]), 0.0
    j = _piece(stations, spacing, s)
    w = (s - stations[j]) / (stations[j + 1] - stations[j])
    height = heights[j] + w * (heights[j + 1] - heights[j])
    if road < 0 and s == stations[j] and j > 0:
        j -= 1
    slope = slopes[j]
    return height, slope if road > 0 else -slope


@kernel
def place(b, i, bodies, prof):
    """Slot ``i``'s ``z``, ``grade`` and ``lane`` from its pose."""
    _place(
        b, i, bodies.x, bodies.y, bodies.length, bodies.cg_height, bodies.z, bodies.grade,
        bodies.lane, prof.road, prof.stations, prof.heights, prof.slopes, prof.spacing,
    )  # fmt: skip


@kernel
def place_slots(b, slots, bodies, prof):
    """:func:`place` for each slot of ``slots`` (one call for all the bodies that
    another integrator moved)."""
    for k in range(slots.size):
        place(b, slots[k], bodies, prof)


@kernel(inline=True)
def _place(b, i, x, y, length, cg_height, z, grade, lane, road, stations, heights, slopes,
           spacing):  # fmt: skip
    height, g = ground(road, stations, heights, slopes, spacing, x[b, i] + 0.5 * length[b, i])
    grade[b, i] = g
    z[b, i] = height + cg_height[b, i] / math.sqrt(1.0 + g * g)  # cos(pitch) of the grade
    lane[b, i] = lane_of(y[b, i])


@kernel(inline=True)
def resistance(v, drag_area, rolling, m, cos_p, sin_p):
    """[N] air drag, rolling resistance and the grade's pull on a body of mass ``m``
    [kg] at speed ``v`` [m/s] (``cos_p``, ``sin_p``: of the grade's pitch)."""
    return (
        0.5 * AIR_DENSITY * drag_area * v * abs(v)
        + rolling * m * GRAVITY * cos_p * math.tanh(v / ROLLING_SPEED)
        + m * GRAVITY * sin_p
    )  # fmt: skip


@kernel(inline=True)
def drive_limit(b, i, bodies, v):
    """[m/s^2] the most acceleration body ``i``'s powertrain and driven wheels give at
    speed ``v`` [m/s] on its grade now (:func:`integrate`'s point mass)."""
    g = bodies.grade[b, i]
    cos_p = 1.0 / math.sqrt(1.0 + g * g)
    m = bodies.mass[b, i]
    force = min(
        bodies.max_power[b, i] / max(v, POWER_SPEED_MIN),
        bodies.mu[b, i] * m * GRAVITY * cos_p * bodies.driven_share[b, i],
    )
    resist = resistance(v, bodies.drag_area[b, i], bodies.rolling[b, i], m, cos_p, g * cos_p)
    return (force - resist) / bodies.eff_mass[b, i]


@kernel
def integrate(b, bodies, accel, steer, drive, brake, prof, dt):
    """Step episode ``b``'s bodies by ``dt`` [s] under the commanded accelerations
    ``accel`` and front-wheel angles ``steer`` (B, N): the point mass along its lane
    within the power, the driven wheels' grip and the brakes' grip, never rolling back;
    the kinematic bicycle across (the kinematic world's model, module doc). Where
    ``accel`` is NaN the raw ``drive`` and ``brake`` fractions (0..1 of the power and
    of the full brakes) act instead."""
    valid, x, y, yaw, speed = bodies.valid, bodies.x, bodies.y, bodies.yaw, bodies.speed
    yaw_rate, grade, drive_power = bodies.yaw_rate, bodies.grade, bodies.drive_power
    mass, eff_mass, drag_area = bodies.mass, bodies.eff_mass, bodies.drag_area
    rolling, mu, driven = bodies.rolling, bodies.mu, bodies.driven_share
    max_power, wheelbase, length = bodies.max_power, bodies.wheelbase, bodies.length
    cg_height, z, lane = bodies.cg_height, bodies.z, bodies.lane
    road, stations, heights, slopes, spacing = (
        prof.road,
        prof.stations,
        prof.heights,
        prof.slopes,
        prof.spacing,
    )
    for i in range(bodies.top[b]):
        if not valid[b, i]:
            continue
        v0 = speed[b, i]
        g = grade[b, i]
        cos_p = 1.0 / math.sqrt(1.0 + g * g)
        sin_p = g * cos_p
        m = mass[b, i]
        resist = resistance(v0, drag_area[b, i], rolling[b, i], m, cos_p, sin_p)
        command = accel[b, i]
        power_limit = max_power[b, i] / max(v0, POWER_SPEED_MIN)
        grip = mu[b, i] * m * GRAVITY * cos_p  # all four wheels: the brakes' limit
        if math.isnan(command):  # raw control
            force = min(drive[b, i] * power_limit, grip * driven[b, i])
            braking = min(brake[b, i] * BRAKE_LOCK_MARGIN * mu[b, i] * m * GRAVITY, grip)
            held = v0 <= 0.0 and brake[b, i] > 0.0 and drive[b, i] == 0.0
        else:
            wanted = eff_mass[b, i] * command + resist
            force = min(min(max(wanted, 0.0), power_limit), grip * driven[b, i])
            braking = min(max(-wanted, 0.0), grip)
            held = v0 <= 0.0 and command <= 0.0
        a = 0.0 if held else (force - braking - resist) / eff_mass[b, i]  # held at rest
        drive_power[b, i] = force * v0
        v1 = max(v0 + a * dt, 0.0)
        # a vehicle that stops inside the step travels to its stop and stays
        moving = dt if v1 > 0.0 else min(dt, v0 / max(-a, 1e-9))
        distance = max(v0 * moving + 0.5 * a * moving * moving, 0.0)
        # the bicycle about the centre of mass, midway between the axles
        turn, slip = 0.0, 0.0
        if steer[b, i] != 0.0:
            tan = math.tan(steer[b, i])
            slip = math.atan(0.5 * tan)
            turn = distance * math.cos(slip) * tan / wheelbase[b, i]
        middle = yaw[b, i] + 0.5 * turn + slip
        x[b, i] += distance * math.cos(middle)
        y[b, i] -= distance * math.sin(middle)  # y grows to the right of travel
        yaw[b, i] += turn
        yaw_rate[b, i] = turn / dt
        speed[b, i] = v1
        _place(b, i, x, y, length, cg_height, z, grade, lane, road, stations, heights, slopes,
               spacing)  # fmt: skip


@kernel
def keep_sorted(b, bodies, order, listed, centre):
    """Keep ``order[b]`` (B, N) the valid slots of episode ``b`` sorted by x (their
    centres where ``centre``, else their backs) from call to call (-1 past the last;
    ``listed`` (B, N) bool: which are in it): last call's order of the slots still
    valid, the new ones after, then an insertion sort (few moves between calls).
    Returns how many."""
    valid, x, length = bodies.valid, bodies.x, bodies.length
    half = 0.5 if centre else 0.0
    m = 0
    for k in range(valid.shape[1]):  # last call's order, of the slots still valid
        o = order[b, k]
        if o < 0:
            break
        if valid[b, o]:
            order[b, m] = o
            m += 1
        else:
            listed[b, o] = False
    for i in range(bodies.top[b]):  # and the new ones
        if valid[b, i] and not listed[b, i]:
            order[b, m] = i
            listed[b, i] = True
            m += 1
    if m < valid.shape[1]:
        order[b, m] = -1
    for k in range(1, m):  # insertion sort by x
        o = order[b, k]
        key = x[b, o] + half * length[b, o]
        j = k - 1
        while j >= 0 and x[b, order[b, j]] + half * length[b, order[b, j]] > key:
            order[b, j + 1] = order[b, j]
            j -= 1
        order[b, j + 1] = o
    return m


@kernel
def overlaps(b, bodies, order, listed, pairs):
    """The pairs of episode ``b``'s slots whose footprints overlap now (rectangles of
    the bodies' length and width about their centres, turned by their yaw; the
    separating-axis test on candidates close along the road). ``order`` (B, N) keeps
    the slots sorted by centre x from step to step, ``listed`` which are in it
    (:func:`keep_sorted`); writes up to ``pairs.shape[1]`` (slot, slot) rows into
    ``pairs[b]`` and returns how many (-1: more than that)."""
    x, y, yaw = bodies.x, bodies.y, bodies.yaw
    length, width = bodies.length, bodies.width
    m = keep_sorted(b, bodies, order, listed, np.bool_(True))
    reach = 0.0
    for k in range(m):
        o = order[b, k]
        reach = max(reach, 0.5 * (length[b, o] + width[b, o]))
    count = 0
    for k in range(m):
        i = order[b, k]
        xi = x[b, i] + 0.5 * length[b, i]
        for q in range(k + 1, m):
            j = order[b, q]
            xj = x[b, j] + 0.5 * length[b, j]
            if xj - xi > 2.0 * reach:
                break
            # the bounding boxes first (a footprint reaches at most its half diagonal)
            reach_ij = 0.5 * (length[b, i] + width[b, i] + length[b, j] + width[b, j])
            if abs(y[b, j] - y[b, i]) > reach_ij or xj - xi > reach_ij:
                continue
            if footprints_overlap(xi, y[b, i], yaw[b, i], 0.5 * length[b, i], 0.5 * width[b, i],
                        xj, y[b, j], yaw[b, j], 0.5 * length[b, j], 0.5 * width[b, j]):  # fmt: skip
                if count == pairs.shape[1]:
                    return -1
                pairs[b, count, 0], pairs[b, count, 1] = min(i, j), max(i, j)
                count += 1
    return count


@kernel(inline=True)
def footprints_overlap(xi, yi, yaw_i, hl_i, hw_i, xj, yj, yaw_j, hl_j, hw_j):
    """Whether two footprints (centres, yaws, half lengths and widths) overlap, by the
    separating axes of both."""
    ci, si = math.cos(yaw_i), math.sin(yaw_i)
    cj, sj = math.cos(yaw_j), math.sin(yaw_j)
    dx, dy = xj - xi, yj - yi
    for k in range(4):
        # each footprint's axes in the road frame (x along travel, y to the right)
        if k == 0:
            ax, ay = ci, -si
        elif k == 1:
            ax, ay = si, ci
        elif k == 2:
            ax, ay = cj, -sj
        else:
            ax, ay = sj, cj
        reach_i = hl_i * abs(ci * ax - si * ay) + hw_i * abs(si * ax + ci * ay)
        reach_j = hl_j * abs(cj * ax - sj * ay) + hw_j * abs(sj * ax + cj * ay)
        if abs(dx * ax + dy * ay) > reach_i + reach_j:
            return False
    return True
