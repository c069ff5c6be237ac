"""The indoor scene in Mitsuba: built once, then set to each frame's state in place.

:class:`IndoorRig` builds the scene (the room shell, corridor and furniture as
one mesh, every person slot in one mesh, the door, lights, sun and sky) and
applies an :class:`IndoorState` to its parameters, changing only what differs
from the state last applied.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from mincam_render.render import mitsuba_scene as ms
from mincam_render.scenes.indoor.config import (
    DoorConfig,
    FloorLampConfig,
    FurnitureConfig,
    LightBankConfig,
    RoomConfig,
    Wall,
    WindowConfig,
    wall_frame,
)
from mincam_render.scenes.indoor.door import Door
from mincam_render.scenes.indoor.geometry import (
    bank_radiance_w_m2_sr,
    ceiling_panels,
    furniture_mesh,
    lamp_meshes,
    lamp_radiance_w_m2_sr,
    merge_meshes,
    quad,
    wall_with_holes,
)
from mincam_render.scenes.indoor.people import Appearance, BodyModel, Pose

if TYPE_CHECKING:
    import mitsuba as mi

    from mincam_render.render.capabilities import View
    from mincam_render.scenes.sky import Daylight, DaylightConfig

#: Parameter keys of the sun and sky (checked against mi.traverse at build time).
SUN_KEY, SKY_KEY = "sun", "sky"
SUN_IRRADIANCE_PARAM = f"{SUN_KEY}.irradiance.value"
SUN_TO_WORLD_PARAM = f"{SUN_KEY}.to_world"
SKY_DATA_PARAM = f"{SKY_KEY}.data"
ROOM_KEY = "room"
PEOPLE_KEY = "people"
PEOPLE_VERTICES_PARAM = f"{PEOPLE_KEY}.vertex_positions"
PEOPLE_ALBEDO_PARAM = f"{PEOPLE_KEY}.{ms.VERTEX_ALBEDO}"
#: Albedo of an unused (parked) person slot.
PARKED_ALBEDO = 0.3
DOOR_KEY = "door"
DOOR_VERTICES_PARAM = f"{DOOR_KEY}.vertex_positions"
#: Lat-long size of the sky map seen through windows (a smooth CIE sky needs little).
SKY_MAP_SIZE = (32, 64)
#: Scenes whose parameters an :class:`IndoorRig` keeps between frames (the render
#: scene plus one more, e.g. a preview's).
_SCENES_KEPT = 2
#: Sampling weight of a switched-off emitter: tiny, never zero (an all-dark scene
#: must still have a valid emitter distribution).
OFF_SAMPLING_WEIGHT = 1e-6


@dataclass(frozen=True)
class Light:
    """A switchable emitter of the scene: its dict key and its radiance when on (W m^-2 sr^-1)."""

    name: str
    key: str
    radiance_w_m2_sr: float

    @property
    def radiance_param(self) -> str:
        return f"{self.key}.emitter.radiance.value"

    @property
    def weight_param(self) -> str:
        return f"{self.key}.emitter.sampling_weight"


class SkySampling(enum.Enum):
    """How light samples find the sky seen through the window."""

    PORTAL = "portal"  # through the window opening (mincam_render.render.portal_sky)
    ENVMAP = "envmap"  # Mitsuba's envmap: over the whole sphere (for validation)


@dataclass(frozen=True)
class IndoorState:
    """Everything that changes between frames of an indoor scene.

    Args:
        people: the people in the scene (inside the room or in the corridor) as
            ``(appearance, pose)``; at most the family's number of slots. The
            rest of the slots are parked out of sight.
        door_angle_rad: opening of the door (0 = closed); ignored without a door.
        lights_on: on/off per switchable light, in the family's order.
        daylight_time_s: time (s) whose sun and sky light the window.
        daylight: False turns the sun and sky off (one light's background
            component); the sky keeps a 1e-6 W m^-2 sr^-1 floor so its sampling
            stays defined (about 1e-7 of the daylit sky).
    """

    people: tuple[tuple[Appearance, Pose], ...] = ()
    door_angle_rad: float = 0.0
    lights_on: tuple[bool, ...] = ()
    daylight_time_s: float = 0.0
    daylight: bool = True


def static_shapes(
    room: RoomConfig,
    window: WindowConfig | None,
    door: Door | None,
    furniture: tuple[FurnitureConfig, ...],
) -> dict:
    """The room shell, corridor and furniture as one Mitsuba mesh with a per-vertex albedo.

    One shape rather than one per albedo: every shape adds to the per-frame cost
    of tracing the render kernel (Dr.Jit records each shape's and BSDF's calls).
    """
    holes: dict[Wall, list] = {w: [] for w in Wall}
    if window is not None:
        holes[window.wall].append(
            (
                window.center_m - window.width_m / 2,
                window.center_m + window.width_m / 2,
                window.sill_height_m,
                window.sill_height_m + window.height_m,
            )
        )
    if door is not None:
        c = door.config
        holes[c.wall].append(
            (c.center_m - c.width_m / 2, c.center_m + c.width_m / 2, 0.0, c.height_m)
        )
    w, d, h = room.size_m
    parts = [(wall_with_holes(room, wall, holes[wall]), room.wall_albedo) for wall in Wall]
    floor = quad((0, 0, 0), (w, 0, 0), (w, d, 0), (0, d, 0), (0, 0, 1.0))
    ceiling = quad((0, 0, h), (w, 0, h), (w, d, h), (0, d, h), (0, 0, -1.0))
    parts += [(floor, room.floor_albedo), (ceiling, room.ceiling_albedo)]
    if door is not None:
        parts.append((door.corridor(room), door.config.corridor_albedo))
    parts += [(furniture_mesh(item), item.reflectance) for item in furniture]
    vertices, faces = merge_meshes([mesh for mesh, _ in parts])
    albedo = np.concatenate([np.full(len(mesh[0]), a) for mesh, a in parts])
    return {ROOM_KEY: ms.mesh(ROOM_KEY, vertices, faces, reflectance=albedo)}


class PeopleLayout:
    """Where each person slot's vertices lie in the one mesh holding every person.

    All people are one mesh (key ``"people"``) with a per-vertex albedo
    (``vertex_albedo``), not three meshes per slot: Dr.Jit records the calls of
    every shape and BSDF when it traces a frame's render, and the 24 person
    meshes of the workspace's 8 slots cost about 4 ms of tracing per frame
    (render at 1 spp: 13.8 ms with them, 9-10 ms with one mesh).
    Slot ``s`` owns vertices ``[s V, (s + 1) V)``,
    its parts (upper clothes, lower clothes, skin) in :attr:`BodyModel.PARTS` order.
    """

    def __init__(self, body: BodyModel, slots: int) -> None:
        self.body, self.slots = body, slots
        parked = body.parked()
        self.part_sizes = [len(parked[p]) for p in BodyModel.PARTS]
        self.slot_size = sum(self.part_sizes)
        self.parked_vertices = np.concatenate([parked[p] for p in BodyModel.PARTS])
        offsets = np.cumsum([0, *self.part_sizes[:-1]])
        parts = zip(BodyModel.PARTS, offsets, strict=True)
        one = np.concatenate([body.faces[p] + o for p, o in parts])
        # (slots F, 3): no faces in an empty room (no slots)
        self.faces = (one[None] + self.slot_size * np.arange(slots)[:, None, None]).reshape(-1, 3)

    def person(self, a: Appearance, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices (V, 3) m, albedo (V,))`` of one slot holding person ``a`` in ``pose``."""
        v = self.body.vertices(a, pose)
        albedo = np.repeat([a.upper_albedo, a.lower_albedo, a.skin_albedo], self.part_sizes)
        return np.concatenate([v[p] for p in BodyModel.PARTS]), albedo

    def empty(self) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices, albedo)`` of an unused slot: parked out of sight."""
        return self.parked_vertices, np.full(self.slot_size, PARKED_ALBEDO)

    def slot(self, s: int) -> slice:
        """Vertex range of slot ``s``."""
        return slice(s * self.slot_size, (s + 1) * self.slot_size)

    def shape(self) -> mi.Mesh:
        """The people mesh with every slot parked, for a scene dict."""
        v, albedo = self.empty()
        return ms.mesh(
            PEOPLE_KEY,
            np.tile(v, (self.slots, 1)),
            self.faces,
            reflectance=np.tile(albedo, self.slots),
        )


@dataclass
class _SceneCache:
    """An indoor scene's parameters and the state last applied to it.

    Holds the scene itself, so its identity cannot be reused while cached.
    """

    scene: object
    params: Any  # mi.SceneParameters
    applied: dict[str, object]
    people_vertices: np.ndarray  # (slots V, 3) float32, m
    people_albedo: np.ndarray  # (slots V,) float32


class IndoorRig:
    """Builds an indoor scene once and applies an :class:`IndoorState` to it in place."""

    def __init__(
        self,
        *,
        room: RoomConfig,
        window: WindowConfig | None,
        door: DoorConfig | None,
        furniture: tuple[FurnitureConfig, ...],
        banks: tuple[LightBankConfig, ...],
        lamps: tuple[FloorLampConfig, ...],
        daylight: DaylightConfig,
        daylight_update_s: float,
        slots: int,
        max_depth: int,
        sky_sampling: SkySampling = SkySampling.PORTAL,
    ) -> None:
        self.room, self.window, self.furniture = room, window, furniture
        self.door = Door(room, door) if door is not None else None
        self.banks, self.lamps = banks, lamps
        self.daylight_config, self.daylight_update_s = daylight, daylight_update_s
        self.slots, self.max_depth = slots, max_depth
        self.sky_sampling = sky_sampling
        self.body = BodyModel()
        self.people = PeopleLayout(self.body, slots)
        self.lights = tuple(
            [Light(b.name, f"bank_{i}", bank_radiance_w_m2_sr(b)) for i, b in enumerate(banks)]
            + [Light(lp.name, f"lamp_{i}", lamp_radiance_w_m2_sr(lp)) for i, lp in enumerate(lamps)]
        )
        self._sky_cache: dict[float, Daylight] = {}
        self._scenes: list[_SceneCache] = []  # newest first

    # -- building
    def param_keys(self) -> list[str]:
        keys = [PEOPLE_VERTICES_PARAM, PEOPLE_ALBEDO_PARAM] if self.slots else []
        keys += [li.radiance_param for li in self.lights] + [li.weight_param for li in self.lights]
        if self.door is not None:
            keys.append(DOOR_VERTICES_PARAM)
        if self.window is not None:
            keys += [SUN_IRRADIANCE_PARAM, SUN_TO_WORLD_PARAM, SKY_DATA_PARAM]
        return keys

    def build_scene(self) -> mi.Scene:
        import mitsuba as mi

        from mincam_render.scenes.sky import envmap_to_world

        shapes = static_shapes(self.room, self.window, self.door, self.furniture)
        if self.door is not None:
            shapes[DOOR_KEY] = ms.mesh(
                DOOR_KEY,
                self.door.vertices(0.0),
                self.door.faces,
                reflectance=self.door.config.albedo,
            )
        for li, b in zip(self.lights, self.banks, strict=False):
            shapes[li.key] = ms.mesh(
                li.key,
                *ceiling_panels(self.room, b),
                reflectance=0.8,
                radiance_w_m2_sr=li.radiance_w_m2_sr,
            )
        poles = []
        for li, lamp in zip(self.lights[len(self.banks) :], self.lamps, strict=True):
            pole, shade = lamp_meshes(lamp)
            poles.append(pole)
            shapes[li.key] = ms.mesh(
                li.key, *shade, reflectance=0.8, radiance_w_m2_sr=li.radiance_w_m2_sr
            )
        if poles:
            shapes["lamp_poles"] = ms.mesh("lamp_poles", *merge_meshes(poles), reflectance=0.08)
        if self.slots:
            shapes[PEOPLE_KEY] = self.people.shape()
        if self.window is not None:
            day = self.sky(0.0)
            shapes[SUN_KEY] = ms.directional_light(-day.sun_direction, day.sun_irradiance_w_m2)
            if self.sky_sampling is SkySampling.PORTAL:
                shapes[SKY_KEY] = ms.portal_sky(day.sky_radiance_w_m2_sr, *self.window_rectangle())
            else:
                shapes[SKY_KEY] = ms.environment_map(day.sky_radiance_w_m2_sr, envmap_to_world())
        scene = ms.load_scene(ms.scene_dict(shapes, max_depth=self.max_depth))
        params = mi.traverse(scene)
        missing = [k for k in self.param_keys() if k not in params]
        if missing:
            raise RuntimeError(f"scene has no parameter(s) {missing[:4]}")
        return scene

    def window_rectangle(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The window opening ``(corner, edge_u, edge_v)`` (m, world), edge_u x edge_v outward."""
        w = self.window
        if w is None:
            raise ValueError("the room has no window")
        origin, t, inward = wall_frame(self.room, w.wall)
        corner = origin + (w.center_m - w.width_m / 2) * t + w.sill_height_m * np.array([0, 0, 1.0])
        edge_u, edge_v = w.width_m * t, w.height_m * np.array([0, 0, 1.0])
        if np.cross(edge_u, edge_v) @ inward > 0:
            corner, edge_u = corner + edge_u, -edge_u
        return corner, edge_u, edge_v

    def sky(self, time_s: float) -> Daylight:
        """Daylight at ``time_s`` rounded down to the update interval (cached)."""
        from mincam_render.scenes.sky import daylight

        tq = self.daylight_time_s(time_s)
        if tq not in self._sky_cache:
            if len(self._sky_cache) > 64:
                self._sky_cache.clear()
            self._sky_cache[tq] = daylight(
                self.daylight_config, tq, height=SKY_MAP_SIZE[0], width=SKY_MAP_SIZE[1]
            )
        return self._sky_cache[tq]

    def daylight_time_s(self, time_s: float) -> float:
        """The time (s) whose daylight is shown at ``time_s``: rounded down to the update period."""
        return math.floor(time_s / self.daylight_update_s + 1e-9) * self.daylight_update_s

    # -- per frame
    def apply(self, scene: mi.Scene, state: IndoorState) -> None:
        """Set ``scene``'s parameters to ``state`` in place (no rebuild)."""
        import drjit as dr
        import mitsuba as mi

        # scalars go in as opaque variables, not literals: a literal's value is
        # baked into the kernel, so each new value would compile a new kernel

        if len(state.people) > self.slots:
            raise ValueError(
                f"state has {len(state.people)} people; the scene has {self.slots} slots"
            )
        if len(state.lights_on) != len(self.lights):
            raise ValueError(
                f"state has {len(state.lights_on)} light states; the scene has "
                f"{len(self.lights)} lights"
            )
        cache = self._parameters(scene)
        params, applied = cache.params, cache.applied
        # only what differs from the state last applied to this scene is set:
        # parked slots, unchanged lights and a window's fixed daylight cost nothing
        wanted: dict[str, object] = {}
        for s in range(self.slots):
            wanted[f"slot{s}"] = state.people[s] if s < len(state.people) else None
        wanted["lights"] = tuple(state.lights_on)
        wanted["door"] = state.door_angle_rad if self.door is not None else None
        wanted["daylight"] = (
            (self.daylight_time_s(state.daylight_time_s), state.daylight)
            if self.window is not None
            else None
        )
        todo = {k: v for k, v in wanted.items() if k not in applied or applied[k] != v}
        slots = [s for s in range(self.slots) if f"slot{s}" in todo]
        for s in slots:
            person = state.people[s] if s < len(state.people) else None
            v, albedo = self.people.empty() if person is None else self.people.person(*person)
            cache.people_vertices[self.people.slot(s)] = v
            cache.people_albedo[self.people.slot(s)] = albedo
        if slots:
            params[PEOPLE_VERTICES_PARAM] = mi.Float(cache.people_vertices.ravel())
            params[PEOPLE_ALBEDO_PARAM] = mi.Float(cache.people_albedo)
        if "lights" in todo:
            for li, on in zip(self.lights, state.lights_on, strict=True):
                params[li.radiance_param] = dr.opaque(mi.Float, li.radiance_w_m2_sr if on else 0.0)
                params[li.weight_param] = 1.0 if on else OFF_SAMPLING_WEIGHT
        if self.door is not None and "door" in todo:
            params[DOOR_VERTICES_PARAM] = mi.Float(
                self.door.vertices(state.door_angle_rad).astype(np.float32).ravel()
            )
        if self.window is not None and "daylight" in todo:
            day = self.sky(state.daylight_time_s)
            sun_on = 1.0 if state.daylight else 0.0
            params[SUN_IRRADIANCE_PARAM] = dr.opaque(mi.Float, sun_on * day.sun_irradiance_w_m2)
            params[SUN_TO_WORLD_PARAM] = ms.directional_light_to_world(-day.sun_direction)
            sky = np.maximum(sun_on * day.sky_radiance_w_m2_sr, 1e-6)
            params[SKY_DATA_PARAM] = (
                ms.portal_sky_data(sky)
                if self.sky_sampling is SkySampling.PORTAL
                else ms.environment_map_data(sky)
            )
        params.update()
        applied.update(todo)

    def _parameters(self, scene: mi.Scene) -> _SceneCache:
        """What this rig keeps of ``scene`` between frames (for the scenes last used)."""
        import mitsuba as mi

        for cache in self._scenes:
            if cache.scene is scene:
                return cache
        n = self.slots * self.people.slot_size
        cache = _SceneCache(
            scene=scene,
            params=mi.traverse(scene),
            applied={},  # nothing known: the first apply sets everything
            people_vertices=np.zeros((n, 3), dtype=np.float32),
            people_albedo=np.zeros(n, dtype=np.float32),
        )
        self._scenes = [cache, *self._scenes[: _SCENES_KEPT - 1]]
        return cache

    def birdseye_view(self) -> View:
        from mincam_render.render.capabilities import View

        w, d, h = self.room.size_m
        half = 0.5 * max(w, d) + 0.2
        fov = 2 * math.degrees(math.atan(half / (h - 0.1)))
        return View((w / 2, d / 2, h - 0.1), (w / 2, d / 2, 0.0), (0.0, 1.0, 0.0), min(fov, 150.0))
