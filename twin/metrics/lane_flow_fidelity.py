"""Lane changes by lane pair and the net lane flow by position, simulated against
recorded in the same moving visible window: the ``lane_flows`` section of a run's
``metrics.json``, and its sums over the episodes of ``twin eval``.

A lane change is counted as the calibration counts the recording's
(:func:`twin.calibration.following.held_changes`: a new lane held for
``LANE_HOLD``), at the place its vehicle first is in the new lane. The recorded changes
counted are those inside the visible window at their time, the simulated ones are the
simulated vehicles' (always inside it). The net flow out of a lane in a bin is the
changes out of it minus the changes into it there; ``changes`` holds where every change
was made (``simulated_x``, ``recorded_x``), for the rates by zone
(:mod:`twin.metrics.lane_change_zones`).
Bins are :data:`BIN` metres, on a grid fixed to the road frame (edges at multiples of
:data:`BIN`) so that episodes add up.
"""

import numpy as np
import pandas as pd

from twin.calibration import following
from twin.core.i24 import N_LANES
from twin.metrics import fidelity
from twin.metrics.table import section_head

BIN = 200.0  # [m] the net flow's bins along the road
LANES = tuple(range(-1, -N_LANES - 1, -1))
#: the adjacent lane pairs (from, to), left to right then right to left
PAIRS = tuple((a, a - 1) for a in LANES[:-1]) + tuple((a - 1, a) for a in LANES[:-1])
WITHIN = 0.3  # the tolerance on each bin's net flow (relative)
MIN_BIN_FLOW = 10  # bins whose recorded net flow is smaller are not judged one by one


def pair_key(lane_from: int, lane_to: int) -> str:
    return f"{lane_from}>{lane_to}"


def simulated_changes(vehicles: pd.DataFrame, dt: float) -> pd.DataFrame:
    """The simulated vehicles' lane changes in a run's log (``vehicles``: every step),
    as ``time`` [s since t0], ``x`` [m], ``lane_from``, ``lane_to``: between the through
    lanes, as the recording's are found (a merge from an on-ramp's lane is none:
    :mod:`twin.metrics.merges`)."""
    rows = vehicles.sort_values(["id", "time"], kind="stable")
    row, lane_from, lane_to = following.held_changes(
        rows["id"].to_numpy(), rows["lane"].to_numpy(), round(following.LANE_HOLD / dt)
    )
    through = np.isin(lane_from, LANES) & np.isin(lane_to, LANES)
    row, lane_from, lane_to = row[through], lane_from[through], lane_to[through]
    return pd.DataFrame(
        {
            "time": rows["time"].to_numpy()[row],
            "x": rows["x"].to_numpy()[row],
            "lane_from": lane_from,
            "lane_to": lane_to,
        }
    )


def recorded_changes_in_window(changes, windows: pd.DataFrame, t0: float) -> pd.DataFrame:
    """The recording's lane changes (:class:`~twin.calibration.following.LaneChanges`)
    inside the moving visible window (``windows``: ``time`` [s since t0], ``x0``,
    ``x1``), in the same columns as :func:`simulated_changes`."""
    frame = pd.DataFrame(
        {
            "time": np.asarray(changes.time, dtype=np.float64) - t0,
            "x": changes.x,
            "lane_from": changes.lane_from,
            "lane_to": changes.lane_to,
        }
    )
    inside = fidelity.in_moving_window(frame["time"].to_numpy(), frame["x"].to_numpy(), windows)
    return frame[inside].reset_index(drop=True)


def episode_section(simulated: pd.DataFrame, recorded: pd.DataFrame, windows) -> dict:
    """The ``lane_flows`` section of a run's ``metrics.json``: changes by lane pair
    (simulated, recorded) and the net flow out of each lane by bin, over the bins the
    visible window covered."""
    lo = np.floor(windows["x0"].min() / BIN) * BIN
    hi = np.ceil(windows["x1"].max() / BIN) * BIN
    edges = np.arange(lo, hi + BIN / 2, BIN)
    pairs = {pair_key(a, b): [_count(simulated, a, b), _count(recorded, a, b)] for a, b in PAIRS}
    net = {
        str(lane): {
            "simulated": _net_out(simulated, lane, edges).tolist(),
            "recorded": _net_out(recorded, lane, edges).tolist(),
        }
        for lane in LANES
    }
    changes = {"simulated_x": _places(simulated), "recorded_x": _places(recorded)}
    return {
        "bin_m": BIN, "x_edges": edges.tolist(), "pairs": pairs, "net_out": net,
        "changes": changes,
    }  # fmt: skip


