"""A picture of a built map for a person to check: overview, close top view, driver's eye.

Rendered headless with pybullet's CPU renderer (TinyRenderer) from the same OBJ files
the cameras use, so what the picture shows is what the twin's cameras will see.
"""

from pathlib import Path

import cv2
import numpy as np

from mapgen.build import MapBundle
from mapgen.road import mile_marker_of
from twin.core.atomic import atomic_file
from twin.core.i24 import Road, lane_center
from twin.physics.map_view import MapView

WIDTH = 1600  # [px] of the picture


def render_preview(bundle: MapBundle, out: Path) -> Path:
    """Render the preview of ``bundle`` to the PNG ``out`` (written whole, then renamed).

    Returns:
        ``out``.
    """
    out = Path(out)
    road = bundle.road
    s0, s1 = road.station_range
    overpass = bundle.description["objects"]["overpass"]["station_m"]
    half_width = road.outer_edge + 60.0
    with MapView(bundle) as view:
        overview = _top_view(view, road, (s0, s1), half_width, WIDTH)
        close = _top_view(view, road, (overpass - 110.0, overpass + 110.0), 55.0, WIDTH)
        merges = []
        for ramp in road.ramps[:1]:  # the eastbound Hickory Hollow Pkwy on-ramp's taper
            end = float(road.station(ramp.road, ramp.x_end))
            merges.append(
                _titled(
                    _top_view(view, road, (end - 180.0, end + 40.0), 55.0, WIDTH),
                    f"Top view of the {ramp.road.value} on-ramp's acceleration lane ending at "
                    f"MM {mile_marker_of(end):.2f} (its 300 ft taper)",
                )
            )
        eye = _drivers_eye(view, road, overpass - 140.0, WIDTH, WIDTH * 9 // 16)
    panels = [
        _titled(
            overview,
            f"Overview: MM {mile_marker_of(s0):.2f} to {mile_marker_of(s1):.2f}, westbound on top",
        ),
        _titled(close, "Top view at the Old Franklin Rd overpass (MM 60.82)"),
        *merges,
        _titled(eye, "Driver's eye: eastbound lane -2, 140 m before the overpass"),
    ]
    picture = cv2.cvtColor(np.concatenate(panels, axis=0), cv2.COLOR_RGB2BGR)
    with atomic_file(out) as tmp:
        if not cv2.imwrite(str(tmp), picture):
            raise OSError(f"could not write {out}")
    return out


def _top_view(view: MapView, road, stations, half_width, width) -> np.ndarray:
    """View from straight above, eastbound travel to the right and westbound on top.

    TinyRenderer takes its near and far planes from a perspective matrix, so the view
    is a narrow perspective from high up (20 km), which is orthographic within 0.1 %.
    """
    length = stations[1] - stations[0]
    height = max(2, round(width * 2.0 * half_width / length))
    center = 0.5 * (stations[0] + stations[1]) * road.direction_vector
    altitude = 20_000.0  # [m]
    eye = [center[0], center[1], altitude]
    up = -road.right_vector
    fov = np.degrees(2.0 * np.arctan(half_width / altitude))
    target = [center[0], center[1], 0.0]
    return view.look(
        eye, target, [up[0], up[1], 0.0], fov, 19_000.0, 21_000.0, width, height,
        aspect=length / (2.0 * half_width),
    )  # fmt: skip


def _drivers_eye(view: MapView, road, station, width, height) -> np.ndarray:
    """Perspective view from 1.4 m above the centre of eastbound lane -2."""
    x = station
    position, _, _ = road.to_world(Road.EASTBOUND, [x], [float(lane_center(-2))])
    eye = position[0] + [0.0, 0.0, 1.4]
    ahead, _, _ = road.to_world(Road.EASTBOUND, [x + 60.0], [float(lane_center(-2))])
    target = ahead[0] + [0.0, 0.0, 0.4]
    return view.look(eye, target, [0.0, 0.0, 1.0], 60.0, 0.3, 2500.0, width, height, horizon=True)


def _titled(image: np.ndarray, title: str) -> np.ndarray:
    band = np.full((34, image.shape[1], 3), 245, dtype=np.uint8)
    cv2.putText(band, title, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (20, 20, 20), 1, cv2.LINE_AA)
    return np.concatenate([band, image], axis=0)
