"""``docs/benchmarks.md`` from the JSON lines ``twin bench`` prints.

Each benchmark prints one JSON object: its figures (medians of its repeats), the
options it ran with and the context of :func:`twin.perf.common.context` (commit, date,
machine). This module turns any number of such lines into one Markdown page: a table
of every figure with its unit, the runs with their settings, date and commit, and the
machines they ran on. Nothing in the page is typed by hand, so measuring again and
regenerating (``twin bench report --run ... --out docs/benchmarks.md``) replaces it.
"""

import inspect
import json
import os
import re
import subprocess
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from twin.core.atomic import atomic_file
from twin.core.errors import TwinError

#: What ``--run`` without names runs: the benchmarks well under a few minutes each on two
#: cores, in that order. ``camera``, ``ingest`` and ``eval`` take a few minutes more and
#: are named to run; ``dataset`` and ``worlds`` are long and are run by hand, their lines
#: passed to the report.
QUICK = ("query", "synth", "map", "physics", "traffic", "run", "calibrate", "env")

#: Keys of a line that describe the run, not a figure.
CONTEXT_KEYS = frozenset(
    {"bench", "commit", "dirty", "date", "python", "cpus", "machine", "options", "targets"}
)
#: Keys of a line that repeat a setting of the benchmark (how much it timed).
SETTING_KEYS = frozenset(
    {
        "calls_per_repeat",
        "camera_rate_hz",
        "dt",
        "duration_s",
        "episodes",
        "frames",
        "frames_per_episode",
        "minutes",
        "repeats",
        "steps",
        "vector_workers",
        "vehicles",
        "window_m",
    }
)
#: Keys of a line that break a figure down further than the page needs.
DETAIL_KEYS = frozenset({"triangles_per_part"})
#: Units by the ending of a figure's key, tried in order (the first that matches wins).
UNIT_SUFFIXES = (
    ("_mb_s", "MB/s"),
    ("steps_per_s", "steps/s"),
    ("fps_per_busy_core", "frames/s per core"),
    ("s_per_wall_s", "x real time"),
    ("_per_min", "1/min"),
    ("_per_s", "1/s"),
    ("_us", "µs"),
    ("_ms", "ms"),
    ("_s", "s"),
    ("_mb", "MB"),
    ("_fps", "frames/s"),
    ("_percent", "%"),
    ("_share", "share"),
    ("_mps", "m/s"),
    ("_m", "m"),
    ("_hz", "Hz"),
    ("real_time_factor", "x real time"),
    ("scaling", "x"),
    ("cores_busy", "cores"),
)
#: Units of counts, by a word in the key.
COUNT_WORDS = (
    "triangles",
    "vehicles",
    "lane_changes",
    "trajectories",
    "followers",
    "runs",
)
#: Qualifiers stripped from a key's end before its unit is looked up.
QUALIFIERS = re.compile(r"(_median|_mean|_p\d+)$")
PAGE = "docs/benchmarks.md"


class ReportError(TwinError):
    """A benchmark line cannot be read, or a benchmark run for the report failed."""


@dataclass(frozen=True)
class Figure:
    """One figure of one benchmark line.

    Attributes:
        bench: the benchmark (``query``, ``physics``, ...).
        name: the figure's key in the line, nested keys joined by dots
            (``vehicles_100.step_ms``).
        value: its value, as the line gives it (a median of the repeats).
        unit: its unit, read from the key (``-`` where none is known).
        target: the benchmark's target for it (``<= 200``), or ``None``.
        run: the number of its line among the report's lines, from 1.
    """

    bench: str
    name: str
    value: float
    unit: str
    target: str | None
    run: int


def read_lines(paths: Sequence[str | os.PathLike]) -> list[dict]:
    """The benchmark lines of JSON Lines files (``-`` reads standard input).

    Blank lines are skipped; every other line must be one JSON object with a ``bench``
    name, as ``twin bench`` prints it.

    Raises:
        ReportError: a file cannot be read, or a line is not such an object; the
            message names the file and the line number.
    """
    lines = []
    for path in paths:
        if str(path) == "-":
            text, where = sys.stdin.read(), "<stdin>"
        else:
            where = str(path)
            try:
                text = Path(path).read_text()
            except OSError as error:
                raise ReportError(f"cannot read {where}: {error.strerror}") from None
        for number, raw in enumerate(text.splitlines(), start=1):
            if raw.strip():
                lines.append(parse_line(raw, f"{where}:{number}"))
    return lines


