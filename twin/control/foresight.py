"""What an AV that knew its leader's whole future could save: how far a policy is from
what a controller keeping the wave-dampening targets could do on a morning.

A policy sees the present (and the recorded speeds ahead); a controller that knows how
its leader will drive for the whole episode can do more. :func:`least_fuel_plan` finds
that controller's trajectory: the AV's speeds, every ``step`` seconds with a constant
acceleration between, that drive it the most miles per gallon of its own (the RAV4
fuel model on the flat) while its time gap stays within a comfort band at every knot
(:class:`Band`: the benchmark's 1 to 4 s, at least 2 m, the env's acceleration range;
optionally a share of the knots longer: the p90 target). It is a dynamic programme over
(gap, speed) on a grid (the value function interpolated in the gap; the long knots
left as a state), with Dinkelbach's iteration for the ratio (distance over fuel: least
``fuel - mu distance``, ``mu`` updated to the plan's fuel per metre until it settles).

:func:`headroom` measures it in the twin: it drives ``human`` on episodes of the vector
env (the benchmark's pairing), plans each AV's trajectory from its leader's speeds in
that run, then drives the plans in the same episodes (the AV tracks its plan; its
leader is driven again, and an episode whose leader changes is not counted), and
reports per episode the AV's economy and that of the AV and its followers against
``human``. The AV's own figure bounds any controller that keeps the band (up to the
grid and the leader's drift; ``human`` itself may leave the band, at a standing start
closer than 2 m, say); the followers' is what they make of the AV's best plan for
itself (a plan for the group could do better for them): an estimate, not a bound.
"""

import math
from dataclasses import dataclass

import numpy as np

from twin.control.env import ACCEL_RANGE
from twin.control.observe import GAP_CAP
from twin.metrics.economy import economy
from twin.physics.energy import RAV4_2019

FINE_DT = 0.1  # [s] the env's control step: the leader's speeds come at it
#: [m] a gap that moves this much more in a control step than the two speeds say is
#: another leader's (a lane change); such an episode is not planned, or not counted.
LEADER_JUMP = 1.0
TIME_GAP_FLOOR_SPEED = 1.0  # [m/s] the time gap is gap / max(speed, this), as evolve's
STEP = 1.0  # [s] between a plan's knots


class ForesightError(ValueError):
    """A plan was asked of impossible inputs (named)."""


@dataclass(frozen=True)
class Band:
    """The comfort band the plan keeps at every knot: time gap [s] (gap over the
    speed, at least 1 m/s) within ``time_gap``, gap at least ``min_gap`` [m],
    acceleration [m/s^2] within ``accel``; but up to ``long_share`` of the knots may
    have a longer time gap, up to ``long_max`` (``long_share`` 0.1: the benchmark's
    target on the time gap's p90)."""

    time_gap: tuple[float, float] = (1.0, 4.0)
    min_gap: float = 2.0
    accel: tuple[float, float] = ACCEL_RANGE
    long_share: float = 0.0
    long_max: float = 10.0

    def __post_init__(self):
        low, high = self.time_gap
        if not (0 <= low < high and math.isfinite(high)):
            raise ForesightError(
                f"time_gap must be (low, high) with 0 <= low < high, got {self.time_gap}"
            )
        if not (self.accel[0] < 0 < self.accel[1]):
            raise ForesightError(f"accel must be (braking < 0, accelerating > 0), got {self.accel}")
        if not (0 <= self.long_share <= 1):
            raise ForesightError(f"long_share must be within 0 and 1, got {self.long_share!r}")
        if self.long_share > 0 and not (high < self.long_max and math.isfinite(self.long_max)):
            raise ForesightError(
                f"long_max must be over the band's {high} s, got {self.long_max!r}"
            )
        if not (math.isfinite(self.min_gap) and self.min_gap >= 0):
            raise ForesightError(f"min_gap must be a number >= 0, got {self.min_gap!r}")

    def holds(self, gap, speed, upper=None) -> np.ndarray:
        """Whether ``gap`` [m] at ``speed`` [m/s] is within the band (up to ``upper``
        [s] of time gap instead of its own upper end, if given)."""
        floor = np.maximum(speed, TIME_GAP_FLOOR_SPEED)
        low = np.maximum(self.min_gap, self.time_gap[0] * floor)
        return (gap >= low) & (gap <= (self.time_gap[1] if upper is None else upper) * floor)


