"""Workspace family (paper Sec. 7.1): labels from geometry, determinism, continuity, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mincam_render.core.config import ConfigError
from mincam_render.core.labels import LabelKind
from mincam_render.render.capabilities import PeopleRemoval
from mincam_render.scenes.indoor import (
    Appearance,
    IndoorState,
    Pose,
    inside_room,
    zone_overlaps,
)
from mincam_render.scenes.registry import load_family
from mincam_render.scenes.workspace import WorkspaceFamily

pytestmark = pytest.mark.usefixtures("variant")

NUM_FRAMES = 150
#: Local solar midnight for the default daylight (start 7.5 h, 0.003 h/s): no daylight.
MIDNIGHT_S = (24.0 - 7.5) / 0.003
PERSON = Appearance(
    height_m=1.75, build=1.0, upper_albedo=0.5, lower_albedo=0.2, skin_albedo=0.4, speed_m_s=1.2
)


def _family(seed: int = 3, num_frames: int = NUM_FRAMES, **over) -> WorkspaceFamily:
    return load_family(
        "workspace", seed=seed, num_frames=num_frames, overrides={"burn_in_s": 120.0, **over}
    )


@pytest.fixture(scope="module")
def workspace_family() -> WorkspaceFamily:
    return _family()


@pytest.fixture(scope="module")
def workspace_scene(workspace_family):
    return workspace_family.build_scene()


def _small_camera(workspace_family, detectors=2, res=8):
    from dataclasses import replace

    return replace(
        workspace_family.config.camera, detectors=detectors, mask_resolution=res
    ).camera()


def test_label_specs(workspace_family):
    specs = {s.name: s for s in workspace_family.labels}
    assert specs["people_count"].kind is LabelKind.COUNT
    assert specs["people_count"].median_filter_s == 2.0
    assert specs["zones"].kind is LabelKind.BINARY
    assert specs["zones"].element_names == ("entrance", "desks_south", "desks_north", "meeting")
    assert specs["zones"].size == 4 and specs["zones"].median_filter_s == 0.5
    assert specs["door_open"].kind is LabelKind.BINARY and specs["door_open"].median_filter_s == 0.5


@pytest.mark.parametrize("zone_index", range(4))
def test_person_in_zone_sets_that_zone_only(workspace_family, zone_index):
    zone = workspace_family.config.zones[zone_index]
    x0, y0, x1, y1 = zone.rect_m
    state = IndoorState(
        people=((PERSON, Pose(0.5 * (x0 + x1), 0.5 * (y0 + y1))),), lights_on=(True, True)
    )
    labels = workspace_family.labels_for(state)
    expected = np.zeros(4, dtype=np.float32)
    expected[zone_index] = 1.0
    np.testing.assert_array_equal(labels["zones"], expected)
    assert labels["people_count"][0] == 1.0


def test_footprint_overlap_at_zone_edge(workspace_family):
    zone = workspace_family.config.zones[1]  # desks_south, x from 1.0
    r = PERSON.radius_m
    y = 0.5 * (zone.rect_m[1] + zone.rect_m[3])
    assert zone_overlaps(zone, zone.rect_m[0] - 0.9 * r, y, r)
    assert not zone_overlaps(zone, zone.rect_m[0] - 1.1 * r, y, r)


def test_person_in_corridor_is_not_counted(workspace_family):
    corridor, doorway, _ = workspace_family.rig.door.waypoints()
    state = IndoorState(people=((PERSON, Pose(*corridor)),), lights_on=(True, True))
    labels = workspace_family.labels_for(state)
    assert labels["people_count"][0] == 0.0
    assert labels["zones"].sum() == 0.0


@pytest.mark.parametrize(("angle_deg", "is_open"), [(0.0, 0), (5.0, 0), (15.0, 1), (90.0, 1)])
def test_door_label_from_angle(workspace_family, angle_deg, is_open):
    state = IndoorState(door_angle_rad=math.radians(angle_deg), lights_on=(True, True))
    assert workspace_family.labels_for(state)["door_open"][0] == is_open


def test_door_geometry_swings_into_room(workspace_family):
    door = workspace_family.rig.door
    closed = door.vertices(0.0)
    opened = door.vertices(math.radians(90.0))
    d = workspace_family.config.room.size_m[1]  # the default door is in the north wall (y = D)
    assert np.all(np.abs(closed[:, 1] - d) <= door.THICKNESS_M + 1e-6)
    assert opened[:, 1].min() < d - 0.8  # the leaf now sticks ~0.9 m into the room
    hinge_x = door.hinge[0]
    assert np.all(np.abs(opened[:, 0] - hinge_x) <= door.THICKNESS_M + 1e-6)


def test_people_count_equals_people_inside(workspace_family):
    for index in range(0, NUM_FRAMES, 10):
        state = workspace_family.state(index)
        inside = sum(inside_room(workspace_family.config.room, p.x, p.y) for _, p in state.people)
        assert workspace_family.labels_for(state)["people_count"][0] == inside
    counts = [
        workspace_family.labels_for(workspace_family.state(i))["people_count"][0]
        for i in range(NUM_FRAMES)
    ]
    assert 0 <= min(counts) and max(counts) <= workspace_family.config.max_people


def test_set_frame_updates_geometry_and_returns_labels(workspace_family, workspace_scene):
    import mitsuba as mi

    labels = workspace_family.set_frame(workspace_scene, 7)
    expected = workspace_family.labels_for(workspace_family.state(7))
    for k, v in expected.items():
        np.testing.assert_array_equal(labels[k], v)
        assert labels[k].dtype == np.float32
    params = mi.traverse(workspace_scene)
    v = np.asarray(params["door.vertex_positions"]).reshape(-1, 3)
    np.testing.assert_allclose(
        v, workspace_family.rig.door.vertices(workspace_family.state(7).door_angle_rad), atol=1e-5
    )


def test_continuity_between_frames(workspace_family):
    tr = workspace_family.track
    vmax = workspace_family.config.people.walk_speed_m_s[1]
    same = tr.active[1:] & tr.active[:-1] & (tr.visit[1:] == tr.visit[:-1])
    step = np.linalg.norm(tr.pose[1:, :, :2] - tr.pose[:-1, :, :2], axis=-1)
    assert same.any()
    assert np.all(step[same] <= vmax / workspace_family.fps + 1e-9)
    dmax = math.radians(workspace_family.config.door.speed_deg_s) / workspace_family.fps
    assert np.all(np.abs(np.diff(tr.door_angle_rad)) <= dmax + 1e-9)


def test_deterministic_for_a_seed(workspace_family, workspace_scene):
    from mincam_render.render.transport import render_transport

    other = _family()
    np.testing.assert_array_equal(workspace_family.track.pose, other.track.pose)
    np.testing.assert_array_equal(workspace_family.lights_on, other.lights_on)
    cam = _small_camera(workspace_family)
    # visiting frames out of order gives the same frame
    workspace_family.set_frame(workspace_scene, 40)
    a = render_transport(workspace_scene, cam, spp=4, seed=1)
    workspace_family.set_frame(workspace_scene, 90)
    workspace_family.set_frame(workspace_scene, 40)
    b = render_transport(workspace_scene, cam, spp=4, seed=1)
    np.testing.assert_array_equal(a, b)
    assert a.sum() > 0
    different = _family(seed=4)
    assert not np.array_equal(workspace_family.track.pose, different.track.pose)


def test_ceiling_light_brightens_transport(workspace_family, workspace_scene):
    from mincam_render.render.transport import render_transport

    cam = _small_camera(workspace_family)
    dark = IndoorState(lights_on=(False, False), daylight_time_s=MIDNIGHT_S)
    lit = IndoorState(lights_on=(True, False), daylight_time_s=MIDNIGHT_S)
    workspace_family.apply_state(workspace_scene, dark)
    t_dark = render_transport(workspace_scene, cam, spp=4, seed=0)
    workspace_family.apply_state(workspace_scene, lit)
    t_lit = render_transport(workspace_scene, cam, spp=4, seed=0)
    assert t_lit.sum() > 10 * max(t_dark.sum(), 1e-15)


def test_desk_illuminance_is_indoor_level(workspace_family, workspace_scene):
    """Both banks on at night: a desk top gets 300-600 lux (office lighting)."""
    import mitsuba as mi

    from mincam_render.core.photometry import irradiance_to_lux
    from mincam_render.render import mitsuba_scene as ms

    workspace_family.apply_state(
        workspace_scene, IndoorState(lights_on=(True, True), daylight_time_s=MIDNIGHT_S)
    )
    # a 10 cm lux meter lying on the desk top, facing up
    meter = mi.load_dict(ms.irradiance_meter((1.9, 1.7, 0.76), (0, 0, 1), (1, 0, 0), (0.1, 0.1)))
    e = float(np.asarray(mi.render(workspace_scene, sensor=meter.sensor(), spp=1024)).ravel()[0])
    assert 300.0 < irradiance_to_lux(e) < 600.0


def _write(tmp_path, text):
    path = tmp_path / "bad.toml"
    path.write_text('family = "workspace"\n' + text)
    return path


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("colour = 3\n", "colour"),
        ("max_people = 'eight'\n", "max_people"),
        ("max_people = 20\n", "max_people"),
        ("[[zones]]\nname = 'outside'\nrect_m = [5.0, 4.0, 7.5, 5.0]\n", "zones[0].rect_m"),
        ("[camera]\nposition = [7.0, 1.0, 2.0]\nlook_at = [2.0, 2.0, 0.5]\n", "camera.position"),
        ("[door]\ncenter_m = 5.9\n", "door.center_m"),
        ("[room]\nsize_m = [6.0, 'x', 2.8]\n", "room.size_m[1]"),
    ],
)
def test_bad_descriptions_are_rejected(tmp_path, text, field):
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_family(path, seed=0, num_frames=1)
    assert str(path) in str(err.value)
    assert field in str(err.value)


def test_applying_only_what_changed_renders_as_a_fresh_scene(workspace_family):
    """A scene taken through other frames (lights, door, people, daylight skipped when
    unchanged) renders bit for bit like a fresh scene set to the last frame."""
    import dataclasses

    from mincam_render.render.transport import render_transport

    cam = dataclasses.replace(workspace_family.camera(), mask_resolution=(4, 4))
    busy = [i for i in range(NUM_FRAMES) if len(workspace_family.state(i).people) >= 2]
    last = busy[-1]
    walked = workspace_family.build_scene()
    for i in (busy[0], 0, busy[len(busy) // 2], last, last):
        workspace_family.set_frame(walked, i)
    workspace_family.set_frame_in_window(walked, last, 60.0)  # other daylight, then back
    workspace_family.set_frame(walked, last)
    fresh = workspace_family.build_scene()
    workspace_family.set_frame(fresh, last)
    a = render_transport(walked, cam, spp=4, seed=2, max_depth=3)
    b = render_transport(fresh, cam, spp=4, seed=2, max_depth=3)
    np.testing.assert_array_equal(a, b)


def test_a_frame_without_its_people_keeps_the_door_and_changes_only_what_they_touch():
    """The privacy audit's background: every slot parked, the frame's door kept; with the
    frame's seed, pixels whose light paths miss the people are bit-identical."""
    import mitsuba as mi

    from mincam_render.render import mitsuba_scene as ms
    from mincam_render.scenes.indoor import PEOPLE_VERTICES_PARAM

    family = _family(fps=1.0, num_frames=20)  # 20 s: people come in through the open door
    assert isinstance(family, PeopleRemoval)
    i = max(range(20), key=lambda k: (len(family.state(k).people) > 0,
                                      family.state(k).door_angle_rad))  # fmt: skip
    state = family.state(i)
    assert state.people and state.door_angle_rad > 0.1
    cam = family.camera()
    sensor = ms.perspective_sensor(cam.position, cam.look_at, cam.up, cam.fov_deg, 32, 32)
    scene = family.build_scene()
    family.set_frame(scene, i)
    view = np.asarray(mi.render(scene, sensor=sensor, spp=4, seed=i))[..., 0]
    family.set_frame_without_people(scene, i)
    empty = np.asarray(mi.render(scene, sensor=sensor, spp=4, seed=i))[..., 0]
    params = mi.traverse(scene)
    vertices = np.asarray(params[PEOPLE_VERTICES_PARAM]).reshape(-1, 3)
    assert np.all(vertices[:, 2] < -10.0)  # every slot parked below the floor
    door = np.asarray(params["door.vertex_positions"]).reshape(-1, 3)
    np.testing.assert_allclose(door, family.rig.door.vertices(state.door_angle_rad), atol=1e-5)
    changed = np.mean(view != empty)
    assert 0.0 < changed < 0.5, changed  # the people's pixels (and their light), not the room
    family.set_frame(scene, i)  # and back: the frame again, bit for bit
    again = np.asarray(mi.render(scene, sensor=sensor, spp=4, seed=i))[..., 0]
    np.testing.assert_array_equal(again, view)