def parse_line(raw: str, where: str = "line") -> dict:
    """One benchmark line as a dict.

    Raises:
        ReportError: ``raw`` is not a JSON object with a string ``bench``; names
            ``where``.
    """
    try:
        line = json.loads(raw)
    except json.JSONDecodeError as error:
        raise ReportError(
            f"{where}: not a JSON line of twin bench ({error.msg} at column {error.colno}): "
            f"{raw[:60]!r}"
        ) from None
    if not isinstance(line, dict):
        raise ReportError(f"{where}: expected a JSON object, got {type(line).__name__}")
    if not isinstance(line.get("bench"), str) or not line["bench"]:
        raise ReportError(
            f"{where}: no benchmark name: a line of twin bench has a string 'bench', "
            f"got keys {sorted(line)[:8]}"
        )
    return line


def unit_of(key: str) -> str:
    """The unit of a figure from its key (``step_ms`` is ms), ``-`` where none is known."""
    key = QUALIFIERS.sub("", key)
    for suffix, unit in UNIT_SUFFIXES:
        if key.endswith(suffix):
            return unit
    if any(word in key for word in COUNT_WORDS):
        return "count"
    return "-"


def figures(line: dict, run: int) -> list[Figure]:
    """Every numeric figure of ``line`` (nested ones by dotted name), in the line's order,
    without the context and the settings."""
    targets = _targets(line)
    found: list[Figure] = []

    def walk(value, path: tuple[str, ...]) -> None:
        if isinstance(value, dict):
            for key, item in value.items():
                walk(item, (*path, str(key)))
        elif isinstance(value, int | float) and not isinstance(value, bool):
            unit = next((u for u in map(unit_of, reversed(path)) if u != "-"), "-")
            name = ".".join(path)
            found.append(Figure(line["bench"], name, value, unit, _target(targets, path), run))

    for key, value in line.items():
        if key in CONTEXT_KEYS | SETTING_KEYS | DETAIL_KEYS or key.startswith("target_"):
            continue
        walk(value, (key,))
    return found


def _targets(line: dict) -> dict[str, str]:
    """The line's targets by figure key: ``targets`` as given, and ``target_<unit>``
    numbers (time limits) as upper bounds of the one figure with that unit's suffix."""
    targets = {
        str(key): str(value)
        for key, value in (line.get("targets") or {}).items()
        if isinstance(value, str)
    }
    for key, value in line.items():
        if key.startswith("target_") and isinstance(value, int | float):
            suffix = key.removeprefix("target")
            matching = [k for k in line if k.endswith(suffix) and k != key]
            if len(matching) == 1:
                targets.setdefault(matching[0], f"<= {value}")
    return targets


_BOUND = re.compile(r"(<=|>=|<|>)\s*(-?[\d.]+)\s*([^\s()]*)")


def met(target: str | None, value: float, unit: str) -> bool | None:
    """Whether ``value`` meets ``target``: a bound such as ``<= 0.3``, or several, each
    with its unit (``>= 10 x (<= 1 ms)``: a real-time factor of 10 x, or a 1 ms step).
    The bound whose unit starts the figure's unit is used, else the only bound without a
    unit; ``None`` where no bound applies (no target, or none in the figure's unit)."""
    if target is None:
        return None
    bounds = _BOUND.findall(target)
    chosen = [b for b in bounds if b[2] and unit.split()[0] == b[2]]
    if not chosen:
        chosen = [b for b in bounds if not b[2]] if len(bounds) == 1 else []
    if not chosen:
        return None
    sign, number, _ = chosen[0]
    limit = float(number)
    return {"<=": value <= limit, ">=": value >= limit, "<": value < limit,
            ">": value > limit}[sign]  # fmt: skip


def _target(targets: dict[str, str], path: tuple[str, ...]) -> str | None:
    """The target of the figure at ``path``: its own, else that of a key above it."""
    for k in range(len(path), 0, -1):
        if (target := targets.get(".".join(path[:k]))) is not None:
            return target
    return None


