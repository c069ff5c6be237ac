"""Traffic family: labels from geometry, SUMO determinism and continuity, descriptions, renders."""

from __future__ import annotations

import math
import sys

import mitsuba as mi
import numpy as np
import pytest

from mincam_render import DetectorLayout, FreeformCamera, render_transport
from mincam_render.core.config import ConfigError, parse
from mincam_render.core.photometry import irradiance_to_lux
from mincam_render.scenes import load_family, sky
from mincam_render.scenes.sumo import SUMO_MAX_SEED, MissingTrafficExtraError, sumo_seed
from mincam_render.scenes.traffic import (
    MPH_PER_M_S,
    PARKED_POINT_M,
    SUN_DIRECTION_PARAM,
    TrafficConfig,
    VehicleShape,
    in_view,
    traffic_labels,
    vehicle_body_key,
    vehicle_faces,
    vehicle_trim_key,
    vehicle_vertices,
    vertex_param,
)

CAMERA = TrafficConfig().camera.camera()


def heading(direction: str) -> float:
    """Yaw (rad from +x) of travel to the camera's left or right."""
    right = CAMERA.frame[0]
    sgn = 1.0 if direction == "right" else -1.0
    return math.atan2(sgn * right[1], sgn * right[0])


def centre_of_view(height_m: float = 0.7) -> np.ndarray:
    """A road point on the camera's optical axis, lifted to a vehicle's half height."""
    pos, fwd = np.asarray(CAMERA.position), CAMERA.frame[2]
    t = (height_m - pos[2]) / fwd[2]
    return pos + t * fwd


# ---- labels from explicit states (no SUMO) -----------------------------------------


@pytest.mark.parametrize(("direction", "other"), [("left", "right"), ("right", "left")])
def test_vehicle_at_10_m_s_reads_22_4_mph(direction, other):
    lab = traffic_labels(CAMERA, centre_of_view()[None], [heading(direction)], [10.0])
    np.testing.assert_allclose(lab[f"speed_{direction}_mph"], [22.369], atol=1e-3)
    assert lab[f"speed_{other}_mph"][0] == 0.0
    assert lab[f"count_{direction}"][0] == 1.0 and lab[f"count_{other}"][0] == 0.0
    assert all(v.dtype == np.float32 and v.shape == (1,) for v in lab.values())


def test_default_camera_sees_left_as_minus_x():
    # the camera faces north (+y) from the south sidewalk: -x traffic moves left
    assert heading("left") == pytest.approx(math.pi)


def test_out_of_view_vehicles_do_not_count():
    c = centre_of_view()
    centres = np.array([c, c + [2.0, 0, 0], c + [150.0, 0, 0], [0.0, -30.0, 0.7]])
    yaws = [heading("left"), heading("left"), heading("left"), heading("left")]
    lab = traffic_labels(CAMERA, centres, yaws, [10.0, 20.0, 30.0, 30.0])
    np.testing.assert_allclose(lab["speed_left_mph"], [15.0 * MPH_PER_M_S], rtol=1e-6)
    assert lab["count_left"][0] == 2.0
    assert lab["speed_right_mph"][0] == 0.0 and lab["count_right"][0] == 0.0


def test_stopped_vehicle_counts_at_zero_speed():
    c = centre_of_view()
    lab = traffic_labels(CAMERA, [c, c + [3.0, 0, 0]], [heading("right")] * 2, [0.0, 8.0])
    assert lab["count_right"][0] == 2.0
    np.testing.assert_allclose(lab["speed_right_mph"], [4.0 * MPH_PER_M_S], rtol=1e-6)


def test_no_vehicles_reads_zero():
    lab = traffic_labels(CAMERA, np.zeros((0, 3)), [], [])
    assert all(v[0] == 0.0 for v in lab.values())


def test_in_view_matches_projection_onto_the_mask(rng):
    # one detector at the board centre: in view <=> its ray crosses the mask
    cam = FreeformCamera(
        layout=DetectorLayout(positions_m=((0.0, 0.0),)),
        mask_resolution=(32, 32),
        position=CAMERA.position,
        look_at=CAMERA.look_at,
        up=CAMERA.up,
    )
    pts = rng.uniform([-40, -10, 0], [40, 40, 10], size=(400, 3))
    seen = in_view(cam, pts)
    for p, s in zip(pts, seen, strict=True):
        try:
            r, c = cam.project_to_texel(p, 0)
            expect = 0 <= r <= 32 and 0 <= c <= 32
        except ValueError:  # behind the board
            expect = False
        assert s == expect
    assert 20 < seen.sum() < 380  # the sample exercises both outcomes


@pytest.mark.parametrize("shape", list(VehicleShape))
def test_vehicle_meshes_fit_their_dimensions(shape):
    body_f, trim_f = vehicle_faces()
    body, trim = vehicle_vertices(shape, 5.0, 2.0, 1.6)
    assert body_f.max() + 1 == len(body) and trim_f.max() + 1 == len(trim)
    both = np.concatenate([body, trim])
    assert np.all(np.abs(both[:, 0]) <= 2.5 + 0.021) and np.all(np.abs(both[:, 1]) <= 1.0 + 0.021)
    assert both[:, 2].min() >= 0.0 and both[:, 2].max() == pytest.approx(1.6)


