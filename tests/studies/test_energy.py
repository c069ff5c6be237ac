"""Self-powered budget: storage bookkeeping, closed forms, the irradiance meter, bad inputs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mincam_render.core.config import ConfigError
from mincam_render.core.photometry import lux_to_irradiance
from mincam_render.studies.energy import (
    EnergyConfig,
    PanelConfig,
    StorageConfig,
    load_energy_config,
    simulate_storage,
    threshold_lux,
)
from mincam_render.studies.energy.config import (
    ConsumptionConfig,
    LightSchedule,
    ScheduleConfig,
)
from mincam_render.studies.energy.consumption import (
    FrameBudget,
    head_flops,
    mincam_frame_budget,
    radio_cost,
)
from mincam_render.studies.energy.matching import PAPER_MATCHES, load_match, match_from_study
from mincam_render.studies.energy.panel import PanelLight, day_irradiance, lights_on

LOSSLESS = StorageConfig(
    capacitance_f=0.1,
    max_voltage_v=3.3,
    brownout_voltage_v=1.8,
    restart_voltage_v=1.8,
    initial_voltage_v=1.0,
    leakage_current_a=0.0,
    converter_efficiency=1.0,
)


# -- storage: every joule booked, and the closed forms


def test_energy_is_conserved_through_brownouts_spills_and_leakage(rng):
    """Harvested = stored change + consumed + leaked + spilled, over a day with dark spells."""
    harvest = rng.uniform(0, 4e-3, size=1440) * (rng.uniform(size=1440) > 0.3)
    harvest[300:500] = 0.0  # a dark spell: the load browns out, then restarts
    harvest[900:1000] = 0.05  # a bright spell: the capacitor fills and spills
    storage = StorageConfig(capacitance_f=0.088, leakage_current_a=20e-6)
    trace = simulate_storage(harvest, dt_s=60.0, load_w=1.5e-3, storage=storage)
    assert abs(trace.balance_j()) <= 1e-12 * trace.harvested_j
    assert trace.spilled_j > 0 and trace.leaked_j > 0 and trace.consumed_j > 0
    assert trace.running.min() == 0.0 and trace.running.max() == 1.0
    assert np.all(trace.voltage_v <= storage.max_voltage_v * (1 + 1e-12))


def test_charge_time_at_constant_power_matches_closed_form():
    """No leakage, no load: C (V1^2 - V0^2) / (2 P) to reach V1 from V0."""
    power_w, dt_s = 1e-3, 1.0
    trace = simulate_storage(np.full(2000, power_w), dt_s=dt_s, load_w=0.0, storage=LOSSLESS)
    v0, v1 = LOSSLESS.initial_voltage_v, 3.0
    expected_s = LOSSLESS.capacitance_f * (v1**2 - v0**2) / (2 * power_w)
    # energy is linear in time between steps: interpolate the crossing
    reached_s = np.interp(0.5 * LOSSLESS.capacitance_f * v1**2, trace.stored_j, trace.time_s)
    assert reached_s == pytest.approx(expected_s, rel=1e-12)
    # then full: everything after the cap reaches V_max is spilled
    full_s = LOSSLESS.capacitance_f * (3.3**2 - v0**2) / (2 * power_w)
    assert trace.spilled_j == pytest.approx(power_w * (2000 * dt_s - full_s), rel=1e-9)


def _budget(energy_j: float, static_w: float) -> FrameBudget:
    return FrameBudget(
        pixels=24,
        wake_j=0.0,
        readout_j=energy_j,
        compute_j=0.0,
        radio_j=0.0,
        static_w=static_w,
        active_s=1e-4,
        payload_bytes=48,
        packets=1,
        head_flops=0,
    )


def test_sustainable_rate_under_constant_light_is_harvest_over_frame_energy():
    """Constant light, no leakage, lossless: fps = (P - P_static) / E_frame, and at that rate
    the capacitor holds its charge exactly; 1 % faster it browns out, 1 % slower it fills."""
    harvest_w, budget = 0.9e-3, _budget(25e-6, 30e-6)
    fps = budget.sustainable_fps(harvest_w)
    assert fps == pytest.approx((harvest_w - 30e-6) / 25e-6, rel=1e-15)
    start = dataclasses.replace(LOSSLESS, initial_voltage_v=2.5)
    hold = simulate_storage(
        np.full(600, harvest_w), dt_s=60.0, load_w=budget.power_w(fps), storage=start
    )
    np.testing.assert_allclose(hold.voltage_v, 2.5, rtol=1e-12)
    assert hold.hours_running == pytest.approx(10.0, rel=1e-12)
    fast = simulate_storage(
        np.full(6000, harvest_w), dt_s=60.0, load_w=budget.power_w(1.01 * fps), storage=start
    )
    assert fast.running.min() < 1.0
    slow = simulate_storage(
        np.full(6000, harvest_w), dt_s=60.0, load_w=budget.power_w(0.99 * fps), storage=start
    )
    assert slow.running.min() == 1.0 and slow.voltage_v[-1] == pytest.approx(3.3)


def test_threshold_lux_pays_exactly_for_the_load_and_leakage():
    cfg = EnergyConfig()
    budget = _budget(27e-6, 35e-6)
    lux = threshold_lux(budget, 30.0, cfg)
    harvest = lux_to_irradiance(lux) * cfg.panel.area_m2 * cfg.panel.electrical_efficiency
    s = cfg.storage
    leak = s.max_voltage_v**2 / s.leakage_resistance_ohm
    assert (harvest - leak) * s.converter_efficiency == pytest.approx(budget.power_w(30.0))


def test_usable_energy_between_max_and_brownout():
    s = StorageConfig(capacitance_f=0.088, max_voltage_v=3.3, brownout_voltage_v=1.8)
    assert s.usable_energy_j == pytest.approx(0.5 * 0.088 * (3.3**2 - 1.8**2))


# -- consumption


def test_head_flops_of_the_paper_head():
    from mincam_render.core.labels import LabelKind, LabelSpec
    from mincam_render.learn.models import Head

    labels = [LabelSpec(name="count", kind=LabelKind.COUNT)]
    head = Head(24, labels)
    linear = 2 * (24 * 128 + 128 * 128 + 128 * 1) + (128 + 128 + 1)
    assert head_flops(head) == linear + 2 * 128 + 2 * 24  # + leaky ReLUs + standardisation


def test_radio_cost_splits_payload_into_packets():
    c = ConsumptionConfig()
    e1, n1, t1 = radio_cost(244, c)
    e2, n2, t2 = radio_cost(245, c)
    assert (n1, n2) == (1, 2)
    tx_s = 8 * (245 + 2 * 17) / 1e6
    expected = 3.0 * (5.2e-3 * tx_s + 4.5e-3 * 2 * 230e-6 + 64e6 * 53e-12 * 0.4e-3)
    assert e2 == pytest.approx(expected, rel=1e-12)
    assert t2 == pytest.approx(tx_s + 2 * 230e-6 + 0.4e-3, rel=1e-12)
    assert radio_cost(0, c) == (0.0, 0, 0.0)


def test_frame_energy_grows_with_pixels_and_static_power_with_amplifiers():
    c = ConsumptionConfig()
    b8 = mincam_frame_budget(c, pixels=8, flops=1000, outputs=1)
    b24 = mincam_frame_budget(c, pixels=24, flops=1000, outputs=1)
    assert b24.readout_j == pytest.approx(3 * b8.readout_j)
    assert b24.static_w - b8.static_w == pytest.approx(3.0 * 16 * 350e-9)
    assert b24.payload_bytes == 24 * 2 + 4


# -- matching a conventional grid from a study table


def _study(errors: dict[str, tuple[float, float, float]]) -> dict:
    designs = {}
    for name, (mean, lo, hi) in errors.items():
        if name.startswith("mincam"):
            model = {"kind": "mincam", "pixels": int(name.split("-")[1][:-2])}
        else:
            r, c = name.split("-")[1].split("x")
            model = {"kind": "baseline", "grid": [int(r), int(c)]}
        designs[name] = {"model": model, "error": {"mean": mean, "ci95": [lo, hi]}}
    return {"task": "patches", "error_name": "count RMSE", "designs": designs}


def test_match_is_the_coarsest_grid_within_the_reference_interval():
    study = _study(
        {
            "mincam-2px": (1.8, 1.7, 1.9),
            "mincam-4px": (1.5, 1.45, 1.56),
            "baseline-2x2": (1.7, 1.6, 1.8),
            "baseline-4x4": (1.55, 1.5, 1.6),
            "baseline-8x8": (1.4, 1.3, 1.5),
        }
    )
    m = match_from_study(study, "t.json")
    assert (m.pixels, m.grid, m.matched) == (4, (4, 4), True)
    worse = _study({"mincam-4px": (1.0, 0.9, 1.1), "baseline-8x8": (1.4, 1.3, 1.5)})
    none = match_from_study(worse, "t.json")
    assert none.grid == (8, 8) and not none.matched


def test_paper_match_without_a_study(tmp_path):
    m = load_match("workspace", tmp_path / "missing.json")
    assert (m.pixels, m.grid) == PAPER_MATCHES["workspace"]
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(ValueError, match="bad.json"):
        load_match("workspace", tmp_path / "bad.json")


# -- the day: schedule and linearity in the lights


def _light(day: list[float | None]) -> PanelLight:
    from mincam_render.render.irradiance import IrradianceEstimate

    est = [
        None if v is None else IrradianceEstimate(mean_w_m2=v, stderr_w_m2=0.0, spp=1) for v in day
    ]
    lamp = IrradianceEstimate(mean_w_m2=1.0, stderr_w_m2=0.0, spp=1)
    return PanelLight(lights={"lamp": lamp}, hours=np.arange(24.0), daylight=tuple(est), seconds=0)


def test_day_irradiance_adds_scheduled_lights_to_interpolated_daylight():
    day = [None] * 6 + [float(h - 5) for h in range(6, 18)] + [None] * 6
    light = _light(day)
    office = ScheduleConfig(lights_on_hour=8.0, lights_off_hour=18.0)
    e = day_irradiance(light, office, np.array([3.0, 7.5, 12.0, 18.0]))
    np.testing.assert_allclose(e, [0.0, 2.5 + 0.0, 7.0 + 1.0, 0.0])
    night = ScheduleConfig(lights=(LightSchedule(name="lamp", on_hour=22.0, off_hour=2.0),))
    np.testing.assert_array_equal(
        lights_on(night, "lamp", np.array([21.9, 23.0, 1.0, 2.0])), [False, True, True, False]
    )


# -- the irradiance meter against closed forms


def _meter(center, normal, side_m=1e-3):
    from mincam_render.render.mitsuba_scene import irradiance_meter

    tangent = [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0]
    return irradiance_meter(center, normal, tangent, (side_m, side_m))


@pytest.mark.parametrize("tilt_deg", [0.0, 35.0, 60.0])
def test_meter_under_a_small_lamp_reads_intensity_cos_over_d2(variant, tilt_deg):
    """A spherical lamp (radius r, radiance L) at distance d: intensity I = L pi r^2 and
    E = I cos(theta) / d^2, exact while the sphere is wholly above the panel's horizon.

    Monte Carlo (the meter's rays hit the lamp with probability (r/d)^2 cos(theta)): the
    estimate must lie within 4 of its own measured standard errors, and that error be < 1 %.
    """
    import mitsuba as mi

    from mincam_render.render.irradiance import measure_irradiance

    radiance, r, d = 3.0, 0.3, 1.5
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": 2},
            "lamp": {
                "type": "sphere",
                "center": [0, 0, d],
                "radius": r,
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": radiance}},
            },
        }
    )
    t = math.radians(tilt_deg)
    meter = _meter([0, 0, 0], [math.sin(t), 0, math.cos(t)])
    est = measure_irradiance(scene, meter, spp=1 << 17, batches=8, seed=tilt_deg.__hash__() % 97)
    expected = radiance * math.pi * r**2 * math.cos(t) / d**2
    assert est.relative_error < 0.01
    assert abs(est.mean_w_m2 - expected) < 4 * est.stderr_w_m2, (est, expected)


def test_meter_under_a_uniform_sky_reads_pi_radiance(variant):
    import mitsuba as mi

    from mincam_render.render.irradiance import measure_irradiance

    radiance = 2.0
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": 2},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": radiance}},
        }
    )
    est = measure_irradiance(scene, _meter([0, 0, 0], [0.3, -0.2, 0.9], side_m=0.1), spp=256)
    assert est.mean_w_m2 == pytest.approx(math.pi * radiance, rel=1e-5)
    assert est.spp == 256 * 8


# -- bad inputs: rejected, naming the field


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda: PanelConfig(area_m2=-1.0), "area_m2"),
        (lambda: PanelConfig(efficiency=1.2), "efficiency"),
        (lambda: PanelConfig(mppt_efficiency=0.0), "mppt_efficiency"),
        (lambda: StorageConfig(brownout_voltage_v=3.5), "brownout_voltage_v"),
        (lambda: StorageConfig(restart_voltage_v=1.5), "restart_voltage_v"),
        (lambda: StorageConfig(capacitance_f=0.0), "capacitance_f"),
        (lambda: StorageConfig(leakage_current_a=-1e-6), "leakage_current_a"),
        (lambda: ConsumptionConfig(head_on_device=False, send_samples=False), "nothing is sent"),
        (lambda: ScheduleConfig(step_min=7.0), "step_min"),
        (lambda: LightSchedule(name="x", on_hour=25.0, off_hour=2.0), "on_hour"),
    ],
)
def test_bad_values_are_rejected_naming_the_field(build, field):
    with pytest.raises(ValueError, match=field):
        build()


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("[panel]\nefficiency = 1.5\n", "panel.efficiency"),
        ("[storage]\nbrownout_voltage_v = 4.0\n", "brownout_voltage_v"),
        ("[panel]\ncolour = 1\n", "panel.colour"),
        ("[render]\nspp = 'many'\n", "render.spp"),
        ("fps = -30.0\n", "fps"),
    ],
)
def test_bad_descriptions_are_rejected_naming_file_and_field(tmp_path, text, field):
    path = tmp_path / "energy.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_energy_config(path)
    assert str(path) in str(err.value) and field in str(err.value)


def test_shipped_description_equals_the_defaults():
    """scenes/energy.toml repeats every default: editing one without the other is a bug."""
    assert load_energy_config() == EnergyConfig()


def test_simulation_rejects_negative_harvest_and_time_step():
    with pytest.raises(ValueError, match="harvest_w"):
        simulate_storage(np.array([1e-3, -1e-3]), dt_s=1.0, load_w=0.0, storage=LOSSLESS)
    with pytest.raises(ValueError, match="dt_s"):
        simulate_storage(np.array([1e-3]), dt_s=0.0, load_w=0.0, storage=LOSSLESS)
    with pytest.raises(ValueError, match="pixels"):
        mincam_frame_budget(ConsumptionConfig(), pixels=0, flops=0, outputs=1)


def test_importing_the_package_loads_neither_torch_nor_mitsuba():
    import subprocess
    import sys

    code = (
        "import sys, mincam_render.studies.energy; "
        "print(sorted(m for m in ('torch', 'mitsuba', 'drjit') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_a_schedule_naming_an_unknown_light_is_rejected():
    from mincam_render.studies.energy.panel import check_light_names

    schedule = ScheduleConfig(
        lights=(LightSchedule(name="lamp_wset", on_hour=17.0, off_hour=23.0),)
    )
    with pytest.raises(ValueError, match=r"schedule.lights\[0\].name = 'lamp_wset'.*lamp_west"):
        check_light_names(schedule, ["overhead_south", "lamp_west"])
    check_light_names(schedule, ["lamp_wset"])  # a known name passes


@pytest.mark.parametrize("families", [[], ()])
def test_run_without_a_family_is_refused_naming_the_argument(tmp_path, families):
    from mincam_render.studies.energy import run

    with pytest.raises(ValueError, match="families is empty"):
        run(EnergyConfig(), tmp_path / "out", families=families)
    assert not (tmp_path / "out").exists()


def test_a_killed_study_reads_each_rendered_family_back_instead_of_rendering_it(
    variant, tmp_path, monkeypatch
):
    import mincam_render.studies.energy.study as study
    from mincam_render.studies.energy import load_energy_config, run

    small = {"max_pixels": 2, "schedule": {"step_min": 120.0}, "render": {"spp": 8, "batches": 2,
             "max_depth": 2}}  # fmt: skip
    config = load_energy_config(None, small)
    first = run(config, tmp_path, families=["workspace"])
    kept = tmp_path / "panel_light" / "workspace.json"
    assert kept.is_file()

    def rendered(*args, **kwargs):
        raise AssertionError("rendered again")

    monkeypatch.setattr(study, "render_panel_light", rendered)
    again = run(config, tmp_path, families=["workspace"])  # read back: the same day
    assert again.as_json() == first.as_json()
    other = load_energy_config(None, small | {"render": {"spp": 16, "batches": 2, "max_depth": 2}})
    with pytest.raises(AssertionError, match="rendered again"):  # another description
        run(other, tmp_path, families=["workspace"])


def test_a_read_back_description_is_refused_naming_the_field():
    """``EnergyResult.from_json`` checks the description it reads as a file's."""
    from mincam_render.studies.energy import EnergyResult

    record = {"config": {"panel": {"area_m2": -1.0}}, "families": {}, "comparisons": {}}
    with pytest.raises(ConfigError, match="panel.area_m2"):
        EnergyResult.from_json(record | {"threshold": {}})


def test_depth_check_holds_each_component_against_the_deepest(variant):
    """The benchmark's depth check: per depth and component, the irradiance against the deepest."""
    from mincam_render.studies.energy.panel import depth_check

    cfg = load_energy_config(None, {"render": {"spp": 16, "batches": 2}})
    check = depth_check("workspace", cfg, (2, 3))
    assert check.family == "workspace"
    assert [r.depth for r in check.rows] == [2, 2, 3, 3]  # a light alone, noon daylight
    assert check.rows[0].component.startswith("light=")
    assert check.rows[1].component == "daylight_s=43200"
    for row, deepest in zip(check.rows[:2], check.rows[2:], strict=True):
        assert row.relative_to_deepest == row.irradiance_w_m2 / deepest.irradiance_w_m2 - 1.0
        assert deepest.relative_to_deepest == 0.0 and row.stderr_w_m2 > 0
    assert list(check.as_json()["rows"][0]) == [
        "depth",
        "component",
        "irradiance_w_m2",
        "stderr_w_m2",
        "relative_to_deepest",
    ]
