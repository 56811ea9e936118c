"""Pictures of camera frames for people: RGB alone, or RGB, depth, semantic and
instance labels side by side."""

from pathlib import Path

import cv2
import numpy as np

from mapgen.semantics import semantic_classes
from sensors.camera import Frame
from twin.core.atomic import atomic_file

DEPTH_TICKS = (0.5, 1, 2, 5, 10, 20, 50, 100, 200, 300)  # [m] on the depth colour bar


def frame_vehicles(frame: Frame) -> np.ndarray:
    """Twin ids of the vehicles with at least one pixel in the frame."""
    ids = np.unique(frame.instance)
    return ids[ids >= 0]


def frame_picture(frame: Frame, out: Path, *, labels: bool = False) -> Path:
    """Write ``frame`` as a PNG (written whole, then renamed): the RGB image pixel for
    pixel, or with ``labels`` the figure of :func:`labels_figure`.

    Returns:
        ``out``.
    """
    if labels:
        with atomic_file(out) as tmp:
            labels_figure(frame).savefig(tmp, dpi=100, format="png")
        return Path(out)
    with atomic_file(out) as tmp:
        if not cv2.imwrite(str(tmp), cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR)):
            raise OSError(f"could not write {out}")
    return Path(out)


def labels_figure(frame: Frame):
    """A frame and its labels for people (a matplotlib figure), 2 x 2 panels, each titled:
    RGB; planar depth with a colour bar in metres (log scale); the semantic classes in the
    class table's label colours with a legend of the classes in view; the instances, one
    colour per vehicle. Made without pyplot, so drawing it leaves the caller's
    matplotlib backend and figures alone."""
    import matplotlib
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch
    from matplotlib.ticker import FixedFormatter, FixedLocator, NullLocator

    h, w = frame.rgb.shape[:2]
    fig = Figure(figsize=(2 * w / 100 + 3.2, 2 * h / 100 + 1.0), layout="constrained")
    axes = fig.subplots(2, 2)
    (rgb, depth), (semantic, instance) = axes
    rgb.imshow(frame.rgb)
    rgb.set_title(f"RGB: camera {frame.camera.name} ({frame.renderer} renderer)")
    near, far = frame.camera.near, frame.camera.far  # [m] depth is measured within them
    cmap = matplotlib.colormaps["cividis"].with_extremes(bad="black")
    shown = depth.imshow(np.where(np.isfinite(frame.depth), frame.depth, np.nan), cmap=cmap,
                         norm=LogNorm(near, far))  # fmt: skip
    depth.set_title(f"depth, planar (black: nothing within {far:g} m)")
    bar = fig.colorbar(shown, ax=depth, label="depth [m] (log scale)", shrink=0.9)
    ticks = [t for t in DEPTH_TICKS if near <= t <= far]
    bar.ax.yaxis.set_major_locator(FixedLocator(ticks))
    bar.ax.yaxis.set_major_formatter(FixedFormatter([f"{t:g}" for t in ticks]))
    bar.ax.yaxis.set_minor_locator(NullLocator())
    semantic.imshow(colour_semantic(frame.semantic))
    semantic.set_title("semantic classes")
    present = set(np.unique(frame.semantic).tolist())
    semantic.legend(
        handles=[Patch(facecolor=np.array(c.color) / 255.0, edgecolor="black", lw=0.5,
                       label=c.name) for c in semantic_classes() if c.class_id in present],
        loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8, frameon=False,
    )  # fmt: skip
    n_vehicles = len(frame_vehicles(frame))
    instance.imshow(colour_instance(frame.instance))
    instance.set_title(f"instances: one colour per vehicle ({n_vehicles} in view)")
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{frame.sim_time:.2f} s after t0, {w} x {h} px")
    return fig


def colour_semantic(semantic: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8 RGB in the class table's label colours."""
    palette = np.zeros((256, 3), dtype=np.uint8)
    for c in semantic_classes():
        palette[c.class_id] = c.color
    return palette[semantic]


def colour_instance(instance: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8 RGB: a colour per vehicle id, black where no vehicle."""
    hashed = (instance.astype(np.uint64) * np.uint64(2654435761)) & np.uint64(0xFFFFFF)
    rgb = np.stack([(hashed >> np.uint64(s)) & np.uint64(255) for s in (16, 8, 0)], axis=-1)
    rgb = (rgb.astype(np.uint8) // 2) + 96
    rgb[instance < 0] = 0
    return rgb
