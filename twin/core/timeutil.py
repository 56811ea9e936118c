"""Time at the boundary: unix seconds inside, ISO 8601 and I-24 local time (CST) outside."""

import math
from datetime import datetime, timedelta, timezone

import numpy as np

#: I-24 MOTION recordings (Nov-Dec 2022) are in US Central Standard Time.
CST = timezone(timedelta(hours=-6), "CST")
LATEST = 4102444800.0  # [s] unix time of 2100-01-01: later is no I-24 recording
EARLIEST_MS = 1e11  # [ms] 1973-03-03 in milliseconds: a larger "time" is likely milliseconds


def parse_time(value: str | float) -> float:
    """Unix seconds from a number or an ISO 8601 string with a UTC offset.

    Args:
        value: ``1669812350``, ``"1669812350.5"`` or ``"2022-11-30T06:45:50-06:00"``.

    Raises:
        ValueError: naming the value when it is neither, when it is not finite, or
            when an ISO time lacks its offset (a bare local time is ambiguous).
    """
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        t = float(value)
    else:
        text = str(value).strip()
        try:
            t = float(text)
        except ValueError:
            try:
                parsed = datetime.fromisoformat(text.replace("Z", "+00:00"))
            except ValueError:
                raise ValueError(
                    f"time {value!r} is neither unix seconds nor ISO 8601 "
                    "(e.g. 2022-11-30T06:45:50-06:00)"
                ) from None
            if parsed.tzinfo is None:
                raise ValueError(
                    f"time {value!r} has no UTC offset; write e.g. {text}-06:00 for I-24 local time"
                ) from None
            t = parsed.timestamp()
    if not math.isfinite(t):
        raise ValueError(f"time {value!r} is not a finite number")
    check_unix(t, repr(value))
    return t


def check_unix(t: float, shown: str | None = None) -> None:
    """Check that ``t`` is unix seconds between 1970 and 2100.

    Raises:
        ValueError: naming the value (as ``shown``) and, where it would be a time of
            1973 to 2100 in milliseconds, saying so and giving the seconds.
    """
    if 0.0 <= t < LATEST:
        return
    in_ms = EARLIEST_MS <= t < LATEST * 1000.0
    hint = f"; it looks like milliseconds: give seconds, {t / 1000.0:.3f}" if in_ms else ""
    raise ValueError(
        f"time {shown or t!r} is outside 1970 to 2100 in unix seconds{hint} (or ISO 8601, "
        "e.g. 2022-11-30T06:45:50-06:00)"
    )


def format_local(t: float, *, tenths: bool = False) -> str:
    """``YYYY-MM-DD HH:MM:SS`` in I-24 local time (CST) for unix seconds ``t``; with
    ``tenths``, rounded to a tenth of a second and shown (``HH:MM:SS.s``)."""
    if not tenths:
        return datetime.fromtimestamp(float(t), CST).strftime("%Y-%m-%d %H:%M:%S")
    when = datetime.fromtimestamp(round(float(t), 1), CST)
    return f"{when:%Y-%m-%d %H:%M:%S}.{when.microsecond // 100_000}"


def local_days(t: np.ndarray) -> list[str]:
    """The distinct local (CST) dates, ``YYYY-MM-DD``, of the unix times ``t``."""
    offset = CST.utcoffset(None).total_seconds()
    days = np.unique(np.floor((np.asarray(t, dtype=np.float64) + offset) / 86400.0))
    return [format_local(day * 86400.0 - offset)[:10] for day in days]


def steps_per_sample(rate_hz: float, dt: float) -> int:
    """Simulation steps of ``dt`` [s] between two samples at ``rate_hz`` [Hz].

    Raises:
        ValueError: the rate does not divide the step rate ``1 / dt``.
    """
    every = 1.0 / (rate_hz * dt)
    if abs(every - round(every)) > 1e-6 or round(every) < 1:
        raise ValueError(f"{rate_hz} Hz must divide the step rate {1 / dt:g} Hz")
    return round(every)
