"""One detector's board as the transport kernel sees it, per ray (Dr.Jit arrays)."""

from __future__ import annotations

from typing import NamedTuple

import mitsuba as mi


class Board(NamedTuple):
    """The board of one ray's detector: sizes, frame and centre (Dr.Jit, world, m).

    The detector is a square of side ``a_det`` centred on ``center`` in the
    plane spanned by ``right`` and ``up``; its mask (side ``w_mask``) lies
    ``dist`` further along ``fwd``, parallel to it.

    Attributes:
        a_det: detector side (m).
        w_mask: mask side (m).
        dist: mask-to-detector distance (m).
        right: board frame's right axis, world unit vector.
        up: board frame's up axis, world unit vector.
        fwd: board frame's forward axis (towards the scene), world unit vector.
        center: the ray's detector centre, world (m).
    """

    a_det: mi.Float
    w_mask: mi.Float
    dist: mi.Float
    right: mi.Vector3f
    up: mi.Vector3f
    fwd: mi.Vector3f
    center: mi.Point3f
