"""Lane changes by zone of the road, simulated against recorded: before a lane drop,
in the weave at an on-ramp, and elsewhere.

Where a lane change is made says why it is made: before a lane that ends, its drivers
must leave it (mandatory changes); after an on-ramp's gore, merging vehicles and the
drivers making room for them weave; elsewhere, drivers change for speed or to keep
right (discretionary changes). A twin can get the count right overall and still make
the wrong ones, so the counts are compared zone by zone.

The zones, in the road frame of a carriageway (x [m] along travel, 0 at the segment's
upstream end):

- ``before_drop``: the :data:`BEFORE_DROP` metres upstream of where a lane ends (a
  drop past the segment's downstream end still has its upstream part inside it);
- ``weave``: each on-ramp's acceleration lane, from its gore to :data:`WEAVE_AFTER`
  metres past where its taper ends (:mod:`twin.core.ramps`);
- ``elsewhere``: the rest.

A place in both a drop's zone and a weave counts as before the drop. Where a lane
ends is given where it is known (a family day's parameters file names its
``drop_x``) or found in the recording (:func:`recorded_lane_ends`: a through lane that
the recorded traffic stops using inside the segment).

The changes are those of an evaluation's ``lane_flows`` section
(:mod:`twin.metrics.lane_flow_fidelity`: ``changes.simulated_x`` and
``changes.recorded_x``, where each was made).
"""

from dataclasses import dataclass

import numpy as np

from twin.core.i24 import N_LANES, Road
from twin.core.ramps import SEGMENT_LENGTH, segment_ramps
from twin.metrics.table import section_head

ZONES = ("before_drop", "weave", "elsewhere")
BEFORE_DROP = 500.0  # [m] upstream of a lane's end: where its drivers must leave it
WEAVE_AFTER = 100.0  # [m] past an on-ramp's taper end: where its merged vehicles settle
# recorded_lane_ends: bins [m], the share of its upstream use below which a lane has
# ended, and how much of the segment's upstream part sets that use
END_BIN = 50.0
END_SHARE = 0.05
UPSTREAM_SHARE = 0.5
LANES = tuple(range(-1, -N_LANES - 1, -1))


@dataclass(frozen=True)
class Zones:
    """The zones of one carriageway (module doc) as ``(x_from, x_to)`` intervals [m].

    Attributes:
        drops: the ``before_drop`` intervals.
        weaves: the ``weave`` intervals.
    """

    drops: tuple[tuple[float, float], ...] = ()
    weaves: tuple[tuple[float, float], ...] = ()

    def of(self, x) -> np.ndarray:
        """The zone (an index of :data:`ZONES`) of each place ``x`` [m]."""
        x = np.asarray(x, dtype=np.float64)
        zone = np.full(x.shape, ZONES.index("elsewhere"), dtype=np.int64)
        for (a, b), name in [(w, "weave") for w in self.weaves] + [
            (d, "before_drop") for d in self.drops
        ]:  # drops last: they win where both hold
            zone[(x >= a) & (x < b)] = ZONES.index(name)
        return zone

    def describe(self) -> str:
        """One line of where the zones are."""
        parts = [f"before a drop {a:.0f} to {b:.0f} m" for a, b in self.drops]
        parts += [f"weave {max(a, 0.0):.0f} to {b:.0f} m" for a, b in self.weaves]
        return "; ".join(parts) if parts else "no drop or on-ramp: all elsewhere"

    def to_dict(self) -> dict:
        return {"drops": [list(d) for d in self.drops], "weaves": [list(w) for w in self.weaves]}


def road_zones(road, drop_x=None) -> Zones:
    """The zones of ``road`` (a :class:`~twin.core.i24.Road` or its name): its on-ramps'
    weaves and, where ``drop_x`` [m] (a number or a sequence of them; None: no drop)
    says where lanes end, the stretch before each."""
    road = Road.parse(road) if isinstance(road, str) else road
    drops = () if drop_x is None else np.atleast_1d(np.asarray(drop_x, dtype=np.float64))
    for x in drops:
        if not np.isfinite(x):
            raise ValueError(f"a lane drop's x must be a finite number of metres, got {x!r}")
    return Zones(
        drops=tuple((float(x) - BEFORE_DROP, float(x)) for x in drops),
        weaves=tuple((r.x_start, r.x_end + WEAVE_AFTER) for r in segment_ramps() if r.road == road),
    )