def test_default_daylight_is_tens_of_thousands_of_lux():
    day = sky.daylight(TrafficConfig().daylight, 0.0)
    assert 2e4 < irradiance_to_lux(day.global_horizontal_w_m2) < 1.3e5


# ---- descriptions ----------------------------------------------------------------------


def test_shipped_description_documents_the_defaults():
    import tomllib

    from mincam_render.core.package_data import shipped_path

    table = tomllib.loads(shipped_path("traffic.toml").read_text())
    assert table.pop("family") == "traffic"
    assert parse(TrafficConfig, table, source="traffic.toml") == TrafficConfig()


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("lanes_per_direction = 7", "lanes_per_direction"),
        ("demand_veh_per_h = [-5.0, 100.0]", "demand_veh_per_h[0]"),
        ("lane_widht_m = 3.5", "lane_widht_m"),
        ('fps = "fast"', "fps"),
        ("signal_distance_m = 400.0", "signal_distance_m"),
        ("body_albedo_weights = [1.0]", "body_albedo_weights"),
        ('[[vehicle_types]]\nname = "tank"\nshape = "tank"', "vehicle_types[0].shape"),
        ('[[vehicle_types]]\nname = "a b"\nshape = "bus"', "name"),
        ("[camera]\nposition = [0.0, -3.0, 6.0]\nlook_at = [0.0, 1.0, 0.0]", "camera.position"),
        ("[camera]\nposition = [0.0, -30.0, 6.0]\nlook_at = [0.0, 1.0, 0.0]", "camera.position"),
        ("[daylight]\novercast = 2.0", "daylight.overcast"),
    ],
)
def test_bad_descriptions_name_file_and_field(tmp_path, text, field):
    path = tmp_path / "bad_traffic.toml"
    path.write_text(f'family = "traffic"\n{text}\n')
    with pytest.raises(ConfigError) as err:
        load_family(path, seed=0, num_frames=2)
    msg = str(err.value)
    assert str(path) in msg and field in msg


def test_missing_sumo_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "libsumo", None)  # import libsumo -> ImportError
    with pytest.raises(MissingTrafficExtraError, match=r"pip install 'mincam_render\[traffic\]'"):
        load_family("traffic", seed=0, num_frames=2)


# ---- with SUMO -------------------------------------------------------------------------

SMALL = {
    "warmup_s": 60.0,
    "demand_veh_per_h": [1500.0, 1500.0],
    "max_vehicles": 12,
    "scenery_half_length_m": 70.0,
    "render_half_length_m": 40.0,
    "buildings": False,
    "signal_cycle_s": 0.0,  # free flow, so both directions have traffic in 5 s
}


@pytest.fixture(scope="module")
def traffic_family():
    pytest.importorskip(
        "libsumo", reason="needs Eclipse SUMO: pip install 'mincam_render[traffic]'"
    )
    return load_family("traffic", seed=3, num_frames=150, overrides=SMALL)


def test_same_seed_same_sequence(traffic_family):
    again = load_family("traffic", seed=3, num_frames=150, overrides=SMALL)
    for name in ("step_offsets", "vehicle", "center_m", "yaw_rad", "speed_m_s", "vehicle_type"):
        np.testing.assert_array_equal(
            getattr(traffic_family.trajectories, name), getattr(again.trajectories, name)
        )
    assert traffic_family.frame_state(77) == again.frame_state(77)
    other = load_family("traffic", seed=4, num_frames=150, overrides=SMALL)
    assert len(other.trajectories.center_m) != len(
        traffic_family.trajectories.center_m
    ) or not np.array_equal(other.trajectories.center_m, traffic_family.trajectories.center_m)


def test_a_study_episode_seed_beyond_sumos_int_runs_and_differs_from_others():
    """Episode seeds lie in [0, 2^63); SUMO's --seed is a C int (it refused them)."""
    pytest.importorskip("libsumo", reason="needs Eclipse SUMO")
    assert [sumo_seed(s) for s in (0, 3, SUMO_MAX_SEED)] == [0, 3, SUMO_MAX_SEED]
    big = [sumo_seed(s) for s in (2**62 + 1, 2**62 + 2, 7517301341756292723)]
    assert all(0 <= s <= SUMO_MAX_SEED for s in big) and len(set(big)) == 3
    with pytest.raises(ValueError, match="seed"):
        sumo_seed(-1)
    fam = load_family("traffic", seed=7517301341756292723, num_frames=30, overrides=SMALL)
    assert len(fam.trajectories.center_m) > 0


def test_sequence_has_traffic_both_ways(traffic_family):
    labs = [traffic_family.frame_labels(i) for i in range(0, 150, 10)]
    assert sum(lab["count_left"][0] for lab in labs) > 0
    assert sum(lab["count_right"][0] for lab in labs) > 0