@dataclass(frozen=True)
class Plan:
    """The AV's planned speeds and gaps at the knots (every ``step`` s), its fuel [g]
    and distance [m] (constant acceleration between knots, the flat road)."""

    speeds: np.ndarray
    gaps: np.ndarray
    step: float
    fuel_g: float
    distance_m: float

    def speed_at(self, t) -> np.ndarray:
        """[m/s] the planned speed at times ``t`` [s] from the start."""
        return np.interp(t, self.step * np.arange(self.speeds.size), self.speeds)


def least_fuel_plan(
    leader_speed,
    gap: float,
    speed: float,
    *,
    band: Band = Band(),
    step: float = STEP,
    speed_step: float = 0.25,
    gap_step: float = 0.5,
    gap_max: float = 200.0,
    speed_max: float = 35.0,
    end_speed: float | None = None,
    iterations: int = 6,
) -> Plan:
    """The most miles per gallon the AV could drive behind a leader whose speeds
    ``leader_speed`` [m/s] (every :data:`FINE_DT` from the start, the end's included:
    the leader covers their trapezoid) it knew in advance, from the gap
    ``gap`` [m] (bumper to bumper) and its speed ``speed`` [m/s], within ``band`` at
    every knot (module doc), ending at ``end_speed`` [m/s] or faster (by default its
    leader's last speed: a plan may not sell the speed it was given, coasting down
    for free at the end). Speeds are on a grid of ``speed_step``, gaps of
    ``gap_step`` up to ``gap_max``; the knots are ``step`` s apart, one per ``step`` s
    of ``leader_speed`` (what is left over is not planned). The plan follows the exact
    gap with the moves of the nearest grid row: its time gap may leave the band by up
    to ``gap_step / max(speed, 1 m/s)``.

    Raises:
        ForesightError: an input is not finite or negative, the grid does not fit the
            acceleration range, or no trajectory keeps the band from this start.
    """
    for name, value in (("step", step), ("speed_step", speed_step), ("gap_step", gap_step)):
        if not (math.isfinite(value) and value > 0):
            raise ForesightError(f"{name} must be a positive number, got {value!r}")
    if not (isinstance(iterations, int) and iterations >= 1):
        raise ForesightError(f"iterations must be an integer >= 1, got {iterations!r}")
    lead = np.asarray(leader_speed, dtype=np.float64)
    sub = round(step / FINE_DT)
    if (
        sub < 1
        or lead.ndim != 1
        or lead.size < sub + 1
        or not np.all(np.isfinite(lead))
        or lead.min() < 0
    ):
        raise ForesightError(
            f"leader_speed must be at least {sub + 1} finite speeds >= 0 m/s, one per {FINE_DT} s"
        )
    end_speed = float(lead[-1]) if end_speed is None else end_speed
    for name, value in (("gap", gap), ("speed", speed), ("end_speed", end_speed)):
        if not (math.isfinite(value) and value >= 0):
            raise ForesightError(f"{name} must be a finite number >= 0, got {value!r}")
    if speed > speed_max or gap > gap_max:
        raise ForesightError(
            f"the start ({gap:.1f} m at {speed:.1f} m/s) is off the grid (gaps up to "
            f"{gap_max} m, speeds up to {speed_max} m/s)"
        )
    if abs(sub * FINE_DT - step) > 1e-9:
        raise ForesightError(f"step must be a multiple of {FINE_DT} s, got {step!r}")
    low, high = (a * step / speed_step for a in band.accel)
    if abs(low - round(low)) > 1e-9 or abs(high - round(high)) > 1e-9:
        raise ForesightError(
            f"speed_step {speed_step} m/s must divide the acceleration range {band.accel} "
            f"times the step {step} s"
        )
    # the grid need not reach past what the band and the leader allow
    speed_max = min(speed_max, max(float(lead.max()), speed, end_speed) + 5.0)
    speed_max = speed_step * math.ceil(speed_max / speed_step)
    widest = band.long_max if band.long_share > 0 else band.time_gap[1]
    gap_max = min(gap_max, max(widest * max(speed_max, TIME_GAP_FLOOR_SPEED), gap) + 5.0)
    knots = (lead.size - 1) // sub
    steps = (lead[:-1] + lead[1:])[: knots * sub] / 2.0 * FINE_DT  # as the twin moves it
    ahead = steps.reshape(knots, sub).sum(axis=1)  # the leader's metres per knot
    speeds = np.arange(0.0, speed_max + 1e-9, speed_step)
    gaps = np.arange(0.0, gap_max + 1e-9, gap_step)
    moves = np.arange(round(low), round(high) + 1)  # speed change per step, in speed steps
    inside = band.holds(gaps[:, None], speeds[None, :])
    budget = math.floor(band.long_share * knots + 1e-9)
    if budget:
        over = band.holds(gaps[:, None], speeds[None, :], band.long_max) & ~inside
    else:
        over = np.zeros_like(inside)
    allowed = inside | over  # with any budget left: entering an over state spent one
    fast = speeds[None, :] >= speed_step * math.ceil(end_speed / speed_step - 1e-9)
    last = allowed & fast
    fuel = _step_fuel(speeds[:, None], moves[None, :] * speed_step / step, step)  # (V, moves)
    rate, best = 0.0, None
    for _ in range(iterations):
        policy = _backward(ahead, speeds, gaps, moves, budget, allowed, over, last, fuel, step,
                           rate)  # fmt: skip
        plan = _forward(policy, ahead, speeds, gaps, moves, over, fuel, step, gap, speed, band)
        if plan.distance_m <= 0 or plan.fuel_g <= 0:
            return plan  # standing still: nothing to improve
        if best is None or plan.distance_m / plan.fuel_g > best.distance_m / best.fuel_g:
            best = plan  # the grid's plans need not improve every round: keep the best
        settled = rate > 0 and abs(plan.fuel_g / plan.distance_m - rate) <= 1e-6 * rate
        rate = plan.fuel_g / plan.distance_m
        if settled:
            break
    return best


