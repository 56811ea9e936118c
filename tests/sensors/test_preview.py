"""``twin render --labels``: each panel titled, depth with a colour bar in metres, the
semantic panel with a legend of the classes in view (matplotlib's artists)."""

from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np

from mapgen.semantics import semantic_classes
from sensors.preview import frame_picture, labels_figure


def _frame():
    h, w = 48, 64
    semantic = np.zeros((h, w), np.uint8)  # sky
    semantic[24:] = 1  # road
    semantic[30:40, 10:20] = 9  # a sedan
    instance = np.full((h, w), -1, np.int64)
    instance[30:40, 10:20] = 7
    depth = np.full((h, w), np.inf, np.float32)
    depth[24:] = np.linspace(40.0, 2.0, h - 24)[:, None]
    return SimpleNamespace(
        rgb=np.zeros((h, w, 3), np.uint8), depth=depth, semantic=semantic, instance=instance,
        camera=SimpleNamespace(name="front", near=0.5, far=300.0), renderer="tiny",
        sim_time=12.5,
    )  # fmt: skip


def test_labels_figure_titles_every_panel_and_explains_its_colours():
    figures = plt.get_fignums()  # another test's, where this worker ran one before
    fig = labels_figure(_frame())
    rgb, depth, semantic, instance = fig.axes[:4]
    assert rgb.get_title() == "RGB: camera front (tiny renderer)"
    assert semantic.get_title() == "semantic classes"
    assert instance.get_title() == "instances: one colour per vehicle (1 in view)"
    assert fig.get_suptitle() == "12.50 s after t0, 64 x 48 px"
    bar = fig.axes[4]
    assert bar.get_ylabel() == "depth [m] (log scale)"
    fig.canvas.draw()  # the ticks as drawn, after the layout
    ticks = [t.get_text() for t in bar.get_yticklabels()]
    assert ticks == ["0.5", "1", "2", "5", "10", "20", "50", "100", "200", "300"]
    assert not bar.yaxis.get_minorticklabels() or not any(
        t.get_text() for t in bar.yaxis.get_minorticklabels()
    )
    assert depth.get_title() == "depth, planar (black: nothing within 300 m)"
    names = {c.class_id: c.name for c in semantic_classes()}
    legend = [t.get_text() for t in semantic.get_legend().get_texts()]
    assert legend == [names[0], names[1], names[9]]  # the classes in view, in id order
    assert plt.get_fignums() == figures  # drawn without pyplot: the caller's untouched


def test_plain_frames_stay_pixel_for_pixel(tmp_path):
    import cv2

    frame = _frame()
    frame.rgb[5, 7] = (10, 200, 30)
    out = frame_picture(frame, tmp_path / "f.png")
    assert np.array_equal(cv2.cvtColor(cv2.imread(str(out)), cv2.COLOR_BGR2RGB), frame.rgb)
    labelled = frame_picture(frame, tmp_path / "l.png", labels=True)
    assert cv2.imread(str(labelled)).shape[1] > 2 * frame.rgb.shape[1]
    assert not list(tmp_path.glob(".*partial*"))
