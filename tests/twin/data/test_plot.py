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


def test_a_ramp_vehicle_gets_a_panel_of_the_on_ramps_lane(tmp_path, monkeypatch):
    """Vehicles recorded on an acceleration lane before they merge are drawn in a panel of
    their own below lane -4's, on the same mile-marker scale."""
    import numpy as np

    from tests.conftest import make_doc, make_merging_doc, write_day
    from twin.data import plot
    from twin.data.ingest import ingest
    from twin.data.store import TrajectoryStore

    merging = make_merging_doc("1" * 24)
    other = make_doc("2" * 24, direction=-1, mm=61.9, y_ft=30.0, n=100)
    ingest([write_day(tmp_path / "d.json", [merging, other])], tmp_path / "s", progress=False)
    figures = []
    monkeypatch.setattr(plot, "save_figure", lambda fig, out, dpi: figures.append(fig))
    plot.time_space_plot(TrajectoryStore(tmp_path / "s"), "westbound", SCENARIO_TIME, 1, "x")
    (fig,) = figures
    try:
        labels = [ax.get_ylabel().split("\n")[0] for ax in fig.axes[:-1]]
        assert labels == ["lane -1 (HOV)", "lane -2", "lane -3", "lane -4", "lane -5 (on-ramp)"]
        ramp = fig.axes[4]
        assert len(ramp.collections[0].get_offsets()) == 50
        assert np.allclose(ramp.get_ylim(), fig.axes[0].get_ylim())
    finally:
        plot.plt.close(fig)
