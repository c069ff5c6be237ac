"""What the indoor families share: a rig, simulated people and switched lights."""

from __future__ import annotations

import abc
import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from mincam_render.render.capabilities import (
    DifferentialBackground,
    PeopleRemoval,
    Preview,
    SunlitWindow,
)
from mincam_render.render.fidelity.signal import SignalSource
from mincam_render.scenes.base import SceneFamily
from mincam_render.scenes.indoor.config import FurnitureKind
from mincam_render.scenes.indoor.motion import (
    NavGrid,
    simulate_people,
    switching_process,
    track_state,
)
from mincam_render.scenes.indoor.rig import IndoorRig, IndoorState

if TYPE_CHECKING:
    import mitsuba as mi

    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.render.capabilities import View


class IndoorFamily(SceneFamily, DifferentialBackground, PeopleRemoval, SunlitWindow, Preview):
    """What the indoor families share: one :class:`IndoorRig`, people and switched lights.

    Its static background (room, furniture, lights, daylight) renders
    differentially, its people can be removed, and its window lets the sun in.

    Subclasses set ``name``, ``config_type`` and :attr:`floor_lamps`, and define
    ``labels``, ``labels_for(state)`` and ``frame_state``.
    """

    def __init__(self, config: Any, *, seed: int, num_frames: int) -> None:
        super().__init__(config, seed=seed, num_frames=num_frames)
        c = config
        lamps = self.floor_lamps
        self.rig = IndoorRig(
            room=c.room,
            window=c.window,
            door=c.door,
            furniture=c.furniture,
            banks=c.ceiling_lights,
            lamps=lamps,
            daylight=c.daylight,
            daylight_update_s=c.daylight_update_s,
            slots=c.max_people,
            max_depth=c.max_depth,
        )
        rng = np.random.default_rng(seed)
        nav = NavGrid(c.room, [f for f in c.furniture if f.kind is not FurnitureKind.CHAIR])
        seats = [
            (*f.position_m, math.radians(f.rotation_deg))
            for f in c.furniture
            if f.kind is FurnitureKind.CHAIR
        ]
        self.track = simulate_people(
            rng=rng,
            num_frames=num_frames,
            fps=c.fps,
            slots=c.max_people,
            people=c.people,
            nav=nav,
            seats=seats,
            door=self.rig.door,
            arrivals_per_s=c.arrivals_per_min / 60.0,
            burn_in_s=c.burn_in_s,
        )
        # in the rig's light order: ceiling banks, then floor lamps
        switched = [*c.ceiling_lights, *lamps]
        self.lights_on = (
            np.stack(
                [
                    switching_process(rng, num_frames, c.fps, li.mean_on_s, li.mean_off_s)
                    for li in switched
                ],
                axis=1,
            )
            if switched
            else np.zeros((num_frames, 0), dtype=bool)
        )

    @property
    def floor_lamps(self) -> tuple:
        """The description's floor lamps (none unless the family has them)."""
        return ()

    @property
    def fps(self) -> float:
        return self.config.fps

    def camera(self) -> FreeformCamera:
        return self.config.camera.camera()

    def build_scene(self) -> mi.Scene:
        return self.rig.build_scene()

    def state(self, index: int) -> IndoorState:
        """The scene state of frame ``index`` (people, door, lights, daylight time)."""
        self.check_index(index)
        return IndoorState(
            people=track_state(self.track, index),
            door_angle_rad=float(self.track.door_angle_rad[index]),
            lights_on=tuple(bool(v) for v in self.lights_on[index]),
            daylight_time_s=self.time_s(index),
        )

    @abc.abstractmethod
    def labels_for(self, state: IndoorState) -> dict[str, np.ndarray]:
        """Labels of any state (e.g. one placed by hand in a test)."""

    def apply_state(self, scene: mi.Scene, state: IndoorState) -> dict[str, np.ndarray]:
        """Set ``scene`` to ``state`` in place and return its labels."""
        self.rig.apply(scene, state)
        return self.labels_for(state)

    def set_frame(self, scene: mi.Scene, index: int) -> dict[str, np.ndarray]:
        return self.apply_state(scene, self.state(index))

    # people and the door carry the labels (lighting, whose lights do, says so)
    label_signal = SignalSource.MOVERS

    def _window_start_s(self, index: int, interval_s: float) -> float:
        if not interval_s > 0:
            raise ValueError(f"interval_s = {interval_s!r}: allowed a number > 0 (s)")
        return math.floor(self.time_s(index) / interval_s + 1e-9) * interval_s

    def background_key(self, index: int, interval_s: float) -> str:
        lights = "".join("1" if on else "0" for on in self.state(index).lights_on)
        if self.rig.window is None:  # no daylight: the lights alone make the background
            return f"lights={lights}"
        return f"lights={lights};daylight_s={self._window_start_s(index, interval_s):.10g}"

    def set_background(
        self, scene: mi.Scene, index: int, interval_s: float, *, at: float = 0.0
    ) -> None:
        # nobody in the room, the door closed, the frame's lights, and the daylight
        # at position ``at`` of the frame's interval (0 its start, 1 its end)
        if not 0.0 <= at <= 1.0:
            raise ValueError(f"at = {at!r}: allowed a number in [0, 1]")
        start = self._window_start_s(index, interval_s)
        state = IndoorState(
            lights_on=self.state(index).lights_on, daylight_time_s=start + at * interval_s
        )
        self.rig.apply(scene, state)

    def background_components(self, index: int, interval_s: float) -> dict[str, float]:
        # each light alone (weight 1 when on), and the daylight with every light
        # off at the ends of the frame's window (linear in time between them)
        parts = {
            f"light={li.key}": 1.0
            for li, on in zip(self.rig.lights, self.state(index).lights_on, strict=True)
            if on
        }
        if self.rig.window is not None:
            start = self._window_start_s(index, interval_s)
            a = self.window_fraction(index, interval_s)
            for t, w in ((start, 1.0 - a), (start + interval_s, a)):
                key = f"daylight_s={t:.10g}"
                parts[key] = parts.get(key, 0.0) + w
        return parts

    def set_background_component(self, scene: mi.Scene, key: str) -> None:
        off = (False,) * len(self.rig.lights)
        name, _, value = key.partition("=")
        if name == "daylight_s" and self.rig.window is not None:
            state = IndoorState(lights_on=off, daylight_time_s=float(value))
        elif name == "light" and value in (keys := [li.key for li in self.rig.lights]):
            on = tuple(k == value for k in keys)
            state = IndoorState(lights_on=on, daylight=False)
        else:
            raise ValueError(f"{key!r} is not a background component of family {self.name!r}")
        self.rig.apply(scene, state)

    def set_frame_without_people(self, scene: mi.Scene, index: int) -> None:
        self.rig.apply(scene, replace(self.state(index), people=()))

    def set_frame_in_window(
        self, scene: mi.Scene, index: int, interval_s: float
    ) -> dict[str, np.ndarray]:
        state = replace(self.state(index), daylight_time_s=self._window_start_s(index, interval_s))
        return self.apply_state(scene, state)

    def sun_window(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The window opening (see :class:`SunlitWindow`), or None without a window."""
        return None if self.rig.window is None else self.rig.window_rectangle()

    def window_fraction(self, index: int, interval_s: float) -> float:
        """Where frame ``index``'s daylight lies in its window, in [0, 1) (0: its start).

        On the daylight's update grid: the frame's background is interpolated
        linearly between the window's ends with this weight.
        """
        if self.rig.window is None:
            return 0.0
        start = self._window_start_s(index, interval_s)
        shown = self.rig.daylight_time_s
        t0, t1 = shown(start), shown(start + interval_s)
        if t1 <= t0:  # the daylight does not change within the window
            return 0.0
        return min(max((shown(self.time_s(index)) - t0) / (t1 - t0), 0.0), 1.0)

    def birdseye_view(self) -> View:
        return self.rig.birdseye_view()
