"""What every scene family provides: frames of a continuous sequence and their labels.

A family turns a validated description plus a seed into a *sequence*: for frame
``i`` (time ``i / fps`` seconds) it sets the Mitsuba scene's parameters in place
(``mi.traverse``; the scene is built once) and returns labels computed from the
scene state. Trajectories are simulated once in the constructor, so frames can
be visited in any order (resumable, sharded rendering) with identical results.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import Any, ClassVar

import mitsuba as mi
import numpy as np

from mincam_render.core.checks import check_int
from mincam_render.core.config import Described, spec
from mincam_render.core.labels import LabelSpec
from mincam_render.optics.camera import FreeformCamera
from mincam_render.optics.photodiode import DiodeResponse
from mincam_render.render.fidelity.signal import SignalSource
from mincam_render.render.precision import ErrorScale


@dataclass(frozen=True, kw_only=True)
class CameraMount(Described):
    """Where the camera board hangs in a scene (world metres, +z up in indoor scenes)."""

    position: tuple[float, float, float] = spec(unit="m", doc="board centre")
    look_at: tuple[float, float, float] = spec(unit="m", doc="point the board faces")
    up: tuple[float, float, float] = spec((0.0, 0.0, 1.0), doc="world direction of mask row 0")
    detectors: int = spec(8, range=(1, 64), doc="number of freeform pixels")
    mask_resolution: int = spec(32, range=(1, 512), doc="texels per mask side")
    diode_response: DiodeResponse = spec(
        DiodeResponse.S9119_01,
        doc="angular response of the photodiodes: S9119-01 (the prototype's) or cosine",
    )

    def __post_init__(self) -> None:
        self.camera()  # validates the pose; FreeformCamera's ValueError names the field

    def camera(self) -> FreeformCamera:
        """The default prototype camera with this pose, detectors in a 2-row grid."""
        from mincam_render.optics.camera import MM, DetectorLayout

        rows = 1 if self.detectors < 4 else 2
        cols = -(-self.detectors // rows)
        grid = DetectorLayout.grid(rows=rows, cols=cols, pitch_m=20 * MM)
        layout = DetectorLayout(positions_m=grid.positions_m[: self.detectors])
        return FreeformCamera(
            layout=layout,
            mask_resolution=(self.mask_resolution, self.mask_resolution),
            position=self.position,
            look_at=self.look_at,
            up=self.up,
            directional_response=self.diode_response.directional_response(),
        )


@dataclass(frozen=True)
class View:
    """A perspective view for previews: pose (m), up, and horizontal field of view (deg)."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_deg: float


