"""The lane-flow figure `twin calibrate` writes."""

import warnings

import cv2

from twin.calibration.flow_plot import plot_lane_flows
from twin.core.i24 import LANES


def test_a_road_with_no_lane_changes_is_drawn_without_a_warning(tmp_path):
    # the eastbound road of a westbound morning: no changes to name in a legend
    edges = [0.0, 100.0, 200.0]
    flows = {
        "x_edges": edges,
        "position_bin_m": 100.0,
        "pairs": {},
        "net_out": {str(lane): [0, 0] for lane in LANES},
    }
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = plot_lane_flows(flows, tmp_path / "flows.png", title="eastbound")
    image = cv2.imread(str(out))
    assert image is not None and image.shape[0] > 100