def recorded_lane_ends(lane: np.ndarray, x: np.ndarray, length: float) -> list[float]:
    """Where [m] through lanes that the recorded traffic stops using end, in a
    segment of ``length`` [m]: ``lane`` and ``x`` (n,) are the recording's samples (any
    regular sampling). A lane ends at the upstream edge of the first :data:`END_BIN`
    from which, to the segment's end, its samples per bin stay under
    :data:`END_SHARE` of their median over the segment's upstream half. Sorted; empty
    where every lane runs through."""
    lane = np.asarray(lane)
    x = np.asarray(x, dtype=np.float64)
    edges = np.arange(0.0, length + END_BIN, END_BIN)
    if edges.size < 3:
        return []
    upstream = edges[:-1] < UPSTREAM_SHARE * length
    ends = []
    for k in LANES:
        counts = np.histogram(x[lane == k], edges)[0]
        use = np.median(counts[upstream]) if upstream.any() else 0.0
        if use <= 0:
            continue  # a lane never used is no drop
        low = counts < END_SHARE * use
        # the first bin from which every bin to the end is low
        tail = np.flip(np.cumprod(np.flip(low)))
        first = int(np.argmax(tail)) if tail.any() else -1
        if first > 0 and tail[first] and not upstream[first]:
            ends.append(float(edges[first]))
    return sorted(set(ends))


def by_zone(changes: dict | None, zones: Zones) -> dict:
    """``{zone: {"simulated", "recorded", "ratio"}}`` of the changes (a summed
    ``lane_flows`` section's ``changes``; None: not counted, every count None)."""
    out = {}
    simulated = zones.of(changes["simulated_x"]) if changes else None
    recorded = zones.of(changes["recorded_x"]) if changes else None
    for k, name in enumerate(ZONES):
        if changes is None:
            out[name] = {"simulated": None, "recorded": None, "ratio": None}
            continue
        sim, rec = int(np.count_nonzero(simulated == k)), int(np.count_nonzero(recorded == k))
        out[name] = {"simulated": sim, "recorded": rec, "ratio": _ratio(sim, rec)}
    return out


def describe(counts: dict) -> str:
    """``by_zone``'s counts as one line: simulated / recorded by zone."""
    parts = []
    for name in ZONES:
        c = counts.get(name) or {}
        if c.get("simulated") is None:
            continue
        parts.append(f"{name.replace('_', ' ')} {c['simulated']} / {c['recorded']}")
    return "; ".join(parts)


def _ratio(simulated: int, recorded: int) -> float | None:
    return round(simulated / recorded, 4) if recorded else None


def store_zones(store, road, drop_x=None) -> Zones:
    """The zones of ``road`` in ``store``'s recording: :func:`road_zones` with the
    lanes' ends ``drop_x`` where given, else where the recording shows them
    (:func:`recorded_lane_ends` over the whole recording of the road)."""
    road = Road.parse(road) if isinstance(road, str) else road
    if drop_x is None:
        first, last = store.time_range(road)
        samples = store.samples(road, first, last)
        drop_x = recorded_lane_ends(samples["lane"], samples["x"], SEGMENT_LENGTH) or None
    return road_zones(road, drop_x)


def markdown(by_arm: dict, zones: Zones) -> str:
    """The counts by zone of each arm (``{arm: by_zone(...)}``) as a Markdown table."""
    arms = [a for a, c in by_arm.items() if c]
    if not arms:
        return ""
    lines = section_head(
        f"Lane changes by zone (simulated / recorded; {zones.describe()})", "zone", arms
    )
    for name in ZONES:
        cells = []
        for arm in arms:
            c = by_arm[arm][name]
            cells.append("-" if c["simulated"] is None else f"{c['simulated']} / {c['recorded']}")
        lines.append(f"| {name.replace('_', ' ')} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