def _places(changes: pd.DataFrame) -> list[float]:
    """Where [m, road frame, to 0.1 m] each change was made, in increasing order."""
    if changes.empty:
        return []
    return np.round(np.sort(changes["x"].to_numpy(dtype=np.float64)), 1).tolist()


def _count(changes: pd.DataFrame, lane_from: int, lane_to: int) -> int:
    if changes.empty:
        return 0
    return int(
        np.count_nonzero((changes["lane_from"] == lane_from) & (changes["lane_to"] == lane_to))
    )


def _net_out(changes: pd.DataFrame, lane: int, edges: np.ndarray) -> np.ndarray:
    """(bins,) changes out of ``lane`` minus changes into it, by bin."""
    if changes.empty:
        return np.zeros(edges.size - 1, dtype=np.int64)
    x = changes["x"].to_numpy()
    out = np.histogram(x[changes["lane_from"].to_numpy() == lane], edges)[0]
    into = np.histogram(x[changes["lane_to"].to_numpy() == lane], edges)[0]
    return out - into


def sum_episodes(sections) -> dict | None:
    """The ``lane_flows`` sections of many runs added up (bins aligned on the road
    frame), with the figures the issue judges: the lane changes simulated over
    recorded, and the net flow's error (the sum over lanes and bins of
    |simulated - recorded| over the sum of |recorded|, and the share of bins with a
    recorded net flow of at least :data:`MIN_BIN_FLOW` whose simulated one is within
    :data:`WITHIN`). None when no section is given."""
    sections = [s for s in sections if s]
    if not sections:
        return None
    # one contiguous grid over every bin any episode covered (zeros where none did)
    first = min(s["x_edges"][0] for s in sections)
    last = max(s["x_edges"][-1] for s in sections)
    starts = [round(x, 6) for x in np.arange(first, last - BIN / 2, BIN)]
    index = {x: k for k, x in enumerate(starts)}
    net = {str(lane): np.zeros((2, len(starts)), dtype=np.int64) for lane in LANES}
    pairs = {pair_key(a, b): np.zeros(2, dtype=np.int64) for a, b in PAIRS}
    places = {"simulated_x": [], "recorded_x": []}
    for s in sections:
        columns = [index[round(x, 6)] for x in s["x_edges"][:-1]]
        for name, xs in s.get("changes", {}).items():  # none in sections from before
            places[name].extend(xs)
        for lane, both in s["net_out"].items():
            net[lane][0, columns] += np.asarray(both["simulated"], dtype=np.int64)
            net[lane][1, columns] += np.asarray(both["recorded"], dtype=np.int64)
        for key, (sim, rec) in s["pairs"].items():
            pairs[key] += (sim, rec)
    stacked = np.stack(list(net.values()))  # (lanes, 2, bins)
    sim, rec = stacked[:, 0], stacked[:, 1]
    judged = np.abs(rec) >= MIN_BIN_FLOW
    within = np.abs(sim - rec) <= WITHIN * np.abs(rec)
    total_rec = int(np.abs(rec).sum())
    changes_sim = int(sum(p[0] for p in pairs.values()))
    changes_rec = int(sum(p[1] for p in pairs.values()))
    return {
        "bin_m": BIN,
        "x_edges": starts + ([starts[-1] + BIN] if starts else []),
        "pairs": {k: {"simulated": int(v[0]), "recorded": int(v[1])} for k, v in pairs.items()},
        "net_out": {
            lane: {"simulated": v[0].tolist(), "recorded": v[1].tolist()} for lane, v in net.items()
        },
        "changes": {name: sorted(xs) for name, xs in places.items()},
        "episodes_summed": len(sections),
        "changes_simulated": changes_sim,
        "changes_recorded": changes_rec,
        "changes_ratio": round(changes_sim / changes_rec, 4) if changes_rec else None,
        "net_flow_error": round(float(np.abs(sim - rec).sum()) / total_rec, 4)
        if total_rec
        else None,
        "bins_judged": int(judged.sum()),
        "bins_within": int((judged & within).sum()),
    }


