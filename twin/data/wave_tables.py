"""The wave tables of :mod:`twin.data.wave_analysis`: written and read in the I-24
MOTION team's layout (``lane_N/wave_front_15.csv``, ``wave_tail_15.csv``,
``CC_15.csv``), summarised, drawn, and compared with the real 2022-11-22 westbound
morning (the twin's reference, ``assets/i24_waves_2022-11-22.json``)."""

import json
from pathlib import Path

import pandas as pd

from twin.core import i24
from twin.core.atomic import AtomicFolder, marked_as
from twin.core.i24 import Road
from twin.data.wave_analysis import (
    LANE_NUMBER,
    MPH,
    POINT_COLUMNS,
    REAL_MILES,
    REFERENCE_MPH,
    LaneWaves,
    WaveAnalysisError,
    statistics,
)


def read_tables(
    folder: str | Path, miles: float = REAL_MILES, road: Road | str = Road.WESTBOUND
) -> dict[int, LaneWaves]:
    """The tables of a folder of ``lane_N/`` (the tool's output, or this module's).

    Raises:
        WaveAnalysisError: no ``lane_N`` folder, or a table missing columns.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise WaveAnalysisError(f"{folder} is not a folder of wave tables")
    if is_waves_folder(folder):  # written here: it knows its miles and road
        doc = json.loads((folder / "waves.json").read_text())
        road = doc.get("road", road)
        miles = next(iter(doc["lanes"].values()), {}).get("miles", miles)
    out = {}
    for lane in i24.LANES:
        sub = folder / f"lane_{LANE_NUMBER[lane]}"
        if not sub.is_dir():
            continue
        tables = {}
        for name in ("wave_front_15", "wave_tail_15", "CC_15"):
            path = sub / f"{name}.csv"
            if not path.is_file():
                raise WaveAnalysisError(f"{path} is missing")
            try:
                table = pd.read_csv(path)
            except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as e:
                raise WaveAnalysisError(f"{path} is not a readable CSV table: {e}") from None
            need = (
                POINT_COLUMNS
                if name != "CC_15"
                else ["time_front", "space_front", "time_tail", "c_id"]
            )
            missing = [c for c in need if c not in table.columns]
            if missing:
                raise WaveAnalysisError(f"{path} lacks the columns {', '.join(missing)}")
            tables[name] = table
        out[lane] = LaneWaves(
            LANE_NUMBER[lane],
            Road.parse(road),
            tables["wave_front_15"],
            tables["wave_tail_15"],
            tables["CC_15"],
            miles,
        )
    if not out:
        raise WaveAnalysisError(f"{folder} has no lane_1 .. lane_4 folders of wave tables")
    return out


def summary(lanes: dict[int, LaneWaves]) -> dict:
    """``{"lane_N": statistics}`` of every lane."""
    return {
        f"lane_{w.lane}": statistics(w.front, w.cc, w.miles, road=w.road)
        for _, w in sorted(lanes.items(), key=lambda kv: kv[1].lane)
    }


FORMAT = "i24-twin-waves"


def is_waves_folder(folder: Path) -> bool:
    """True for a folder ``write_tables`` wrote."""
    return marked_as(folder, "waves.json", FORMAT)


def write_tables(lanes: dict[int, LaneWaves], out: str | Path, meta: dict) -> Path:
    """Write every lane's tables, ``waves.json`` (``meta`` and the statistics) and
    ``waves.png`` (fronts and tails over each lane's time-space diagram) into ``out``,
    replaced as a whole (an existing folder only if it is one of these).

    Raises:
        WaveAnalysisError: ``out`` exists and is something else.
    """
    folder = AtomicFolder(Path(out), recognise=is_waves_folder, kind="waves folder",
                          error=WaveAnalysisError)  # fmt: skip
    with folder:
        for w in lanes.values():
            sub = folder.tmp / f"lane_{w.lane}"
            sub.mkdir()
            for name, table in (
                ("wave_front_15", w.front),
                ("wave_tail_15", w.tail),
                ("CC_15", w.cc),
            ):
                table.to_csv(sub / f"{name}.csv", index=False)
        doc = {"format": FORMAT, "version": 1, **meta, "lanes": summary(lanes)}
        (folder.tmp / "waves.json").write_text(json.dumps(doc, indent=1) + "\n")
        plot_waves(lanes, folder.tmp / "waves.png", meta.get("title", "waves"),
                   meta.get("start_unix"))  # fmt: skip
    return Path(out)


#: One colour per wave (Okabe-Ito, apart from the speed scale's blues and yellows).
WAVE_COLOURS = ("#D55E00", "#CC79A7", "#009E73", "#E69F00", "#56B4E9")


def waves_figure(lanes: dict[int, LaneWaves], title: str, start_unix: float | None = None):
    """Each lane's virtual trajectories coloured by speed, with the fronts (hollow
    triangles) and tails (filled circles) of its waves, a colour per wave; a matplotlib
    figure, made without pyplot (the caller's backend and figures are left alone). Lanes
    are numbered as the I-24 tables number them (1 the HOV lane, the twin's -1). Speeds
    in m/s with mph beside them (the tables' unit).

    Args:
        lanes: the lanes' tables and virtual trajectories.
        title: the figure's title.
        start_unix: [s] unix time of the span's start, to label the time axis with the
            clock; ``None``: seconds from the start of the span.
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    from twin.data.plot import SPEED_CMAP, SPEED_RANGE, clock

    shown = sorted(lanes.values(), key=lambda w: w.lane)
    fig = Figure(figsize=(12, 2.6 * len(shown) + 1.4), layout="constrained")
    axes = fig.subplots(len(shown), 1, sharex=True, squeeze=False)
    points = None
    for ax, w in zip(axes[:, 0], shown, strict=True):
        vt = w.trajectories
        if vt is not None:
            every = vt.v_id % 2 == 0  # every other virtual vehicle is enough to see
            points = ax.scatter(vt.time[every], i24.mile_marker(vt.x[every], w.road),
                                c=vt.speed[every], s=1.2, cmap=SPEED_CMAP, vmin=SPEED_RANGE[0],
                                vmax=SPEED_RANGE[1], rasterized=True, linewidths=0)  # fmt: skip
        for k, c in enumerate(pd.unique(w.cc["c_id"]) if len(w.cc) else []):
            rows = w.cc[w.cc["c_id"] == c]
            colour = WAVE_COLOURS[k % len(WAVE_COLOURS)]
            ax.scatter(rows["time_front"], rows["space_front"], marker="^", s=10,
                       facecolors="none", edgecolors=[colour], linewidths=0.7)  # fmt: skip
            ax.scatter(rows["time_tail"], rows["space_tail"], marker="o", s=6, color=colour)
        twin_lane = f"twin lane {-w.lane}{', HOV' if w.lane == 1 else ''}"
        ax.set_title(f"lane {w.lane} ({twin_lane}): "
                     f"{_lane_caption(statistics(w.front, w.cc, w.miles, road=w.road))}",
                     fontsize=9, loc="left")  # fmt: skip
        ax.set_ylabel("mile marker")
        if w.road is Road.WESTBOUND:
            ax.invert_yaxis()  # travel goes up the page either way
        ax.grid(alpha=0.2)
    axes[0, 0].legend(
        handles=[
            Line2D([], [], ls="", marker="^", mfc="none", mec="black",
                   label=f"wave front: slowing through {REFERENCE_MPH:g} mph"),
            Line2D([], [], ls="", marker="o", color="black",
                   label=f"wave tail: speeding up through {REFERENCE_MPH:g} mph"),
            Line2D([], [], ls="", marker="s", color=WAVE_COLOURS[0],
                   label=f"a colour per wave ({len(WAVE_COLOURS)} colours, repeated in turn)"),
        ],
        loc="upper right", fontsize=8, framealpha=0.9,
    )  # fmt: skip
    axes[-1, 0].set_xlabel(
        "time [s] from the start of the span"
        if start_unix is None
        else f"time [s] after {clock(start_unix)}"
    )
    if points is not None:
        bar = fig.colorbar(points, ax=axes[:, 0], label="speed [m/s]", shrink=0.6)
        mph = bar.ax.secondary_yaxis("left", functions=(lambda v: v / MPH, lambda v: v * MPH))
        mph.set_ylabel("speed [mph]")
    fig.suptitle(title)
    return fig


def _lane_caption(stats: dict) -> str:
    """One lane's figures for its panel's title: 'no wave', or the waves' figures."""
    if not stats["waves"]:
        return "no wave"
    speed = stats["front_speed_mps"]["median"]
    gap = stats["front_to_tail_s"]["median"]
    parts = [
        f"{stats['waves']} wave{'s' if stats['waves'] > 1 else ''}",
        f"{stats['fronts_per_vehicle_mile']:.2f} fronts per vehicle-mile",
    ]
    if speed is not None:
        parts.append(f"fronts move upstream at {speed:.1f} m/s ({speed / MPH:.1f} mph)")
    if gap is not None:
        parts.append(f"front to tail {gap:.0f} s")
    return ", ".join(parts)


def plot_waves(
    lanes: dict[int, LaneWaves], out: Path, title: str, start_unix: float | None = None
) -> Path:
    """Write :func:`waves_figure` as a PNG (a temporary name, then renamed)."""
    from twin.data.plot import save_figure

    return save_figure(waves_figure(lanes, title, start_unix), out, dpi=100)


# -- the real morning as the reference -------------------------------------------------

REFERENCE_ASSET = "i24_waves_2022-11-22.json"
#: The bounds a realistic day meets against the real lane (issue 18): fronts per vehicle
#: per mile and the front-to-tail median within 30 %, the front speed median inside the
#: real lane's interquartile range.
RELATIVE_BOUND = 0.30


def reference() -> dict:
    """The real 2022-11-22 westbound figures (``assets/i24_waves_2022-11-22.json``, made
    by :func:`summary` from the shared tables; a test checks it against them)."""
    from twin.core.paths import asset

    return json.loads(asset(REFERENCE_ASSET).read_text())


def compare(ours: dict, real: dict) -> list[dict]:
    """Lane by lane, our figures beside the real ones and whether each is within the
    bounds (``None`` where ours cannot be measured: no wave)."""
    rows = []
    for lane in sorted(real):
        r, o = real[lane], ours.get(lane)
        checks = {}
        if o is not None:
            fronts = o["fronts_per_vehicle_mile"]
            tail = o["front_to_tail_s"]["median"]
            speed = o["front_speed_mps"]["median"]
            checks = {
                "fronts_per_vehicle_mile": fronts is not None
                and abs(fronts / r["fronts_per_vehicle_mile"] - 1.0) <= RELATIVE_BOUND,
                "front_to_tail_median": tail is not None
                and abs(tail / r["front_to_tail_s"]["median"] - 1.0) <= RELATIVE_BOUND,
                "front_speed_in_real_iqr": speed is not None
                and r["front_speed_mps"]["p25"] <= speed <= r["front_speed_mps"]["p75"],
            }
        rows.append({"lane": lane, "ours": o, "real": r, "within": checks})
    return rows


def format_comparison(rows: list[dict], label: str = "this span") -> str:
    """A plain-text table of :func:`compare`'s rows."""

    def cell(stats, key):
        if stats is None:
            return "no data"
        if key == "fronts":
            return f"{stats['fronts_per_vehicle_mile']:.2f}"
        if key == "tail":
            t = stats["front_to_tail_s"]
            return "-" if t["median"] is None else f"{t['median']:.0f} s (p90 {t['p90']:.0f})"
        s = stats["front_speed_mps"]
        if s["median"] is None:
            return "-"
        return f"{s['median']:.1f} ({s['p25']:.1f} to {s['p75']:.1f})"

    mark = {True: "ok", False: "OUT", None: ""}
    lines = [
        f"{'lane':<7} {'':<10} {'waves':>5}  {'fronts/veh/mile':>15}  {'front to tail':>19}  "
        f"{'front speed m/s (IQR)':>22}",
    ]
    for row in rows:
        name = row["lane"].replace("lane_", "")
        name += " (HOV)" if name == "1" else ""
        w = row["within"]
        for who, stats in ((label, row["ours"]), ("real", row["real"])):
            waves = "-" if stats is None else str(stats["waves"])
            flags = ("", "", "")
            if who != "real" and w:
                flags = tuple(
                    mark[w[k]]
                    for k in ("fronts_per_vehicle_mile", "front_to_tail_median",
                              "front_speed_in_real_iqr")
                )  # fmt: skip
            lines.append(
                f"{name:<7} {who[:10]:<10} {waves:>5}  {cell(stats, 'fronts'):>11} {flags[0]:>3}  "
                f"{cell(stats, 'tail'):>15} {flags[1]:>3}  {cell(stats, 'speed'):>18} {flags[2]:>3}"
            )
            name = ""
    return "\n".join(lines)