def _step_fuel(speed, accel, step) -> np.ndarray:
    """[g] over one step from ``speed`` [m/s] at ``accel`` [m/s^2] (arrays that
    broadcast together), the fuel model at the midpoints of its control steps, on the
    flat."""
    tau = (np.arange(round(step / FINE_DT)) + 0.5) * FINE_DT
    v, a = np.broadcast_arrays(np.asarray(speed, dtype=np.float64)[..., None],
                               np.asarray(accel, dtype=np.float64)[..., None])  # fmt: skip
    v = np.maximum(v + a * tau, 0.0)
    a = np.broadcast_to(a, v.shape)
    rate = RAV4_2019.rate(v.ravel(), a.ravel(), np.zeros(v.size)).reshape(v.shape)
    return rate.sum(axis=-1) * FINE_DT


def _backward(ahead, speeds, gaps, moves, budget, allowed, over, last, fuel, step,
              rate) -> np.ndarray:  # fmt: skip
    """The best move (an index of ``moves``, -1 where none keeps the band) at each knot,
    budget of long knots left (0 to ``budget``), gap and speed, for the cost ``fuel -
    rate distance`` to the end. ``allowed`` (G, V): the states a knot may be in;
    ``last``: those the end may be in. Entering an ``over`` state (a long time gap)
    spends one of the budget."""
    n_b, (n_g, n_v) = budget + 1, allowed.shape
    gap_step = gaps[1] - gaps[0]
    value = np.repeat(np.where(last, 0.0, np.inf)[None], n_b, axis=0)
    padded = np.full((n_b, n_g + 2, n_v), np.inf)
    rows = np.arange(n_g)[:, None]
    policy = np.zeros((ahead.size, n_b, n_g, n_v), dtype=np.int16)
    for k in range(ahead.size - 1, -1, -1):
        # what a state is worth to one arriving with budget b: an over state costs one
        spent = np.concatenate([np.full((1, n_g, n_v), np.inf), value[:-1]])
        padded[:, 1:-1] = np.where(over[None], spent, value)
        best = np.full((n_b, n_g, n_v), np.inf)
        choice = np.zeros((n_b, n_g, n_v), dtype=np.int16)
        for j, move in enumerate(moves):
            to = np.arange(n_v) + move
            ok = (to >= 0) & (to < n_v)
            to = np.clip(to, 0, n_v - 1)
            travelled = (speeds + speeds[to]) / 2.0 * step
            shift = (ahead[k] - travelled) / gap_step  # the gap changes by this many cells
            whole = np.floor(shift).astype(int)
            w = shift - whole
            at = np.clip(rows + whole[None, :] + 1, 0, n_g + 1)  # +1: the padding row
            nxt = np.clip(at + 1, 0, n_g + 1)
            left, right = padded[:, at, to[None, :]], padded[:, nxt, to[None, :]]
            with np.errstate(invalid="ignore"):
                later = np.where(w[None, :] > 1e-12, (1 - w) * left + w * right, left)
            later = np.where(np.isnan(later) | ~ok[None, :], np.inf, later)
            cost = (fuel[:, j] - rate * travelled)[None, None, :] + later
            better = cost < best
            best = np.where(better, cost, best)
            choice = np.where(better, j, choice)
        value = np.where(allowed[None], best, np.inf)
        choice[~np.isfinite(value)] = -1  # no way on within the band from there
        policy[k] = choice
    return policy