def document(
    lines: Sequence[dict], *, lines_path: str = "docs/benchmarks.jsonl", page: str = PAGE
) -> str:
    """The benchmarks page (Markdown) of ``lines``.

    Args:
        lines: benchmark lines as :func:`read_lines` gives them.
        lines_path: where the lines are kept, for the commands the page shows.
        page: where the page is written, for the same commands.

    Raises:
        ReportError: no lines.
    """
    if not lines:
        raise ReportError("no benchmark lines to report")
    benches = ",".join(dict.fromkeys(line["bench"] for line in lines))
    machines = _machines(lines)
    out = [
        "# Benchmarks",
        "",
        "Performance of the twin's parts and commands, as `twin bench` measures them: each",
        "benchmark prints one JSON line of figures (medians of its repeats) with the options",
        "it ran with, the date, the commit and the machine. This page is generated from",
        f"those lines (`{lines_path}`) by `twin bench report`; do not edit it. A commit",
        'marked "modified" was measured with changes not yet committed.',
        "",
        "Measure again on your machine and rewrite this page (one benchmark at a time):",
        "",
        "```sh",
        f"twin bench report --run {benches} --lines {lines_path} --out {page}",
        "```",
        "",
        "Rewrite it from lines you already have (`twin bench NAME >> FILE`, one line each):",
        "",
        "```sh",
        f"twin bench report {lines_path} --out {page}",
        "```",
        "",
        "`twin bench --help` lists the benchmarks and `twin bench NAME --help` their",
        "options, with units and defaults. Each run below was made by `twin bench NAME`",
        "with the options in its row of [Runs](#runs).",
        "",
        "## What each benchmark measures",
        "",
        *(f"- **{name}**: {_description(name)}" for name in dict.fromkeys(benches.split(","))),
        "",
        "## Figures",
        "",
        "| benchmark | figure | median | unit | target | met | run |",
        "|---|---|---|---|---|---|---|",
    ]
    for run, line in enumerate(lines, start=1):
        for f in figures(line, run):
            verdict = {True: "yes", False: "**no**", None: "-"}[met(f.target, f.value, f.unit)]
            out.append(
                f"| {f.bench} | `{f.name}` | {_number(f.value)} | {f.unit} | "
                f"{_cell(f.target)} | {verdict} | {f.run} |"
            )
    out += [
        "",
        "## Runs",
        "",
        "| run | benchmark | settings | date (UTC) | commit | machine |",
        "|---|---|---|---|---|---|",
    ]
    for run, line in enumerate(lines, start=1):
        out.append(
            f"| {run} | {line['bench']} | {_settings(line)} | {_date(line.get('date'))} | "
            f"{_commit(line)} | {machines[_machine_key(line)]} |"
        )
    out += [
        "",
        "## Machines",
        "",
        "| machine | cpu | cores (usable) | memory [GB] | os | python | numpy | pybullet |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for key, label in machines.items():
        cpu, cores, usable, memory, system, python, numpy, pybullet = key
        out.append(
            f"| {label} | {_cell(cpu)} | {_cell(cores)} ({_cell(usable)}) | {_cell(memory)} | "
            f"{_cell(system)} | {_cell(python)} | {_cell(numpy)} | {_cell(pybullet)} |"
        )
    return "\n".join(out) + "\n"


def replace_lines(lines: Sequence[dict], new: Sequence[dict]) -> list[dict]:
    """``lines`` with each benchmark that ``new`` measured again replaced by its new
    line(s), in its old place; benchmarks new to ``lines`` follow at the end."""
    fresh: dict[str, list[dict]] = {}
    for line in new:
        fresh.setdefault(line["bench"], []).append(line)
    out, placed = [], set()
    for line in lines:
        bench = line["bench"]
        if bench not in fresh:
            out.append(line)
        elif bench not in placed:
            out += fresh[bench]
            placed.add(bench)
    out += [line for bench, group in fresh.items() if bench not in placed for line in group]
    return out


def write_page(lines: Sequence[dict], out: str | os.PathLike, *, lines_path: str) -> Path:
    """Write :func:`document` of ``lines`` to ``out`` whole or not at all; return ``out``."""
    text = document(lines, lines_path=lines_path, page=str(out))
    with atomic_file(out) as tmp:
        tmp.write_text(text)
    return Path(out)


def write_lines(lines: Iterable[dict], out: str | os.PathLike) -> Path:
    """Write benchmark lines as JSON Lines to ``out`` whole or not at all; return ``out``."""
    with atomic_file(out) as tmp:
        tmp.write_text("".join(json.dumps(line) + "\n" for line in lines))
    return Path(out)


def run_benchmarks(names: Sequence[str]) -> list[dict]:
    """Run ``twin bench NAME`` for each of ``names`` with its default options, one after
    the other in a fresh process each, and return their lines (each also printed).

    Raises:
        ReportError: a benchmark exits with an error or prints no benchmark line.
    """
    lines = []
    for name in names:
        print(f"twin bench {name} ...", file=sys.stderr, flush=True)
        done = subprocess.run(
            [sys.executable, "-m", "twin", "bench", name],
            stdout=subprocess.PIPE,
            text=True,
        )
        printed = [raw for raw in done.stdout.splitlines() if raw.startswith("{")]
        if done.returncode != 0 or not printed:
            raise ReportError(
                f"twin bench {name} failed (exit status {done.returncode}); nothing was written"
            )
        print(printed[-1], flush=True)
        lines.append(parse_line(printed[-1], f"twin bench {name}"))
    return lines


def _description(name: str) -> str:
    """What benchmark ``name`` measures: the first paragraph of its function's docstring
    in :mod:`twin.perf.bench`, in Markdown."""
    from twin.perf import bench

    key = name.replace("-", "_")  # first-run: first_run_bench
    function = getattr(bench, f"{key}_bench", None) or getattr(bench, key, None)
    doc = inspect.getdoc(function) if callable(function) else None
    if not doc:
        return "see `twin bench " + name + " --help`."
    text = " ".join(doc.split("\n\n")[0].split())
    return re.sub(r":\w+:`~?([^`]+)`", r"`\1`", text).replace("``", "`")


def _machines(lines: Sequence[dict]) -> dict[tuple, str]:
    """The machines of ``lines``, labelled A, B, ... in order of first appearance."""
    machines: dict[tuple, str] = {}
    for line in lines:
        key = _machine_key(line)
        if key not in machines:
            machines[key] = chr(ord("A") + len(machines)) if len(machines) < 26 else str(key)
    return machines


def _machine_key(line: dict) -> tuple:
    """What a line says of its machine (``None`` where it says nothing)."""
    machine = line.get("machine") or {}
    return (
        machine.get("cpu"),
        machine.get("cores"),
        line.get("cpus"),
        machine.get("memory_gb"),
        machine.get("os"),
        line.get("python"),
        machine.get("numpy"),
        machine.get("pybullet"),
    )


def _settings(line: dict) -> str:
    """The options a line ran with (``--repeats 3``; ``options`` maps each flag to its
    value), else, for a line without them, its own setting keys (``repeats=3``)."""
    options = line.get("options")
    if not isinstance(options, dict):
        given = [f"{k}={v}" for k, v in line.items() if k in SETTING_KEYS]
        return _cell(", ".join(given) or None)
    parts = []
    for flag, value in options.items():
        values = value if isinstance(value, list) else [value]
        for item in values:
            if item is None or item is False or item == "":
                continue
            parts.append(f"`{flag}`" if item is True else f"`{flag} {item}`")
    return _cell(" ".join(parts) or "defaults")


def _date(date: str | None) -> str:
    """``2026-11-24T05:40:01+00:00`` as ``2026-11-24 05:40``."""
    if not isinstance(date, str):
        return "-"
    return date[:16].replace("T", " ")


def _commit(line: dict) -> str:
    """The commit, marked where the work tree had uncommitted changes."""
    commit = line.get("commit")
    if not commit:
        return "-"
    return f"{commit} (modified)" if line.get("dirty") else str(commit)


def _number(value: float) -> str:
    """A figure as the line gives it (already rounded by the benchmark)."""
    return json.dumps(value)


def _cell(value) -> str:
    """A table cell: ``-`` for nothing, ``|`` escaped."""
    if value is None or value == "":
        return "-"
    return str(value).replace("|", "\\|")
