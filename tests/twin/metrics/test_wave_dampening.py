"""The wave-dampening figures of one run (twin.metrics.wave_dampening): the window's
speed standard deviation, which a fleet of AVs is judged by."""

import numpy as np
import pandas as pd
import pytest

from twin.metrics.wave_dampening import control_figures


def _rows(vid, speeds, lane=-2, x0=0.0, dt=0.1):
    n = len(speeds)
    return pd.DataFrame({
        "time": np.arange(n) * dt, "id": vid, "tid": vid, "lane": lane,
        "x": x0 + np.cumsum(speeds) * dt, "speed": np.asarray(speeds, float),
    })  # fmt: skip


def test_the_window_speed_std_weighs_each_vehicle_by_its_time():
    ego = _rows(0, [20.0] * 20, x0=100.0)  # steady: std 0, 20 samples
    waving = _rows(1, [10.0, 20.0] * 5, lane=-3)  # std 5, 10 samples
    lone = _rows(2, [30.0], lane=-1)  # one sample: no std
    ghosts = pd.DataFrame({c: pd.Series(dtype=float) for c in ("time", "lane", "x", "speed")})
    figures = control_figures(
        pd.concat([ego, waving, lone]), ghosts, 0, [], np.full(3, 4.5), dt=0.1
    )
    assert figures["speed_std_window_mps"] == pytest.approx((0 * 20 + 5.0 * 10) / 30, abs=1e-4)
    # a speed the log lacks (NaN) is no sample: neither in the std nor in the weights
    gappy = waving.assign(speed=waving["speed"].where(waving.index != 0))  # 9 samples
    nan_std = np.std(gappy["speed"].dropna())
    figures = control_figures(pd.concat([ego, gappy]), ghosts, 0, [], np.full(3, 4.5), 0.1)
    assert figures["speed_std_window_mps"] == pytest.approx(nan_std * 9 / 29, abs=1e-4)
    # the ego alone: a steady window
    assert control_figures(ego, ghosts, 0, [], np.full(3, 4.5), 0.1)["speed_std_window_mps"] == 0