def _forward(policy, ahead, speeds, gaps, moves, over, fuel, step, gap, speed, band) -> Plan:
    """Drive the policy from the exact start (its speed on the grid), its budget of
    long knots whole: at each knot the nearer grid row with a way on decides, and
    landing on a row that is ``over`` spends one, as :func:`_backward` counts it."""
    gap_step, speed_step = gaps[1] - gaps[0], speeds[1] - speeds[0]
    v = min(round(speed / speed_step), speeds.size - 1)
    g, budget = float(gap), policy.shape[1] - 1
    out_v, out_g, total_fuel, distance = [speeds[v]], [g], 0.0, 0.0
    for k in range(ahead.size):
        near = g / gap_step
        options = []
        for r in sorted({math.floor(near), math.ceil(near)}, key=lambda r: abs(r - near)):
            # arriving on a long row spends one of the budget (not the start's)
            left = budget - int(k > 0 and 0 <= r < gaps.size and over[r, v])
            if 0 <= r < gaps.size and left >= 0 and policy[k, left, r, v] >= 0:
                options.append((r, left))
        if not options:
            raise ForesightError(
                f"no trajectory keeps the band {band} from a gap of {gap:.1f} m at "
                f"{speed:.1f} m/s behind this leader (none on from {g:.1f} m at "
                f"{speeds[v]:.2f} m/s after {k} knots)"
            )
        row, budget = options[0]
        j = int(policy[k, budget, row, v])
        to = v + int(moves[j])
        travelled = (speeds[v] + speeds[to]) / 2.0 * step
        total_fuel += float(fuel[v, j])
        distance += travelled
        g += ahead[k] - travelled
        v = to
        out_v.append(speeds[v])
        out_g.append(g)
    return Plan(np.array(out_v), np.array(out_g), step, total_fuel, distance)


