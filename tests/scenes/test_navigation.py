"""People's paths around furniture: the navigation grid and its shortest paths (networkx)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mincam_render.scenes.indoor.config import FurnitureConfig, FurnitureKind, RoomConfig
from mincam_render.scenes.indoor.motion import NAV_CELL_M, NAV_CLEARANCE_M, NavGrid


def _desk(x: float, y: float, depth: float, width: float) -> FurnitureConfig:
    return FurnitureConfig(kind=FurnitureKind.DESK, position_m=(x, y), size_m=(depth, width, 0.75))


def _inside_footprint(p: np.ndarray, desk: FurnitureConfig) -> bool:
    depth, width, _ = desk.size
    return abs(p[0] - desk.position_m[0]) < depth / 2 and abs(p[1] - desk.position_m[1]) < width / 2


def test_empty_room_path_has_the_closed_form_8_connected_length():
    """No obstacle: cost max(dx, dy) + (sqrt 2 - 1) min(dx, dy) cells, and a straight walk."""
    nav = NavGrid(RoomConfig(size_m=(2.0, 2.0, 2.5)), [])
    start, goal = (3, 3), (15, 8)  # (iy, ix), both free at 0.3 m clearance
    cells = nav.cell_path(start, goal)
    steps = np.diff(np.asarray(cells), axis=0)
    length = float(np.hypot(steps[:, 0], steps[:, 1]).sum())
    assert length == pytest.approx(12 + (math.sqrt(2) - 1) * 5, rel=1e-12)
    a, b = nav.point(start), nav.point(goal)
    assert [p.tolist() for p in nav.plan(a, b)] == [a.tolist(), a.tolist(), b.tolist(), b.tolist()]


def test_path_walks_around_a_desk_with_clearance():
    """A 1 m wide desk across the straight line: the walk keeps off it, nearly optimally."""
    desk = _desk(1.5, 1.5, 0.6, 1.0)
    nav = NavGrid(RoomConfig(size_m=(3.0, 3.0, 2.5)), [desk])
    a, b = np.array([0.5, 1.5]), np.array([2.5, 1.5])
    way = nav.plan(a, b)
    walked = np.concatenate([np.linspace(p, q, 50) for p, q in zip(way[:-1], way[1:], strict=True)])
    assert not any(_inside_footprint(p, desk) for p in walked)
    # past the desk's end plus the clearance (to one cell)
    assert np.abs(walked[:, 1] - 1.5).max() >= 0.5 + NAV_CLEARANCE_M - NAV_CELL_M
    # shortest way round the desk grown by the clearance: a to its corner, along, to b
    grown = (0.3 + NAV_CLEARANCE_M, 0.5 + NAV_CLEARANCE_M)
    optimal = 2 * math.hypot(1.0 - grown[0], grown[1]) + 2 * grown[0]
    length = float(np.linalg.norm(np.diff(walked, axis=0), axis=1).sum())
    assert optimal - 2 * NAV_CELL_M < length < 1.1 * optimal


def test_no_path_through_a_wall_of_furniture_raises():
    shelf = _desk(1.5, 1.0, 0.4, 2.0)  # spans the room's whole depth
    nav = NavGrid(RoomConfig(size_m=(3.0, 2.0, 2.5)), [shelf])
    with pytest.raises(ValueError, match="no walkable path"):
        nav.plan(np.array([0.5, 1.0]), np.array([2.5, 1.0]))
