"""Episodes that fail in an evaluation (``twin eval``): which results are done, the
settings and the ``twin run`` that repeat a failed one, the rows that ran, and the
lines that report the failures. A failing episode does not end a sweep
(:mod:`twin.runners.evaluation` records it with these)."""

import json
import shlex
from pathlib import Path

import numpy as np

from twin.core.atomic import atomic_file

FAILED = "failed"  # the evaluation's folder of failed episodes' settings


def repeat_path(out: Path, index: int, label: str) -> Path:
    """``OUT/failed/NNNNNN-ARM.toml``: where a failed episode's settings are written."""
    return out / FAILED / f"{index:06d}-{label}.toml"


def done(path: Path) -> bool:
    """An episode's result is in (a failed one runs again when the evaluation resumes)."""
    if not path.is_file():
        return False
    try:
        return not json.loads(path.read_text()).get("failed")
    except (ValueError, AttributeError):
        return True  # damaged: assemble names it


def repeat_command(path: Path, cosim, store) -> str:
    """Write a failed episode's resolved settings ``cosim`` (a
    :class:`~twin.cosim.config.CosimConfig`) to ``path`` (:func:`repeat_path`) and
    return the ``twin run`` that repeats it."""
    from twin.cosim.config import to_toml

    path.parent.mkdir(exist_ok=True)
    with atomic_file(path) as tmp:
        tmp.write_text(to_toml(cosim))
    data, settings = (shlex.quote(str(p.resolve())) for p in (store.path, path))
    return f"twin run --data {data} --config {settings}"


def ran_rows(frame):
    """The rows of ``frame`` (``episodes.parquet``) whose episode ran: not skipped (no
    room for the ego) and not failed."""
    ran = frame["skipped"].isna() if "skipped" in frame else np.ones(len(frame), bool)
    if "failed" in frame:
        ran &= frame["failed"].isna()
    return frame[ran]


def failure_lines(summary: dict) -> list[str]:
    """Lines naming each failed episode run, its error and the ``twin run`` that
    repeats it (none when every episode ran or was skipped)."""
    key = "controllers" if "controllers" in summary else "behaviours"
    failures = [(arm, f) for arm, e in summary[key].items() for f in e.get("failures", [])]
    if not failures:
        return []
    lines = [
        f"{len(failures)} episode run{'s' if len(failures) > 1 else ''} failed (recorded as "
        "failed, not in the figures; the others ran; rerunning the command retries them):"
    ]
    for arm, f in failures:
        lines.append(f"  episode {f['episode']} ({arm}): {f['error']}")
        lines.append(f"    repeat: {f['repeat']}")
    return lines
