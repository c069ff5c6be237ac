"""What a scene family may declare beyond the frames every family provides.

Every family gives frames and labels (:class:`mincam_render.scenes.base.SceneFamily`).
These optional capabilities are runtime-checkable protocols: a family has one
when it defines its members (subclassing the protocol states it, and then an
unimplemented method is an error at instantiation, as for an abstract class), and
the renderer, the dataset writer and the trainer decide from ``isinstance``
what to do with it -- a scene says what it is; the renderer decides how to
render it. They live in ``render`` because the estimators below ``scenes`` in
the layers check for them without importing a family.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    import mitsuba as mi
    import numpy as np


@runtime_checkable
class DifferentialBackground(Protocol):
    """A static background apart from the movers: frames render differentially.

    See :mod:`mincam_render.render.differential` for the estimator and the meaning
    of the background window ``interval_s`` (scene seconds one background's slowly
    changing light stands for).
    """

    @abc.abstractmethod
    def background_key(self, index: int, interval_s: float) -> str:
        """Identity of frame ``index``'s static background (its scene without movers).

        Frames with equal keys share one background: the lights of the frame and
        the slowly changing light (daylight) of the start of its window.
        """
        ...

    @abc.abstractmethod
    def background_components(self, index: int, interval_s: float) -> dict[str, float]:
        """``{component key: weight}``: frame ``index``'s background as a weighted sum.

        Light transport is linear in the emitters, so the converged background
        is a sum of renders of static components (each light alone, the
        daylight at the ends of the frame's window), each rendered once per
        dataset and shared by every frame that uses it.
        """
        ...

    @abc.abstractmethod
    def set_background(
        self, scene: mi.Scene, index: int, interval_s: float, *, at: float = 0.0
    ) -> None:
        """Set ``scene`` to the static background of frame ``index`` (movers removed).

        ``at``: with the slow light at this position in the frame's window (0 its
        start, the ``C`` of differential rendering; 1 its end).
        """
        ...

    @abc.abstractmethod
    def set_background_component(self, scene: mi.Scene, key: str) -> None:
        """Set ``scene`` to one static component (see :meth:`background_components`)."""
        ...

    @abc.abstractmethod
    def set_frame_in_window(
        self, scene: mi.Scene, index: int, interval_s: float
    ) -> dict[str, np.ndarray]:
        """Set ``scene`` to frame ``index`` lit by its background's slow light; return labels.

        The movers and lights of the frame, with the slow light of the start of
        its window (the ``X`` of differential rendering).
        """
        ...


@runtime_checkable
class SunlitWindow(Protocol):
    """A window the sun shines through: renders connect paths to its sunlit patches."""

    @abc.abstractmethod
    def sun_window(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(corner, edge_u, edge_v)`` of the window (m, world), or None when it has none.

        ``edge_u x edge_v`` points out of the room
        (:mod:`mincam_render.render.sun_patch`).
        """
        ...


@runtime_checkable
class TemporalLabels(Protocol):
    """Labels that need a time history of measurements (traffic speed from 1 s of frames)."""

    #: Frames of measurements one prediction reads (the head's input window; 1:
    #: none). A class variable where it is fixed; a family whose description
    #: decides it sets it per instance.
    history_frames: int


@runtime_checkable
class PeopleRemoval(Protocol):
    """Frames can be rendered with their people removed (the privacy audit's backgrounds)."""

    @abc.abstractmethod
    def set_frame_without_people(self, scene: mi.Scene, index: int) -> None:
        """Set ``scene`` to frame ``index`` with its people removed, all else as in the frame.

        Unlike a differential background the doors, lights and daylight stay the
        frame's own: the frame's view minus this one's is what the people add.
        """
        ...


@dataclass(frozen=True)
class View:
    """A perspective view for previews: pose (m), up, and horizontal field of view (deg)."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_deg: float


@runtime_checkable
class Preview(Protocol):
    """A view from above for previews, beside the camera's own view."""

    @abc.abstractmethod
    def birdseye_view(self) -> View:
        """A view from above covering the scene."""
        ...


def history_frames(family: object) -> int:
    """Frames of history a family's labels need (:class:`TemporalLabels`): 1 for a static task.

    Also of a family class, through its class variable (1 when it has none).
    """
    frames = getattr(family, "history_frames", 1)
    return frames if isinstance(frames, int) else 1