def test_people_mesh_carries_each_persons_albedo_per_vertex(workspace_family):
    import mitsuba as mi

    from mincam_render.scenes.indoor import PEOPLE_ALBEDO_PARAM, PEOPLE_VERTICES_PARAM

    scene = workspace_family.build_scene()
    state = IndoorState(
        people=((PERSON, Pose(2.0, 2.0)),), lights_on=workspace_family.state(0).lights_on
    )
    workspace_family.apply_state(scene, state)
    params = mi.traverse(scene)
    layout = workspace_family.rig.people
    albedo = np.asarray(params[PEOPLE_ALBEDO_PARAM])
    vertices = np.asarray(params[PEOPLE_VERTICES_PARAM]).reshape(-1, 3)
    upper, lower, skin = layout.part_sizes
    np.testing.assert_allclose(albedo[layout.slot(0)][:upper], PERSON.upper_albedo)
    np.testing.assert_allclose(albedo[layout.slot(0)][upper : upper + lower], PERSON.lower_albedo)
    np.testing.assert_allclose(albedo[layout.slot(0)][upper + lower :], PERSON.skin_albedo)
    assert vertices[layout.slot(0)][:, 2].min() > -0.01  # standing on the floor
    assert np.all(vertices[layout.slot(1)][:, 2] < -10.0)  # unused slots parked below it
    np.testing.assert_allclose(albedo[layout.slot(1)], 0.3)


