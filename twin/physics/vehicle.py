"""The vehicle model: one rigid body per vehicle on four ray-cast wheels (pure numpy).

The physics engine integrates the body; this module computes the forces on it from
the wheels' ray hits, the controls and the body's state, for all vehicles at once:

* suspension: a spring and damper per wheel along the body's up axis, acting only
  while the wheel's ray touches the road;
* tyres: longitudinal force from the slip ratio of a spinning wheel and lateral force
  from the slip angle, both proportional to the wheel's load, limited together by a
  friction circle (``mu * load``);
* wheel spin: each wheel's spin obeys ``I dw/dt = T_drive - T_brake - r F_x``, updated
  implicitly in the tyre's slip stiffness (a stiff equation at dt = 0.01 s);
* drive limited by engine power and by the tyres, brakes as Coulomb torques on the
  wheels (they can lock them; the tyres then slide at the friction limit);
* rolling resistance at each tyre and aerodynamic drag on the body.

Gravity is applied by the engine, so vehicles slow on an upgrade because gravity acts
on them. Frames: world east-north-up; body x forward, y left, z up, origin at the
centre of mass. Wheels are ordered front-left, front-right, rear-left, rear-right.
"""

from dataclasses import dataclass, fields

import numpy as np

from twin.core.vehicle_classes import VehicleClassTable

GRAVITY = 9.81  # [m/s^2]
AIR_DENSITY = 1.2  # [kg/m^3]
REST_LENGTH_MIN = 0.3  # [m] unloaded suspension length (at least twice the static sag)
SLIP_SPEED_MIN = 5.0  # [m/s] slip is measured against at least this speed (low-speed stability)
POWER_SPEED_MIN = 1.0  # [m/s] below it the power limit is taken at this speed
ROLLING_SPEED = 0.5  # [m/s] rolling resistance fades in over this speed (no creep at rest)
HOLD_SPEED = 0.05  # [m/s] below it a braking vehicle is held by static friction
BRAKE_LOCK_MARGIN = 1.5  # full brake torque, as a multiple of what locks a wheel at rest
FRONT = np.array([True, True, False, False])


