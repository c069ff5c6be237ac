"""Shared pieces of the indoor families: room, furniture, door, lights and people.

World frame (indoor scenes): metres, +z up, +x east, +y north. A room spans
``[0, W] x [0, D] x [0, H]`` (``RoomConfig.size_m``); its walls are named by
compass side (:class:`Wall`): south is ``y = 0``, north ``y = D``, west
``x = 0``, east ``x = W``. A position *along* a wall (``center_m`` of a door or
window) is measured from its west end (south/north walls) or south end
(west/east walls).

Modules: :mod:`.config` (descriptions and their checks), :mod:`.geometry`
(meshes, numpy + trimesh), :mod:`.door`, :mod:`.people` (appearance, pose, body
model), :mod:`.motion` (paths, the people simulator, door dynamics, light
switching), :mod:`.rig` (the Mitsuba scene and its per-frame parameters) and
:mod:`.family` (:class:`IndoorFamily`). Here: the names the families and tests use.
"""

from mincam_render.scenes.indoor.config import (
    DoorConfig,
    FloorLampConfig,
    FurnitureConfig,
    FurnitureKind,
    LightBankConfig,
    PeopleConfig,
    RoomConfig,
    Wall,
    WindowConfig,
    ZoneConfig,
    check_inside,
    check_room_layout,
    check_zones,
)
from mincam_render.scenes.indoor.family import IndoorFamily
from mincam_render.scenes.indoor.geometry import (
    inside_room,
    lamp_surface_points,
    points_in_view,
    zone_overlaps,
)
from mincam_render.scenes.indoor.motion import switching_process
from mincam_render.scenes.indoor.people import Appearance, Pose
from mincam_render.scenes.indoor.rig import (
    PEOPLE_ALBEDO_PARAM,
    PEOPLE_VERTICES_PARAM,
    IndoorState,
    SkySampling,
)

__all__ = [
    "PEOPLE_ALBEDO_PARAM",
    "PEOPLE_VERTICES_PARAM",
    "Appearance",
    "DoorConfig",
    "FloorLampConfig",
    "FurnitureConfig",
    "FurnitureKind",
    "IndoorFamily",
    "IndoorState",
    "LightBankConfig",
    "PeopleConfig",
    "Pose",
    "RoomConfig",
    "SkySampling",
    "Wall",
    "WindowConfig",
    "ZoneConfig",
    "check_inside",
    "check_room_layout",
    "check_zones",
    "inside_room",
    "lamp_surface_points",
    "points_in_view",
    "switching_process",
    "zone_overlaps",
]