class SceneFamily(abc.ABC):
    """A procedural scene family: description + seed -> frames with labels.

    Subclasses set ``name``, ``config_type`` and ``labels`` and implement the
    abstract methods. ``set_frame`` must be a pure function of the frame index.
    """

    name: ClassVar[str]
    config_type: ClassVar[type]
    #: True when the task needs a time history (traffic speed from 30 frames).
    needs_history: ClassVar[bool] = False
    #: What errors relative to the total are relative to
    #: (:class:`~mincam_render.render.precision.ErrorScale`): each probe frame's
    #: own measurement (FRAME), or the mean over the probe frames (MEAN) for a
    #: family whose light level is itself the label and varies tenfold by frame.
    #: The bounds of the biases (path depth, float16) are in this scale.
    total_error_scale: ClassVar[ErrorScale] = ErrorScale.FRAME
    #: What the fidelity planner's Monte Carlo target is relative to: the total
    #: (``total_error_scale``, target ``--target-error``) or the label signal
    #: (SIGNAL, target :attr:`signal_target_error`).
    planning_error_scale: ClassVar[ErrorScale] = ErrorScale.FRAME
    #: The target relative to the label signal that the task-level check chose
    #: (``benchmarks/bench_task_fidelity.py``); None where none was checked.
    signal_target_error: ClassVar[float | None] = None
    #: Where the labels live in the frames: what the label signal is
    #: (:class:`~mincam_render.render.fidelity.signal.SignalSource`).
    label_signal: ClassVar[SignalSource] = SignalSource.FRAMES

    def __init__(self, config: Any, *, seed: int, num_frames: int) -> None:
        check_int("seed", seed, 0)
        check_int("num_frames", num_frames, 1)
        self.config = config
        self.seed = seed
        self.num_frames = num_frames

    @property
    @abc.abstractmethod
    def fps(self) -> float:
        """Frames per second of the sequence."""

    @property
    @abc.abstractmethod
    def labels(self) -> tuple[LabelSpec, ...]:
        """The labels returned by :meth:`set_frame`."""

    @abc.abstractmethod
    def camera(self) -> FreeformCamera:
        """The default camera of this family (its pose from the description)."""

    @abc.abstractmethod
    def build_scene(self) -> mi.Scene:
        """Build the Mitsuba scene once (frame 0's state is not yet applied)."""

    @abc.abstractmethod
    def set_frame(self, scene: mi.Scene, index: int) -> dict[str, np.ndarray]:
        """Set ``scene``'s parameters to frame ``index`` in place; return its labels.

        Returns:
            ``{label name: float32 array of shape (spec.size,)}``.
        """

    @abc.abstractmethod
    def frame_state(self, index: int) -> dict[str, Any]:
        """A JSON-ready summary of frame ``index``'s state (for metadata)."""

    @abc.abstractmethod
    def birdseye_view(self) -> View:
        """A view from above covering the scene, for previews."""

    #: True when the family separates a static background from moving objects
    #: (:meth:`background_key`, :meth:`set_background`), for differential rendering.
    has_background: ClassVar[bool] = False

    def background_key(self, index: int, interval_s: float) -> str:
        """Identity of frame ``index``'s static background (its scene without movers).

        Frames with equal keys share one background: the lights of the frame and
        the slowly changing light (daylight) of the start of its ``interval_s``
        window. See :mod:`mincam_render.render.differential`.
        """
        raise NotImplementedError(f"family {self.name!r} has no static background")

    def set_background(
        self, scene: mi.Scene, index: int, interval_s: float, *, at: float = 0.0
    ) -> None:
        """Set ``scene`` to the static background of frame ``index`` (movers removed).

        ``at``: with the daylight at this position in the frame's window (0 its
        start, the ``C`` of differential rendering; 1 its end).
        """
        raise NotImplementedError(f"family {self.name!r} has no static background")

    def background_components(self, index: int, interval_s: float) -> dict[str, float]:
        """``{component key: weight}``: frame ``index``'s background as a weighted sum.

        Light transport is linear in the emitters, so the converged background
        is a sum of renders of static components (each light alone, the
        daylight at the ends of the frame's window), each rendered once per
        dataset and shared by every frame that uses it.
        """
        raise NotImplementedError(f"family {self.name!r} has no static background")

    def set_background_component(self, scene: mi.Scene, key: str) -> None:
        """Set ``scene`` to one static component (see :meth:`background_components`)."""
        raise NotImplementedError(f"family {self.name!r} has no static background")

    #: True when the family can render a frame with its people removed
    #: (:meth:`set_frame_without_people`), for the privacy audit's backgrounds.
    removes_people: ClassVar[bool] = False

    def set_frame_without_people(self, scene: mi.Scene, index: int) -> None:
        """Set ``scene`` to frame ``index`` with its people removed, all else as in the frame.

        Unlike :meth:`set_background` the door, lights and daylight stay the
        frame's own: the frame's view minus this one's is what the people add
        (themselves, their shadows, their light on the room). For the privacy
        audit's backgrounds (:mod:`mincam_render.data.views`).
        """
        raise NotImplementedError(f"family {self.name!r} cannot remove its people")

    def set_frame_in_window(self, scene: mi.Scene, index: int, interval_s: float) -> dict:
        """Set ``scene`` to frame ``index`` lit by its background's slow light; return labels.

        The movers, door and lights of the frame, with the daylight of the start
        of its ``interval_s`` window (the ``X`` of differential rendering).
        """
        raise NotImplementedError(f"family {self.name!r} has no static background")

    def render_transport(
        self,
        scene: mi.Scene,
        camera: FreeformCamera,
        *,
        spp: int,
        seed: int,
        max_depth: int | None = None,
        parallax: bool = True,
    ) -> np.ndarray:
        """Transport images of ``scene`` with this family's estimator (``[detector, row, col]``, W).

        :func:`mincam_render.render.transport.render_transport` with the family's
        :meth:`sun_window`: every render of a dataset (frames, ``X``, ``C``,
        background components, the planner's pilots and reference) goes
        through here, so they all use one estimator.
        """
        from mincam_render.render.transport import render_transport

        return render_transport(
            scene,
            camera,
            spp=spp,
            seed=seed,
            max_depth=max_depth,
            parallax=parallax,
            sun_window=self.sun_window(),
        )

    def sun_window(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The window the sun shines through, ``(corner, edge_u, edge_v)`` (m, world), or None.

        ``edge_u x edge_v`` points out of the room. Renders connect paths to the
        sunlit patches behind it (:mod:`mincam_render.render.sun_patch`); None (the
        default) renders with the scene's path tracer alone.
        """
        return None

    def time_s(self, index: int) -> float:
        """Time of frame ``index`` since the start of the sequence (s)."""
        return index / self.fps

    def check_index(self, index: int) -> None:
        """Raise ``IndexError`` unless 0 <= index < num_frames."""
        if not 0 <= index < self.num_frames:
            raise IndexError(f"frame {index} outside [0, {self.num_frames})")