def headroom(data, episodes: int = 40, *, duration: float = 120.0, split: str = "test",
             seed: int = 0, band: Band = Band(), gap_step: float = 0.5,
             progress: bool = True) -> list[dict]:  # fmt: skip
    """Per episode of ``data``'s ``split`` (the first ``episodes`` the vector env places),
    ``human``'s figures and those of the AV driving the plan of
    :func:`least_fuel_plan` (within ``band``, on a grid of ``gap_step`` [m]) from its
    leader's speeds in ``human``'s run (module doc):
    rows with ``episode``, ``status`` (``planned``, or why not: ended early, another
    leader, no way within the band), ``plan`` (the :class:`Plan`), the AV's planned and
    human's economy [mpg] on the plan's grid (``av_plan_mpg``, ``av_human_grid_mpg``),
    and from the twin: the AV and its followers' mpg with ``human`` and with the plan
    (``human_mpg``, ``plan_mpg``), the plan's collisions and least time to collision,
    how far the replayed gap strayed from the plan's at a knot (``replay_gap_drift_m``:
    the leader is driven again, and the traffic ahead of it need not do exactly what it
    did) and the replay's time gap p10 and p90 [s]."""
    from twin.control.evolve import _placeable
    from twin.control.vector_env import VectorWaveDampeningEnv

    def env(ego):
        return VectorWaveDampeningEnv(episodes, data, split=split, duration=duration, ego=ego,
                                      seed=seed)  # fmt: skip

    human_env = env("human")
    chosen = _placeable(human_env, iter(range(1000)), episodes)
    observed, human = _drive(human_env, chosen, lambda obs, t: np.zeros(len(chosen)))
    rows, plans = [], {}
    for b, k in enumerate(chosen):
        o = observed[:, b]
        row = {"episode": k, "human_mpg": human[b].get("ego_and_followers_mpg")}
        gap, lead, own = o[:, 2], o[:, 3], o[:, 0]
        if human[b].get("simulated_s", 0.0) < duration - 1e-6:
            rows.append({**row, "status": "ended early"})
            continue
        if _leader_changed(o):
            rows.append({**row, "status": "another leader or none"})
            continue
        sub = round(STEP / FINE_DT)
        end = (o.shape[0] - 1) // sub * sub  # the plan's last knot
        try:
            plan = least_fuel_plan(lead, float(gap[0]), float(own[0]), band=band,
                                   gap_step=gap_step,
                                   end_speed=min(float(own[end]), float(lead[end])))  # fmt: skip
        except ForesightError as error:
            rows.append({**row, "status": str(error)})
            continue
        plans[b] = plan
        rows.append({**row, "status": "planned", "plan": plan,
                     "av_human_grid_mpg": _mpg(*_grid_drive(own[: end + 1 : sub], plan.step)),
                     "av_plan_mpg": _mpg(plan.distance_m, plan.fuel_g)})  # fmt: skip
        if progress:
            print(f"episode {k}: planned ({len(plans)} of {b + 1})", flush=True)
    tracked = sorted(plans)
    if tracked:
        times = FINE_DT * np.arange(1, observed.shape[0] + 1)  # each step's end
        target = np.zeros((times.size, len(chosen)))
        for b in tracked:
            target[:, b] = plans[b].speed_at(times)
        steer = np.isin(np.arange(len(chosen)), tracked)  # the others stand: not counted

        def track(obs, t):
            k = min(round(t / FINE_DT), times.size - 1)
            return np.where(steer, (target[k] - obs[:, 0]) / FINE_DT, 0.0)

        replayed, planned = _drive(env("agent"), chosen, track)
        for b in tracked:
            plan, figures, o = plans[b], planned[b], replayed[:, b]
            knots = o[:: round(plan.step / FINE_DT), 2][: plan.gaps.size]
            drift = float(np.max(np.abs(knots - plan.gaps)))
            time_gaps = o[:, 2] / np.maximum(o[:, 0], TIME_GAP_FLOOR_SPEED)
            rows[b].update({
                "plan_mpg": figures.get("ego_and_followers_mpg"),
                "plan_collisions": figures.get("collisions"),
                "plan_min_ttc_s": figures.get("min_ttc_s"),
                "replay_gap_drift_m": round(drift, 3),
                "replay_time_gap_p10_s": round(float(np.percentile(time_gaps, 10)), 3),
                "replay_time_gap_p90_s": round(float(np.percentile(time_gaps, 90)), 3),
            })  # fmt: skip
            if figures.get("simulated_s", 0.0) < duration - 1e-6:
                rows[b]["status"] = "the replay ended early"
            elif _leader_changed(o):
                rows[b]["status"] = "another leader in the replay"
    return rows


