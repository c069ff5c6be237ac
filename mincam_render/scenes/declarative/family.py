"""``family = "mitsuba"``: a user's Mitsuba scene, its movers and switched emitters, as a task.

The scene file is loaded as it is; only the described movers move (translated
within their regions or along their paths, shown or hidden) and only the
described emitters switch. Labels are computed from each frame's state. The
static rest -- the scene without its movers, each switched emitter alone and the
emitters that never switch -- is a differential background, so the renderer may
render frames as a converged background plus what the movers change; the movers
can be removed for the privacy audit; a speed label makes the task temporal.
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from mincam_render.core.config import ConfigError
from mincam_render.core.labels import LabelSpec
from mincam_render.core.strict_json import JsonObject
from mincam_render.optics.camera import FreeformCamera
from mincam_render.render.capabilities import (
    DifferentialBackground,
    PeopleRemoval,
    Preview,
    TemporalLabels,
    View,
)
from mincam_render.scenes.base import SceneFamily
from mincam_render.scenes.declarative.config import (
    RULE_LABELS,
    LabelDescription,
    LabelRule,
    MitsubaConfig,
)
from mincam_render.scenes.declarative.layout import SceneLayout, check_in_view, read_layout
from mincam_render.scenes.declarative.motion import (
    MoverTrack,
    simulate_mover,
    simulate_switches,
)

#: Background component of the emitters that never switch.
STATIC = "static"


class MitsubaFamily(SceneFamily, DifferentialBackground, PeopleRemoval, TemporalLabels, Preview):
    """A user's Mitsuba scene with movers, switched emitters and labels (docs/your_own_task.md)."""

    name = "mitsuba"
    config_type = MitsubaConfig
    #: 1 (no history) unless a speed label asks for ``history_s`` of measurements.
    history_frames = 1

    def __init__(self, config: MitsubaConfig, *, seed: int, num_frames: int) -> None:
        super().__init__(config, seed=seed, num_frames=num_frames)
        scene = self.build_scene()
        _check_scene(scene, config, self.camera())
        self.layout: SceneLayout = read_layout(scene, config)
        check_in_view(config, self.layout, self.camera())
        self.tracks = {
            m.id: simulate_mover(m, seed=seed, num_frames=num_frames, fps=config.fps)
            for m in config.movers
        }
        self.switches = simulate_switches(
            config.emitters, seed=seed, num_frames=num_frames, fps=config.fps
        )
        self.label_values = _label_values(config, self.tracks, self.switches)
        if any(label.kind is LabelRule.SPEED for label in config.labels):
            self.history_frames = max(2, round(config.history_s * config.fps))

    @property
    def fps(self) -> float:
        return self.config.fps

    @property
    def labels(self) -> tuple[LabelSpec, ...]:
        return tuple(_label_spec(label, self.config) for label in self.config.labels)

    def camera(self) -> FreeformCamera:
        return self.config.camera.camera()

    def build_scene(self) -> mi.Scene:
        from mincam_render.render.mitsuba_scene import SceneError, load_scene

        try:
            return load_scene(self.config.scene, optimize=False)  # movers keep their ids
        except SceneError as err:
            raise ConfigError(f"scene = '{self.config.scene}': {err}") from None

    def set_frame(self, scene: mi.Scene, index: int) -> dict[str, np.ndarray]:
        self._apply(scene, index, movers=True, switched=self._switched_on(index), static=True)
        return self._labels(index)

    def frame_state(self, index: int) -> JsonObject:
        self.check_index(index)
        return {
            "movers": {
                key: {
                    "present": bool(track.present[index]),
                    "position_m": [float(v) for v in track.position_m[index]],
                }
                for key, track in self.tracks.items()
            },
            "emitters_on": dict(
                zip(
                    [e.id for e in self.config.emitters],
                    map(bool, self.switches[index]),
                    strict=True,
                )
            ),
        }

    def background_key(self, index: int, interval_s: float) -> str:
        bits = "".join("1" if on else "0" for on in self.switches[index])
        return f"emitters={bits}" if bits else STATIC

    def background_components(self, index: int, interval_s: float) -> dict[str, float]:
        parts = {STATIC: 1.0} if self.layout.static_emitters else {}
        for e, on in zip(self.config.emitters, self.switches[index], strict=True):
            if on:
                parts[f"emitter={e.id}"] = 1.0
        return parts

    def set_background(
        self, scene: mi.Scene, index: int, interval_s: float, *, at: float = 0.0
    ) -> None:
        if not 0.0 <= at <= 1.0:
            raise ValueError(f"at = {at!r}: allowed a number in [0, 1]")
        # no slow light in a user's scene: the background is the same across its window
        self._apply(scene, index, movers=False, switched=self._switched_on(index), static=True)

    def set_background_component(self, scene: mi.Scene, key: str) -> None:
        name, _, value = key.partition("=")
        off = (False,) * len(self.config.emitters)
        ids = [e.id for e in self.config.emitters]
        if key == STATIC and self.layout.static_emitters:
            self._apply(scene, 0, movers=False, switched=off, static=True)
        elif name == "emitter" and value in ids:
            on = tuple(i == value for i in ids)
            self._apply(scene, 0, movers=False, switched=on, static=False)
        else:
            raise ValueError(f"{key!r} is not a background component of this scene")

    def set_frame_in_window(
        self, scene: mi.Scene, index: int, interval_s: float
    ) -> dict[str, np.ndarray]:
        return self.set_frame(scene, index)

    def set_frame_without_people(self, scene: mi.Scene, index: int) -> None:
        self._apply(scene, index, movers=False, switched=self._switched_on(index), static=True)

    def birdseye_view(self) -> View:
        """The scene file's own sensor, or a view from behind and above the camera."""
        if self.layout.sensor_view is not None:
            return self.layout.sensor_view
        lo, hi = self.layout.bbox_m
        cam = self.camera()
        _, up, forward = cam.frame
        reach = float(np.linalg.norm(hi - lo))
        eye = np.asarray(cam.position) + reach * (0.6 * up - 0.4 * forward)
        return View(tuple(eye), tuple((lo + hi) / 2), tuple(up), 60.0)

    def _switched_on(self, index: int) -> tuple[bool, ...]:
        self.check_index(index)
        return tuple(bool(v) for v in self.switches[index])

    def _apply(
        self,
        scene: mi.Scene,
        index: int,
        *,
        movers: bool,
        switched: tuple[bool, ...],
        static: bool,
    ) -> None:
        """Set ``scene``: movers at frame ``index`` (or all hidden), emitters on or off."""
        params = mi.traverse(scene)
        for key, shape in self.layout.movers.items():
            track = self.tracks[key]
            shown = movers and bool(track.present[index])
            params[shape.key] = shape.placed(track.position_m[index], shown)
        params.update()
        on = dict.fromkeys(self.layout.static_emitters, static)
        for e, state in zip(self.config.emitters, switched, strict=True):
            on[self.layout.switched[e.id]] = state
        for i, emitter in enumerate(scene.emitters()):
            self.layout.emitters[i].apply(emitter, on[i])

    def _labels(self, index: int) -> dict[str, np.ndarray]:
        return {name: values[index] for name, values in self.label_values.items()}