@dataclass(frozen=True, eq=False)
class VehicleParams:
    """Physical parameters per vehicle, struct-of-arrays (each (n,) unless noted).

    Made from the class table and each vehicle's size by :meth:`from_classes`.
    """

    vehicle_class: np.ndarray  # int
    length: np.ndarray  # [m]
    width: np.ndarray
    height: np.ndarray
    mass: np.ndarray  # [kg]
    inertia: np.ndarray  # (n, 3) [kg m^2] principal roll, pitch, yaw
    mounts: np.ndarray  # (n, 4, 3) [m] suspension top points in the body frame
    ray_length: np.ndarray  # [m] unloaded suspension plus wheel radius
    box_center: np.ndarray  # (n, 3) [m] chassis box centre in the body frame
    box_half: np.ndarray  # (n, 3) [m] chassis box half extents
    cg_height: np.ndarray  # [m] centre of mass above the ground at rest
    wheel_radius: np.ndarray
    wheel_inertia: np.ndarray  # [kg m^2] per wheel
    spring: np.ndarray  # [N/m] per wheel
    damper: np.ndarray  # [N s/m] per wheel
    max_power: np.ndarray  # [W]
    drag_area: np.ndarray  # [m^2] drag coefficient times frontal area
    rolling: np.ndarray  # rolling resistance coefficient
    mu: np.ndarray  # tyre friction coefficient
    cornering: np.ndarray  # [1/rad] cornering stiffness per unit load
    slip_stiffness: np.ndarray  # longitudinal stiffness per unit load and slip ratio
    driven: np.ndarray  # (n, 4) bool: the driven wheels
    brake_share: np.ndarray  # (n, 4) share of the brake force per wheel

    @classmethod
    def from_classes(
        cls,
        table: VehicleClassTable,
        vehicle_class: np.ndarray,
        length: np.ndarray,
        width: np.ndarray,
        height: np.ndarray,
    ) -> "VehicleParams":
        """Parameters of vehicles of the given classes and sizes [m].

        Mass scales with length against the class's mean length; radii of gyration
        scale with the body; the centre of mass sits at ``cg_height_ratio`` of the
        height, centred along and across the body.

        Raises:
            ValueError: a class id is unknown or a size is not positive and finite.
        """
        k = np.asarray(vehicle_class, dtype=np.int64)
        length, width, height = (np.asarray(a, dtype=np.float64) for a in (length, width, height))
        if k.size and (k.min() < 0 or k.max() >= len(table.frame)):
            raise ValueError(f"vehicle classes must be 0..{len(table.frame) - 1}, got {k}")
        sizes = np.stack([length, width, height])
        if not np.all(np.isfinite(sizes)) or np.any(sizes <= 0):
            raise ValueError("vehicle length, width and height must be positive and finite")

        def col(name):
            return table.column(name).astype(np.float64)[k]

        mass = col("mass_kg") * length / col("length_m")
        inertia = mass[:, None] * np.stack(
            [
                (col("roll_gyration_ratio") * width) ** 2,
                (col("pitch_gyration_ratio") * length) ** 2,
                (col("yaw_gyration_ratio") * length) ** 2,
            ],
            axis=1,
        )
        radius = col("wheel_radius_m")
        omega = 2.0 * np.pi * col("suspension_hz")
        sag = GRAVITY / omega**2  # static compression
        rest = np.maximum(REST_LENGTH_MIN, 2.0 * sag)
        clearance = np.minimum(col("ground_clearance_m"), 0.5 * height)
        cg = col("cg_height_ratio") * height
        half_base = 0.5 * col("wheelbase_ratio") * length
        half_track = 0.5 * col("track_ratio") * width
        mounts = np.empty((k.size, 4, 3))
        mounts[:, :, 0] = half_base[:, None] * np.array([1.0, 1.0, -1.0, -1.0])
        mounts[:, :, 1] = half_track[:, None] * np.array([1.0, -1.0, 1.0, -1.0])
        mounts[:, :, 2] = (radius + rest - sag - cg)[:, None]
        corner_mass = mass / 4.0
        spring = corner_mass * omega**2
        front = col("brake_front_share")
        driven = np.where(col("drive_axle")[:, None] == 0, FRONT, ~FRONT)
        return cls(
            vehicle_class=k,
            length=length,
            width=width,
            height=height,
            mass=mass,
            inertia=inertia,
            mounts=mounts,
            ray_length=rest + radius,
            box_center=np.stack(
                [np.zeros_like(cg), np.zeros_like(cg), 0.5 * (clearance + height) - cg], 1
            ),
            box_half=0.5 * np.stack([length, width, height - clearance], axis=1),
            cg_height=cg,
            wheel_radius=radius,
            wheel_inertia=col("wheel_inertia_kgm2"),
            spring=spring,
            damper=2.0 * col("damping_ratio") * np.sqrt(spring * corner_mass),
            max_power=1000.0 * col("max_power_kw"),
            drag_area=col("drag_coefficient") * col("frontal_area_ratio") * width * height,
            rolling=col("rolling_resistance"),
            mu=col("tyre_friction"),
            cornering=col("cornering_stiffness_per_load"),
            slip_stiffness=col("slip_stiffness_per_load"),
            driven=driven,
            brake_share=np.stack([front / 2, front / 2, (1 - front) / 2, (1 - front) / 2], 1),
        )

    def take(self, index: np.ndarray) -> "VehicleParams":
        """The parameters of a subset (or reordering) of the vehicles."""
        return VehicleParams(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    @staticmethod
    def concatenate(parts: list["VehicleParams"]) -> "VehicleParams":
        return VehicleParams(
            **{
                f.name: np.concatenate([getattr(p, f.name) for p in parts])
                for f in fields(VehicleParams)
            }
        )

    def __len__(self) -> int:
        return self.mass.size

    @property
    def effective_mass(self) -> np.ndarray:
        """[kg] the body plus the wheels' rotational inertia, as felt along travel."""
        return self.mass + 4.0 * self.wheel_inertia / self.wheel_radius**2


@dataclass(frozen=True, eq=False)
class Controls:
    """Inputs per vehicle, struct-of-arrays (n,).

    ``accel`` [m/s^2] is the acceleration to track along the body's heading; the model
    adds what grade, rolling resistance and drag take (feedforward) and turns the sum
    into drive or brake torque. Where ``accel`` is NaN the raw ``drive`` and ``brake``
    fractions in 0..1 are used instead (full drive: the power limit; full brake: enough
    torque to lock the wheels). ``steer`` [rad] is the front wheels' angle, left positive.
    """

    accel: np.ndarray
    drive: np.ndarray
    brake: np.ndarray
    steer: np.ndarray


@dataclass(frozen=True, eq=False)
class WheelForces:
    """What :func:`vehicle_forces` returns (world frame)."""

    force: np.ndarray  # (n, 3) [N] total on the body, at its centre of mass
    torque: np.ndarray  # (n, 3) [N m] about the centre of mass
    wheel_spin: np.ndarray  # (n, 4) [rad/s] after this step
    load: np.ndarray  # (n, 4) [N] suspension force (0 without contact)
    contact: np.ndarray  # (n, 4) bool
    drive_power: np.ndarray  # (n,) [W] the drive torques times the wheels' spin (tractive)


def ray_ends(params: VehicleParams, position: np.ndarray, rotation: np.ndarray):
    """World start and end points of the wheels' rays, each (n, 4, 3)."""
    mounts = np.einsum("nij,nkj->nki", rotation, params.mounts)
    start = position[:, None, :] + mounts
    end = start - rotation[:, None, :, 2] * params.ray_length[:, None, None]
    return start, end


# One piece on purpose (134 lines): the wheel, tyre, drivetrain, brake and drag forces of
# a step are one chain of vectorised array expressions over (n, 4) wheels, each term
# feeding the next; split into functions, the dozen intermediate arrays would travel
# through their arguments, and this runs every physics step for every body.
def vehicle_forces(
    params: VehicleParams,
    controls: Controls,
    position: np.ndarray,
    rotation: np.ndarray,
    velocity: np.ndarray,
    angular_velocity: np.ndarray,
    wheel_spin: np.ndarray,
    hit_fraction: np.ndarray,
    hit_normal: np.ndarray,
    dt: float,
) -> WheelForces:
    """Forces of wheels, tyres, engine, brakes and air on each body for one step.

    Args:
        params: n vehicles.
        controls: their inputs.
        position: (n, 3) [m] centres of mass; rotation: (n, 3, 3) body-to-world.
        velocity, angular_velocity: (n, 3) [m/s], [rad/s] world frame.
        wheel_spin: (n, 4) [rad/s].
        hit_fraction: (n, 4) of each ray's length to the road, >= 1 where it missed.
        hit_normal: (n, 4, 3) road normals at the hits.
        dt: [s] the step.
    """
    # Vectors are handled as their world components, each (n, 4) per wheel or (n, 1)
    # per body: numpy's per-call cost dominates on arrays this small.
    r = rotation
    ex, ey, ez = r[:, 0, 0:1], r[:, 1, 0:1], r[:, 2, 0:1]  # body forward axis
    lx, ly, lz = r[:, 0, 1:2], r[:, 1, 1:2], r[:, 2, 1:2]  # body left axis
    ux, uy, uz = r[:, 0, 2:3], r[:, 1, 2:3], r[:, 2, 2:3]  # body up axis
    bx, by, bz = params.mounts[..., 0], params.mounts[..., 1], params.mounts[..., 2]
    mx = ex * bx + lx * by + ux * bz  # suspension tops from the centre of mass
    my = ey * bx + ly * by + uy * bz
    mz = ez * bx + lz * by + uz * bz
    contact = hit_fraction < 1.0
    ray = params.ray_length[:, None]
    distance = np.minimum(hit_fraction, 1.0) * ray
    ax, ay, az = mx - ux * distance, my - uy * distance, mz - uz * distance  # contact points
    vx0, vy0, vz0 = velocity[:, 0:1], velocity[:, 1:2], velocity[:, 2:3]
    wx, wy, wz = angular_velocity[:, 0:1], angular_velocity[:, 1:2], angular_velocity[:, 2:3]

    # suspension, along the body's up axis
    rate = -(
        (vx0 + wy * mz - wz * my) * ux
        + (vy0 + wz * mx - wx * mz) * uy
        + (vz0 + wx * my - wy * mx) * uz
    )
    spring = params.spring[:, None] * (ray - distance) + params.damper[:, None] * rate
    load = np.where(contact, np.maximum(spring, 0.0), 0.0)

    # tyre axes on the road plane; the front wheels are steered about the body's up axis
    cos, sin = np.cos(controls.steer)[:, None], np.sin(controls.steer)[:, None]
    fx = np.where(FRONT, cos * ex + sin * lx, ex)
    fy = np.where(FRONT, cos * ey + sin * ly, ey)
    fz = np.where(FRONT, cos * ez + sin * lz, ez)
    nx = np.where(contact, hit_normal[..., 0], ux)
    ny = np.where(contact, hit_normal[..., 1], uy)
    nz = np.where(contact, hit_normal[..., 2], uz)
    along = fx * nx + fy * ny + fz * nz
    fx, fy, fz = fx - along * nx, fy - along * ny, fz - along * nz
    norm = np.sqrt(fx * fx + fy * fy + fz * fz)
    fx, fy, fz = fx / norm, fy / norm, fz / norm
    sx, sy, sz = ny * fz - nz * fy, nz * fx - nx * fz, nx * fy - ny * fx  # lateral = n x f
    cvx = vx0 + wy * az - wz * ay  # contact point velocities
    cvy = vy0 + wz * ax - wx * az
    cvz = vz0 + wx * ay - wy * ax
    vx = cvx * fx + cvy * fy + cvz * fz
    vy = cvx * sx + cvy * sy + cvz * sz

    speed = (vx0 * ex + vy0 * ey + vz0 * ez)[:, 0]
    # lateral: slip angle, never more than what stops the sideways slide in one step
    reference = np.maximum(np.abs(vx), SLIP_SPEED_MIN)
    ty = -params.cornering[:, None] * load * np.arctan(vy / reference)
    corner_mass = (params.mass / 4.0)[:, None]
    slide = corner_mass * np.abs(vy) / dt
    ty = np.clip(ty, -slide, slide)
    # what the steered wheels' cornering forces pull along the heading, which the
    # powertrain's feedforward makes up: without it a car at 0.75 m/s steered 0.3 rad
    # back to its lane's centre braked at 1.6 m/s^2 for 0.92 asked
    along = (ty * (sx * ex + sy * ey + sz * ez)).sum(axis=1)
    drive_torque, brake_torque = _torques(params, controls, speed, ez[:, 0], along)

    # longitudinal: slip of a spinning wheel, its spin implicit in the slip stiffness
    radius = params.wheel_radius[:, None]
    inertia = params.wheel_inertia[:, None]
    stiffness = params.slip_stiffness[:, None] * load
    a = dt * radius**2 * stiffness / (inertia * reference)
    free = (wheel_spin + dt * drive_torque / inertia + a * vx / radius) / (1.0 + a)
    stop = dt * brake_torque / (inertia * (1.0 + a))
    spin = free - np.sign(free) * np.minimum(np.abs(free), stop)
    tx = stiffness * (spin * radius - vx) / reference
    # friction circle
    limit = params.mu[:, None] * load
    total = np.hypot(tx, ty)
    sliding = total > limit
    scale = np.where(sliding, limit / np.maximum(total, 1e-12), 1.0)
    tx, ty = tx * scale, ty * scale
    slid = wheel_spin + dt * (drive_torque - radius * tx) / inertia
    slid -= np.sign(slid) * np.minimum(np.abs(slid), dt * brake_torque / inertia)
    spin = np.where(sliding, slid, spin)
    spin = np.where(contact, spin, wheel_spin + dt * drive_torque / inertia)
    rolling = -params.rolling[:, None] * load * np.clip(vx / ROLLING_SPEED, -1.0, 1.0)
    # Held at rest by the brakes: static friction cancels the creep and the grade's
    # pull in one step, within the friction limit (a slip model alone lets it creep).
    held = _held(controls, speed)[:, None] & contact
    static = np.clip(corner_mass * (GRAVITY * ez - vx / dt), -limit, limit)
    tx = np.where(held, static, tx + rolling)
    spin = np.where(held, 0.0, spin)

    # wheel forces, then their sum and moment about the centre of mass, plus drag
    px = load * ux + tx * fx + ty * sx
    py = load * uy + tx * fy + ty * sy
    pz = load * uz + tx * fz + ty * sz
    drag = -0.5 * AIR_DENSITY * params.drag_area[:, None] * np.sqrt(vx0**2 + vy0**2 + vz0**2)
    force = np.concatenate(
        [
            px.sum(1, keepdims=True) + drag * vx0,
            py.sum(1, keepdims=True) + drag * vy0,
            pz.sum(1, keepdims=True) + drag * vz0,
        ],
        axis=1,
    )
    torque = np.stack(
        [
            (ay * pz - az * py).sum(1),
            (az * px - ax * pz).sum(1),
            (ax * py - ay * px).sum(1),
        ],
        axis=1,
    )
    return WheelForces(
        force=force,
        torque=torque,
        wheel_spin=spin,
        load=load,
        contact=contact,
        drive_power=(drive_torque * spin).sum(axis=1),
    )


def _held(controls: Controls, speed: np.ndarray) -> np.ndarray:
    """(n,) bool: vehicles at rest whose controls ask to stay there."""
    raw = np.isnan(controls.accel)
    braking = np.where(
        raw, (controls.brake > 0) & (controls.drive == 0), np.nan_to_num(controls.accel) <= 0
    )
    return braking & (np.abs(speed) < HOLD_SPEED)


def _torques(params, controls, speed, sin_pitch, lateral_along):
    """Drive and brake torque per wheel (n, 4) [N m] from the controls, given the
    speed along the heading (n,) [m/s], the sine of the body's pitch (n,) and what the
    tyres' cornering forces pull along the heading (n,) [N]."""
    radius = params.wheel_radius
    # the force at the wheels that makes the body accelerate at `accel` (feedforward)
    wanted = (
        params.effective_mass * np.nan_to_num(controls.accel)
        + resistance(params, speed, sin_pitch)
        - lateral_along
    )
    power_limit = params.max_power / np.maximum(np.abs(speed), POWER_SPEED_MIN)
    full_brake = full_brake_torque(params)  # per wheel
    raw = np.isnan(controls.accel)
    drive_force = np.where(raw, controls.drive * power_limit, np.clip(wanted, 0.0, power_limit))
    brake_force = np.where(raw, 0.0, np.maximum(-wanted, 0.0))
    driven = params.driven.astype(np.float64)
    drive = (drive_force * radius)[:, None] * driven / driven.sum(axis=1, keepdims=True)
    brake = (brake_force * radius)[:, None] * params.brake_share
    brake = np.where(
        raw[:, None], (controls.brake * 4.0 * full_brake)[:, None] * params.brake_share, brake
    )
    return drive, brake


def resistance(params: VehicleParams, speed: np.ndarray, sin_pitch: np.ndarray) -> np.ndarray:
    """(n,) [N] what aerodynamic drag, rolling resistance and the grade take along the
    heading at ``speed`` [m/s] on a grade of pitch sine ``sin_pitch`` (nose-up
    positive): the force the powertrain adds to its feedforward."""
    return (
        0.5 * AIR_DENSITY * params.drag_area * speed * np.abs(speed)
        + params.rolling
        * params.mass
        * GRAVITY
        * np.sqrt(1.0 - sin_pitch**2)
        * np.tanh(speed / ROLLING_SPEED)
        + params.mass * GRAVITY * sin_pitch
    )


def full_brake_torque(params: VehicleParams) -> np.ndarray:
    """(n,) [N m] per wheel at full brake: enough to lock a wheel at rest."""
    return BRAKE_LOCK_MARGIN * params.mu * params.mass * GRAVITY / 4.0 * params.wheel_radius