def test_consecutive_frames_move_by_speed_over_fps(traffic_family):
    moved = 0
    for i in range(0, 149, 7):
        a, b = traffic_family.vehicles(i), traffic_family.vehicles(i + 1)
        common, ia, ib = np.intersect1d(a["vehicle"], b["vehicle"], return_indices=True)
        dx = np.abs(b["center_m"][ib, 0] - a["center_m"][ia, 0])
        dy = np.abs(b["center_m"][ib, 1] - a["center_m"][ia, 1])
        mean_speed = 0.5 * (a["speed_m_s"][ia] + b["speed_m_s"][ib])
        # longitudinal step = speed / fps, up to acceleration within the frame
        np.testing.assert_allclose(dx, mean_speed / traffic_family.fps, atol=0.03)
        assert np.all(dy < 0.1)  # lane changes are gradual (2 s)
        moved += int((dx > 0.1).sum())
    assert moved > 0


def test_signals_queue_traffic_at_high_demand():
    pytest.importorskip(
        "libsumo", reason="needs Eclipse SUMO: pip install 'mincam_render[traffic]'"
    )
    over = {**SMALL, "signal_cycle_s": 90.0, "demand_veh_per_h": [1800.0, 1800.0]}
    fam = load_family("traffic", seed=0, num_frames=301, overrides=over)
    speeds = np.concatenate([fam.vehicles(i)["speed_m_s"] for i in range(0, 301, 30)])
    assert (speeds < 1.0).sum() >= 3  # stopped or creeping vehicles within 60 m of the camera
    assert speeds.max() > 10.0


def test_labels_follow_the_state(traffic_family):
    st = traffic_family.frame_state(40)
    seen = [v for v in st["vehicles"] if v["in_view"]]
    assert st["labels"]["count_left"] + st["labels"]["count_right"] == len(seen)
    for side, sgn in (("left", -1.0), ("right", 1.0)):
        speeds = [v["speed_m_s"] for v in seen if sgn * math.cos(v["yaw_rad"]) > 0]
        expect = float(np.mean(speeds)) * MPH_PER_M_S if speeds else 0.0
        assert st["labels"][f"speed_{side}_mph"] == pytest.approx(expect, rel=1e-5, abs=1e-6)


@pytest.fixture(scope="module")
def traffic_scene(traffic_family):
    return traffic_family.build_scene()


def _frame_with_vehicle(traffic_family) -> int:
    return next(
        i
        for i in range(150)
        if traffic_family.frame_labels(i)["count_left"][0]
        + traffic_family.frame_labels(i)["count_right"][0]
        > 0
    )


def test_transport_changes_when_a_vehicle_passes(traffic_family, traffic_scene, tmp_path):
    cam = FreeformCamera(
        layout=DetectorLayout(positions_m=((0.0, 0.0),)),
        mask_resolution=(8, 8),
        position=traffic_family.camera().position,
        look_at=traffic_family.camera().look_at,
        up=traffic_family.camera().up,
    )
    f = _frame_with_vehicle(traffic_family)
    traffic_family.set_frame(traffic_scene, f)
    with_cars = render_transport(traffic_scene, cam, spp=32, seed=1)
    params = mi.traverse(traffic_scene)
    for slot in range(traffic_family.config.max_vehicles):
        for key in (vehicle_body_key(slot), vehicle_trim_key(slot)):
            n = len(params[vertex_param(key)]) // 3
            params[vertex_param(key)] = mi.Float(np.tile(np.float32(PARKED_POINT_M), n))
    params.update()
    empty = render_transport(traffic_scene, cam, spp=32, seed=1)
    traffic_family.set_frame(traffic_scene, f)  # in place again: the same image
    again = render_transport(traffic_scene, cam, spp=32, seed=1)
    diff = np.abs(with_cars - empty)
    if diff.max() <= 0.2 * empty.max():
        np.save(tmp_path / "with_cars.npy", with_cars)
        np.save(tmp_path / "empty.npy", empty)
    assert diff.max() > 0.2 * empty.max()  # a vehicle covers part of the view
    np.testing.assert_allclose(again, with_cars, rtol=1e-4, atol=1e-4 * with_cars.max())


def test_sun_moves_in_time_lapse(traffic_family, traffic_scene):
    fam = load_family(
        "traffic",
        seed=3,
        num_frames=2,
        overrides={**SMALL, "daylight": {"hours_per_second": 1.0}, "daylight_update_s": 0.0},
    )
    fam.set_frame(traffic_scene, 0)
    m0 = np.array(mi.traverse(traffic_scene)[SUN_DIRECTION_PARAM].matrix)
    fam.set_frame(traffic_scene, 1)  # 1/30 s = 2 solar minutes later
    m1 = np.array(mi.traverse(traffic_scene)[SUN_DIRECTION_PARAM].matrix)
    assert not np.allclose(m0, m1)
