"""Lighting family (paper Sec. 7.2): lights out of view, labels follow switches, bad input."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mincam_render.core.config import ConfigError
from mincam_render.core.labels import LabelKind
from mincam_render.scenes.indoor import IndoorState, lamp_surface_points, points_in_view
from mincam_render.scenes.lighting import LightingFamily, panel_points
from mincam_render.scenes.registry import load_family

pytestmark = pytest.mark.usefixtures("variant")

NUM_FRAMES = 120
NAMES = ("overhead_south", "overhead_north", "lamp_southwest", "lamp_southeast", "lamp_west")


def _family(seed: int = 5, **over) -> LightingFamily:
    return load_family(
        "lighting", seed=seed, num_frames=NUM_FRAMES, overrides={"burn_in_s": 60.0, **over}
    )


@pytest.fixture(scope="module")
def lighting_family() -> LightingFamily:
    return _family()


@pytest.fixture(scope="module")
def lighting_scene(lighting_family):
    return lighting_family.build_scene()


@pytest.fixture(scope="module")
def lighting_camera(lighting_family):
    """The default pose with 16 x 16 masks (fast), all 8 detectors."""
    return replace(lighting_family.config.camera, mask_resolution=16).camera()


def _only(index: int | None) -> tuple[bool, ...]:
    return tuple(i == index for i in range(len(NAMES)))


def test_label_spec(lighting_family):
    (spec,) = lighting_family.labels
    assert spec.name == "lights" and spec.kind is LabelKind.BINARY
    assert spec.size == 5 and spec.element_names == NAMES
    assert spec.median_filter_s == 0.5


def test_emitters_project_outside_every_mask(lighting_family):
    cam = lighting_family.camera()
    for lamp in lighting_family.config.floor_lamps:
        assert not points_in_view(cam, lamp_surface_points(lamp)).any(), lamp.name
    for bank in lighting_family.config.ceiling_lights:
        assert not points_in_view(cam, panel_points(lighting_family.config.room, bank)).any(), (
            bank.name
        )


def test_view_check_sees_a_point_in_front(lighting_family):
    cam = lighting_family.camera()
    assert points_in_view(cam, [np.asarray(cam.look_at)]).all()


def test_no_emitter_is_directly_visible(lighting_family, lighting_scene, lighting_camera):
    """Depth 1 renders only emitters seen directly: with every light on it is black."""
    from mincam_render.render.transport import render_transport

    lighting_family.apply_state(lighting_scene, IndoorState(lights_on=(True,) * 5))
    t = render_transport(lighting_scene, lighting_camera, spp=4, seed=0, max_depth=1)
    assert float(np.abs(t).max()) == 0.0
    assert render_transport(lighting_scene, lighting_camera, spp=4, seed=0).sum() > 0


@pytest.mark.parametrize("light", range(5), ids=NAMES)
def test_switching_a_light_on_brightens_its_side(
    lighting_family, lighting_scene, lighting_camera, light
):
    from mincam_render.render.transport import render_transport

    lighting_family.apply_state(lighting_scene, IndoorState(lights_on=_only(None)))
    dark = render_transport(lighting_scene, lighting_camera, spp=4, seed=0)
    labels = lighting_family.apply_state(lighting_scene, IndoorState(lights_on=_only(light)))
    np.testing.assert_array_equal(labels["lights"], np.array(_only(light), dtype=np.float32))
    lit = render_transport(lighting_scene, lighting_camera, spp=4, seed=0)
    assert dark.sum() == 0.0  # no window by default: all off is black
    assert lit.sum() > 0.0
    # the camera looks north: west lamps light the left half (col 0 = left) more
    half = lit.shape[2] // 2
    left, right = lit[:, :, :half].sum(), lit[:, :, half:].sum()
    if NAMES[light] in ("lamp_southwest", "lamp_west"):
        assert left > 1.2 * right
    elif NAMES[light] == "lamp_southeast":
        assert right > 1.2 * left


def test_labels_follow_the_switching_process(lighting_family, lighting_scene):
    on = lighting_family.lights_on
    assert on.shape == (NUM_FRAMES, 5)
    for i in (0, 37, NUM_FRAMES - 1):
        np.testing.assert_array_equal(
            lighting_family.set_frame(lighting_scene, i)["lights"], on[i].astype(np.float32)
        )
    # mean on/off durations of tens of seconds: at most a few switches in 4 s
    assert np.abs(np.diff(on.astype(int), axis=0)).sum() <= 10


def test_switching_statistics():
    from mincam_render.scenes.indoor import switching_process

    rng = np.random.default_rng(0)
    s = switching_process(rng, 300_000, 30.0, mean_on_s=30.0, mean_off_s=10.0)
    # stationary on-fraction 30 / (30 + 10); ~250 cycles, so a few percent spread
    assert abs(s.mean() - 0.75) < 0.06


def test_deterministic_and_continuous(lighting_family):
    other = _family()
    np.testing.assert_array_equal(lighting_family.lights_on, other.lights_on)
    np.testing.assert_array_equal(lighting_family.track.pose, other.track.pose)
    tr = lighting_family.track
    same = tr.active[1:] & tr.active[:-1] & (tr.visit[1:] == tr.visit[:-1])
    step = np.linalg.norm(tr.pose[1:, :, :2] - tr.pose[:-1, :, :2], axis=-1)
    assert np.all(
        step[same] <= lighting_family.config.people.walk_speed_m_s[1] / lighting_family.fps + 1e-9
    )
    assert not np.array_equal(
        lighting_family.lights_on, _family(seed=6).lights_on
    ) or not np.array_equal(lighting_family.track.pose, _family(seed=6).track.pose)


def _write(tmp_path, text):
    path = tmp_path / "bad.toml"
    path.write_text('family = "lighting"\n' + text)
    return path


LAMP = "[[floor_lamps]]\nname = 'a'\nposition_m = [{x}, {y}]\n"


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("brightness = 1\n", "brightness"),
        ("max_people = 40\n", "max_people"),
        ("max_depth = 'three'\n", "max_depth"),
        (LAMP.format(x=3.5, y=4.0), "floor_lamps[0]"),  # in plain view
        (LAMP.format(x=7.5, y=1.0), "floor_lamps[0].position_m"),  # outside the room
        (
            "[[floor_lamps]]\nname = 'a'\nposition_m = [0.5, 0.5]\nlumens = -3.0\n",
            "floor_lamps[0].lumens",
        ),
    ],
)
def test_bad_descriptions_are_rejected(tmp_path, text, field):
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_family(path, seed=0, num_frames=1)
    assert str(path) in str(err.value)
    assert field in str(err.value)