def _label_values(
    config: MitsubaConfig, tracks: dict[str, MoverTrack], switches: np.ndarray
) -> dict[str, np.ndarray]:
    """Every label of every frame, ``{name: float32 array [frame, size]}``, from the state."""
    out = {}
    for label in config.labels:
        if label.region is not None:  # count_in_region
            inside = [
                tracks[m].present
                & np.array([label.region.contains(tuple(p)) for p in tracks[m].position_m])
                for m in label.movers or tuple(tracks)
            ]
            values = np.sum(inside, axis=0)[:, None]
        elif label.kind is LabelRule.EMITTER_ON:
            column = {e.id: j for j, e in enumerate(config.emitters)}
            values = switches[:, [column[i] for i in _emitters_of(label, config)]]
        elif label.axis is not None:  # position
            values = tracks[label.mover].position_m[:, ["x", "y", "z"].index(label.axis.value)]
            values = values[:, None]
        else:  # speed
            values = tracks[label.mover].speed_m_s[:, None]
        out[label.name] = np.asarray(values, dtype=np.float32)
    return out


def _emitters_of(label: LabelDescription, config: MitsubaConfig) -> tuple[str, ...]:
    """The switched emitters an emitter_on label reports (all when it names none)."""
    return label.emitters or tuple(e.id for e in config.emitters)


def _label_spec(label: LabelDescription, config: MitsubaConfig) -> LabelSpec:
    kind, median_filter_s, unit = RULE_LABELS[label.kind]
    names = _emitters_of(label, config) if label.kind is LabelRule.EMITTER_ON else ()
    return LabelSpec(
        name=label.name,
        kind=kind,
        size=max(len(names), 1),
        unit=unit,
        element_names=names,
        median_filter_s=median_filter_s if label.median_filter_s is None else label.median_filter_s,
    )


def _check_scene(scene: mi.Scene, config: MitsubaConfig, camera: FreeformCamera) -> None:
    """ConfigError for a scene without light, with invalid emission, or far from the camera."""
    from mincam_render.render.mitsuba_scene import SceneError
    from mincam_render.render.user_scene import check_scene

    try:
        check_scene(scene, camera, require_emitter=True)
    except SceneError as err:
        raise ConfigError(f"scene = '{config.scene}': {err}") from None
