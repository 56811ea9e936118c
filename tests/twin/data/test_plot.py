import matplotlib.image as mpimg
import pytest

from twin.core.errors import StoreError
from twin.core.i24 import SCENARIO_TIME
from twin.data.plot import time_space_plot


def test_time_space_plot_writes_a_png(wave_store, tmp_path):
    out = time_space_plot(wave_store, "westbound", SCENARIO_TIME - 120, 4, tmp_path / "ts.png")
    image = mpimg.imread(out)
    assert image.shape[0] > 800 and image.shape[1] > 1000
    assert not list(tmp_path.glob(".*partial*"))


def test_empty_window_is_a_clear_error(wave_store, tmp_path):
    with pytest.raises(StoreError, match="no westbound samples"):
        time_space_plot(wave_store, "westbound", SCENARIO_TIME + 86400, 1, tmp_path / "x.png")
