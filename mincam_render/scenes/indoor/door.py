"""The hinged door: its leaf at any opening angle, the corridor behind it, the way in."""

from __future__ import annotations

import math

import numpy as np

from mincam_render.scenes.indoor.config import DoorConfig, HingeSide, RoomConfig, wall_frame
from mincam_render.scenes.indoor.geometry import box_mesh, inward_box


class Door:
    """Geometry of a hinged door leaf; angle 0 = closed (in the wall), > 0 swings into the room."""

    THICKNESS_M = 0.04

    def __init__(self, room: RoomConfig, config: DoorConfig) -> None:
        self.config = config
        origin, t, n = wall_frame(room, config.wall)
        self.tangent, self.normal = t, n
        c = config.center_m
        self.center = origin + c * t  # doorway centre on the floor
        s_hinge = (
            c - config.width_m / 2 if config.hinge is HingeSide.START else c + config.width_m / 2
        )
        self.hinge = origin + s_hinge * t
        # leaf (closed): from the hinge toward the other jamb, just inside the wall plane
        self._leaf_dir = t if config.hinge is HingeSide.START else -t
        v, f = box_mesh(
            (0, 0, 0), (config.width_m - 0.01, self.THICKNESS_M, config.height_m - 0.01)
        )
        # local: x along the leaf from the hinge, y along the inward normal, z up
        self._local = v + np.array([config.width_m / 2, self.THICKNESS_M / 2, config.height_m / 2])
        # a left-handed (leaf, normal, up) basis mirrors the box: flip faces to keep them outward
        mirrored = np.linalg.det(np.stack([self._leaf_dir, n, [0.0, 0.0, 1.0]])) < 0
        self.faces = f[:, ::-1] if mirrored else f

    def vertices(self, angle_rad: float) -> np.ndarray:
        """World vertices of the leaf opened by ``angle_rad`` (turning toward the room)."""
        c, s = math.cos(angle_rad), math.sin(angle_rad)
        d = c * self._leaf_dir + s * self.normal
        side = c * self.normal - s * self._leaf_dir
        v = self._local
        return self.hinge + v[:, :1] * d + v[:, 1:2] * side + v[:, 2:3] * np.array([0, 0, 1.0])

    def corridor(self, room: RoomConfig) -> tuple[np.ndarray, np.ndarray]:
        c = self.config
        w = c.width_m + 1.2
        a = self.center - self.tangent * w / 2
        b = self.center + self.tangent * w / 2 - self.normal * c.corridor_depth_m
        lo = np.minimum(a, b)
        hi = np.maximum(a, b)
        hi[2] = c.height_m + 0.3
        axis = int(np.argmax(np.abs(self.normal)))
        return inward_box(lo, hi, open_axis=axis, open_at=float(self.center[axis]))

    def waypoints(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(corridor start, doorway, inside the room) (x, y) points of the way in."""
        corridor = self.center - 0.7 * self.config.corridor_depth_m * self.normal
        inside = self.center + 0.9 * self.normal
        return corridor[:2], self.center[:2], inside[:2]
