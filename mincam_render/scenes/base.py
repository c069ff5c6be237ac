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
from mincam_render.core.strict_json import JsonObject
from mincam_render.optics.camera import FreeformCamera
from mincam_render.optics.photodiode import DiodeResponse
from mincam_render.render.capabilities import SunlitWindow
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


class SceneFamily(abc.ABC):
    """A procedural scene family: description + seed -> frames with labels.

    What every family provides: subclasses set ``name`` and ``config_type`` (a
    frozen dataclass read from the description, every field with a ``spec``) and
    implement the abstract methods; ``set_frame`` must be a pure function of the
    frame index. What a family may add -- a differential background, people
    removal, temporal labels, a sunlit window, a bird's-eye preview -- it
    declares by having the members of the protocols in
    :mod:`mincam_render.render.capabilities` (re-exported by
    :mod:`mincam_render.scenes`); the renderer checks for them.
    """

    name: ClassVar[str]
    config_type: ClassVar[type]
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
    def frame_state(self, index: int) -> JsonObject:
        """A JSON-ready summary of frame ``index``'s state (for metadata)."""

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

        :func:`mincam_render.render.transport.render_transport`, through the
        family's window when it has one
        (:class:`~mincam_render.render.capabilities.SunlitWindow`): every render
        of a dataset (frames, ``X``, ``C``, background components, the planner's
        pilots and reference) goes through here, so they all use one estimator.
        """
        from mincam_render.render.transport import render_transport

        return render_transport(
            scene,
            camera,
            spp=spp,
            seed=seed,
            max_depth=max_depth,
            parallax=parallax,
            sun_window=self.sun_window() if isinstance(self, SunlitWindow) else None,
        )

    def time_s(self, index: int) -> float:
        """Time of frame ``index`` since the start of the sequence (s)."""
        return index / self.fps

    def check_index(self, index: int) -> None:
        """Raise ``IndexError`` unless 0 <= index < num_frames."""
        if not 0 <= index < self.num_frames:
            raise IndexError(f"frame {index} outside [0, {self.num_frames})")