def _leader_changed(observed) -> bool:
    """Whether the observations (T, obs) of one episode show another leader (a gap
    jumping by more than :data:`LEADER_JUMP` beyond what the speeds move it) or none
    within the gap cap."""
    gap, lead, own = observed[:, 2], observed[:, 3], observed[:, 0]
    moved = (lead[:-1] + lead[1:] - own[:-1] - own[1:]) / 2.0 * FINE_DT
    jumps = np.abs(np.diff(gap) - moved) > LEADER_JUMP
    return bool(jumps.any() or gap.max() >= GAP_CAP - 1.0)


def _grid_drive(speeds, step) -> tuple[float, float]:
    """(distance [m], fuel [g]) of speeds at knots ``step`` s apart, a constant
    acceleration between them, on the flat (as a plan is counted)."""
    fuel = sum(_step_fuel(speeds[:-1], np.diff(speeds) / step, step).tolist())  # in order
    return float(((speeds[:-1] + speeds[1:]) / 2.0 * step).sum()), fuel


def _mpg(distance, fuel) -> float | None:
    return economy(distance, fuel)["mpg"]


def _drive(env, chosen, accel):
    """Run ``env``'s sub-envs on episodes ``chosen`` to their end with the accelerations
    ``accel(obs, t)``; the observations from the first to the last (T + 1, B, obs; an
    episode that ended early is another one's after it: check its figures'
    ``simulated_s``) and each episode's figures."""
    obs, _ = env.reset(seed=0, options={"episode": list(chosen)})
    done = np.zeros(len(chosen), dtype=bool)
    seen, figures, step = [obs.astype(np.float64)], [dict() for _ in chosen], 0
    while not done.all():
        action = np.clip(accel(obs.astype(np.float64), step * FINE_DT), *ACCEL_RANGE)
        obs, _, terminated, truncated, info = env.step(action[:, None].astype(np.float32))
        for b in np.flatnonzero((terminated | truncated) & ~done):
            figures[b] = {name: values[b] for name, values in info["metrics"].items()}
        done |= terminated | truncated
        seen.append(obs.astype(np.float64))
        step += 1
    return np.array(seen), figures


def summary(rows: list[dict]) -> dict:
    """The figures of :func:`headroom`'s rows over the planned episodes: the AV's own
    economy change [%] (the plan against ``human`` on the plan's grid) and the AV and
    its followers' in the twin, mean and median, the plans' collisions and the median
    of their least times to collision [s]."""

    def number(value) -> bool:
        return value is not None and math.isfinite(value) and value > 0

    needed = ("plan_mpg", "human_mpg", "av_plan_mpg", "av_human_grid_mpg")
    planned = [
        r for r in rows if r["status"] == "planned" and all(number(r.get(k)) for k in needed)
    ]
    if not planned:
        return {"episodes": len(rows), "planned": 0}
    own = np.array([100.0 * (r["av_plan_mpg"] / r["av_human_grid_mpg"] - 1.0) for r in planned])
    group = np.array([100.0 * (r["plan_mpg"] / r["human_mpg"] - 1.0) for r in planned])
    ttc = [r["plan_min_ttc_s"] for r in planned if r["plan_min_ttc_s"] is not None]
    return {
        "episodes": len(rows),
        "planned": len(planned),
        "av_economy_pct_mean": round(float(own.mean()), 2),
        "av_economy_pct_median": round(float(np.median(own)), 2),
        "av_and_followers_economy_pct_mean": round(float(group.mean()), 2),
        "av_and_followers_economy_pct_median": round(float(np.median(group)), 2),
        "collisions": int(sum(r["plan_collisions"] for r in planned)),
        "min_ttc_s_median": round(float(np.median(ttc)), 2) if ttc else None,
    }
