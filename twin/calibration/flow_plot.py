"""The picture of a recording's lane-change flows (:mod:`twin.calibration.lane_flows`):
changes by lane pair and the net flow out of each lane along the road, the recording's
beside a simulation's where one is given."""

from pathlib import Path

import numpy as np

from twin.core.atomic import atomic_file
from twin.core.i24 import LANES, SEGMENT_LENGTH

#: Okabe-Ito colours, told apart by colour-blind readers; line styles tell recorded
#: (solid, markers) from simulated (dashed)
COLOURS = ("#0072B2", "#E69F00", "#009E73", "#D55E00", "#CC79A7", "#56B4E9", "#F0E442")


def plot_lane_flows(flows: dict, out: Path, *, title: str, simulated: dict | None = None) -> Path:
    """Draw ``flows`` (and ``simulated``, flows of the same bins) into the PNG ``out``
    (atomically); returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    edges = np.asarray(flows["x_edges"])
    mid = 0.5 * (edges[1:] + edges[:-1])
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    pairs = sorted(set(flows["pairs"]) | set((simulated or {}).get("pairs", {})))
    for j, name in enumerate(pairs):
        colour = COLOURS[j % len(COLOURS)]
        recorded = flows["pairs"].get(name)
        if recorded:
            top.plot(
                mid, recorded["by_position"], "-o", ms=3, color=colour, label=f"{name} recorded"
            )
        if simulated and name in simulated["pairs"]:
            top.plot(
                mid, simulated["pairs"][name]["by_position"], "--", color=colour,
                label=f"{name} simulated",
            )  # fmt: skip
    top.set_ylabel(f"lane changes per {flows['position_bin_m']:.0f} m")
    top.set_title("Lane changes by lane pair (from>to)")
    for k, lane in enumerate(LANES):
        colour = COLOURS[k]
        bottom.plot(
            mid, flows["net_out"][str(lane)], "-o", ms=3, color=colour,
            label=f"lane {lane} recorded",
        )  # fmt: skip
        if simulated:
            bottom.plot(
                mid, simulated["net_out"][str(lane)], "--", color=colour,
                label=f"lane {lane} simulated",
            )  # fmt: skip
    bottom.axhline(0.0, color="0.5", lw=0.8)
    bottom.set_ylabel(f"net flow out of the lane per {flows['position_bin_m']:.0f} m")
    bottom.set_title("Net flow out of each lane (changes leaving less changes entering)")
    bottom.set_xlabel("position along the road x [m] (direction of travel)")
    for ax in (top, bottom):
        for x in (0.0, SEGMENT_LENGTH):
            ax.axvline(x, color="0.3", ls=":", lw=1.0)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:  # a road with no changes has none to name
            ax.legend(fontsize=7, ncol=2, loc="upper left")
    if not pairs:
        top.text(0.5, 0.5, "no lane changes", transform=top.transAxes, ha="center")
    top.text(0.0, 1.0, " segment", transform=top.get_xaxis_transform(), va="top", fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    out = Path(out)
    with atomic_file(out) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return out