def markdown(by_arm: dict) -> str:
    """The sums of :func:`sum_episodes` per arm as Markdown: changes by lane pair and the
    net flow's figures (simulated / recorded)."""
    arms = [a for a, s in by_arm.items() if s]
    if not arms:
        return ""
    lines = section_head(
        "Lane changes held 1 s, by lane pair, and net lane flow (simulated / recorded, "
        "summed over the episodes)",
        "lane pair",
        arms,
    )
    for a, b in PAIRS:
        key = pair_key(a, b)
        cells = [
            f"{by_arm[x]['pairs'][key]['simulated']} / {by_arm[x]['pairs'][key]['recorded']}"
            for x in arms
        ]
        lines.append(f"| {a} to {b} | " + " | ".join(cells) + " |")
    lines.append(
        "| episodes summed | " + " | ".join(str(by_arm[x]["episodes_summed"]) for x in arms) + " |"
    )
    err = [by_arm[x]["net_flow_error"] for x in arms]
    lines.append(
        f"| net flow error by {BIN:g} m bin (sum of abs errors / sum of abs recorded) | "
        + " | ".join("-" if e is None else f"{e:.2f}" for e in err)
        + " |"
    )
    lines.append(
        f"| bins with recorded net flow >= {MIN_BIN_FLOW} within {WITHIN:.0%} | "
        + " | ".join(f"{by_arm[x]['bins_within']} of {by_arm[x]['bins_judged']}" for x in arms)
        + " |"
    )
    return "\n".join(lines) + "\n"


def draw(axes_pairs, axes_lanes, by_arm: dict) -> None:
    """Changes by lane pair (grouped bars, recorded first) on ``axes_pairs`` and the
    net flow out of each lane by bin (recorded black, each arm its own line and marker)
    on ``axes_lanes`` (one per lane, -1 to -4)."""
    arms = [a for a, s in by_arm.items() if s]
    styles = ("o-", "s--", "^-.", "D:", "v-")
    labels = [pair_key(a, b).replace(">", " to ") for a, b in PAIRS]
    width = 0.8 / (len(arms) + 1)
    x = np.arange(len(PAIRS))
    if arms:
        first = by_arm[arms[0]]
        recorded = [first["pairs"][pair_key(a, b)]["recorded"] for a, b in PAIRS]
        axes_pairs.bar(x, recorded, width, color="black", label="the recording")
        hatches = ("//", "..", "xx", "\\\\", "oo")
        for k, arm in enumerate(arms):
            values = [by_arm[arm]["pairs"][pair_key(a, b)]["simulated"] for a, b in PAIRS]
            axes_pairs.bar(
                x + (k + 1) * width, values, width, label=arm, fill=False,
                hatch=hatches[k % len(hatches)], edgecolor=f"C{k}",
            )  # fmt: skip
    axes_pairs.set_xticks(x + 0.4 - width / 2, labels, rotation=45, fontsize=8)
    axes_pairs.set_ylabel("lane changes, summed [count]")
    axes_pairs.set_title("lane changes held 1 s, by lane pair")
    if arms:
        axes_pairs.legend(fontsize=7)
    else:
        axes_pairs.text(
            0.5, 0.5, "no lane flows measured", ha="center", transform=axes_pairs.transAxes
        )
    for ax, lane in zip(axes_lanes, LANES, strict=True):
        for k, arm in enumerate(arms):
            s = by_arm[arm]
            centres = np.asarray(s["x_edges"][:-1]) + BIN / 2
            if k == 0:
                ax.plot(
                    centres, s["net_out"][str(lane)]["recorded"], "k-", lw=2, label="the recording"
                )
            ax.plot(
                centres, s["net_out"][str(lane)]["simulated"], styles[k % len(styles)],
                color=f"C{k}", ms=4, label=arm,
            )  # fmt: skip
        ax.axhline(0.0, color="grey", lw=0.5)
        ax.set_title(f"net flow out of lane {lane}{' (HOV)' if lane == -1 else ''}")
        ax.set_xlabel("x along the road [m]")
        ax.set_ylabel(f"changes out - in per {BIN:g} m")
        if arms:
            ax.legend(fontsize=7)