@pytest.mark.parametrize(("target_z_m", "where"), [(1.0, "corridor"), (2.2, "wall"), (2.3, "wall")])
def test_open_doorway_shows_the_corridor_and_the_wall_above_it_faces_the_room(
    workspace_family, target_z_m, where
):
    """The corridor is open on the room's side: no face in the doorway, none on the wall.

    A closed corridor box put a face in the doorway and one coplanar with the
    north wall above it, facing away from the room; rays then met either the
    wall or that face's black back, depending on the traversal.
    """
    import mitsuba as mi

    rig = workspace_family.rig
    scene = rig.build_scene()
    off = (False,) * len(rig.lights)
    rig.apply(scene, IndoorState(door_angle_rad=math.radians(90.0), lights_on=off, daylight=False))
    door = rig.door
    d_room = workspace_family.config.room.size_m[1]
    # from the middle of the room toward the doorway's centre line, below and
    # above the door's top (2.05 m) but under the corridor's ceiling (2.35 m)
    target = np.array([door.center[0], d_room, target_z_m])
    origin = np.array([door.center[0], d_room - 2.0, 1.2])
    direction = (target - origin) / np.linalg.norm(target - origin)
    ray = mi.Ray3f(mi.Point3f(*map(float, origin)), mi.Vector3f(*map(float, direction)))
    si = scene.ray_intersect(ray)
    hit = np.array(si.p).ravel()
    normal = np.array(si.n).ravel()
    assert bool(si.is_valid()[0])
    assert float(normal @ direction) < 0.0  # a front face, lit by the room or the corridor
    if where == "corridor":
        assert hit[1] > d_room + 0.5  # through the doorway to the corridor's far wall
    else:
        assert hit[1] == pytest.approx(d_room, abs=1e-5)
        np.testing.assert_allclose(normal, [0.0, -1.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("name", ["workspace", "lighting"])
def test_an_empty_room_renders_with_nobody_counted(name):
    """Regression: max_people = 0 passed validation, then failed to build the people mesh."""
    from mincam_render.render.transport import render_transport

    empty = load_family(name, seed=3, num_frames=20, overrides={"max_people": 0})
    scene = empty.build_scene()
    cam = _small_camera(empty, res=4)
    for i in (0, 19):
        labels = empty.set_frame(scene, i)
        assert not empty.frame_state(i)["people"]
        t = render_transport(scene, cam, spp=2, seed=i)
        assert t.shape == (2, 4, 4) and np.all(np.isfinite(t)) and np.all(t >= 0)
    if "count" in labels:
        assert float(np.asarray(labels["count"]).sum()) == 0.0
