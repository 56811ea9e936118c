"""The map alone in a pybullet client of its own, rendered with TinyRenderer for the
pictures people check it by (``twin map preview``), from the same OBJ files the
cameras use."""

import numpy as np

from mapgen.build import MapBundle
from twin.physics.bullet import pybullet as p
from twin.physics.map_bodies import load_map_bodies
from twin.physics.render import LIGHT, SKY_HORIZON, SKY_TOP


class MapView:
    """The map's visual bodies, to look at from anywhere (a context manager).

    Args:
        bundle: the built map.
    """

    def __init__(self, bundle: MapBundle):
        self.client = p.connect(p.DIRECT)
        load_map_bodies(self.client, bundle, collision=False)

    def close(self) -> None:
        p.disconnect(self.client)

    def __enter__(self) -> "MapView":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def look(
        self,
        eye,
        target,
        up,
        fov_deg: float,
        near: float,
        far: float,
        width: int,
        height: int,
        *,
        aspect: float | None = None,
        horizon: bool = False,
    ) -> np.ndarray:
        """(height, width, 3) uint8 RGB seen from ``eye`` toward ``target`` [m, world]
        with ``up`` up, a vertical field of view ``fov_deg`` [deg] between the ``near``
        and ``far`` planes [m] and ``aspect`` (default ``width / height``); the sky a
        gradient (to the horizon with ``horizon``)."""
        view = p.computeViewMatrix(list(eye), list(target), list(up))
        aspect = width / height if aspect is None else aspect
        projection = p.computeProjectionMatrixFOV(fov_deg, aspect, near, far)
        _, _, rgba, _, seg = p.getCameraImage(
            width,
            height,
            view,
            projection,
            renderer=p.ER_TINY_RENDERER,
            physicsClientId=self.client,
            **LIGHT,
        )
        rgb = np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))[:, :, :3].copy()
        sky = np.reshape(np.asarray(seg), (height, width)) < 0
        rows = np.linspace(0.0, 1.0, height)[:, None] if horizon else np.full((height, 1), 0.5)
        gradient = SKY_TOP + (SKY_HORIZON - SKY_TOP) * np.minimum(rows * 2.0, 1.0)
        background = np.broadcast_to(gradient[:, None, :], (height, width, 3)).astype(np.uint8)
        rgb[sky] = background[sky]
        return rgb
