"""The self-powered budget of a scene: panel light over a day, frame rates, hours of operation.

:func:`run` renders the panel's light in each family's scene
(:mod:`.panel`), turns it into power at the capacitor, and for ``K = 1 ..
max_pixels`` freeform pixels reports the sustainable frame rate through the day,
the hours the camera runs at the configured frame rate (a two-day storage
simulation, the second day reported, so the capacitor's state at midnight is the
day's own), and the panel illuminance below which ``max_pixels`` pixels cannot
run at that rate. A conventional module at matched task error (:mod:`.matching`)
is put through the same budget.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.config import to_dict
from mincam_render.core.photometry import WHITE_LIGHT_EFFICACY_LM_PER_W, irradiance_to_lux
from mincam_render.studies.energy.config import ConsumptionConfig, EnergyConfig
from mincam_render.studies.energy.consumption import (
    FrameBudget,
    head_flops,
    mincam_frame_budget,
    module_frame_budget,
    paper_head,
)
from mincam_render.studies.energy.matching import Match, load_match
from mincam_render.studies.energy.panel import (
    PanelLight,
    PanelPose,
    day_irradiance,
    render_panel_light,
)
from mincam_render.studies.energy.result import (
    BudgetRecord,
    ComparedBudget,
    Comparison,
    EnergyResult,
    Estimate,
    FamilyBudget,
    RenderStats,
    StorageDay,
    Threshold,
)
from mincam_render.studies.energy.storage import simulate_storage

if TYPE_CHECKING:
    from mincam_render.core.labels import LabelSpec
    from mincam_render.render.irradiance import IrradianceEstimate
    from mincam_render.scenes.indoor import IndoorFamily

log = logging.getLogger(__name__)
#: Days simulated; the last is reported (the first charges the capacitor from its initial state).
SIMULATED_DAYS = 2


def threshold_lux(budget: FrameBudget, fps: float, config: EnergyConfig) -> float:
    r"""Panel illuminance (lx) whose harvest equals the load at ``fps`` plus leakage at V_max.

    .. math:: E_v = \frac{P_{load}(f) / \eta_{conv} + V_{max}^2 / R_{leak}}{A \, \eta}

    with :math:`\eta` = panel efficiency x mismatch x MPPT, converted to lux with
    the scenes' luminous efficacy of visible-band white light.
    """
    s = config.storage
    leak_w = s.max_voltage_v**2 / s.leakage_resistance_ohm
    need_w = budget.power_w(fps) / s.converter_efficiency + leak_w
    return float(
        irradiance_to_lux(need_w / (config.panel.area_m2 * config.panel.electrical_efficiency))
    )


def harvest_w(irradiance_w_m2: np.ndarray, config: EnergyConfig) -> np.ndarray:
    """Power into the capacitor (W) from panel irradiance (W/m^2, visible band)."""
    return np.asarray(irradiance_w_m2) * config.panel.area_m2 * config.panel.electrical_efficiency


def available_w(harvest: np.ndarray, config: EnergyConfig) -> np.ndarray:
    """Power at the load's rail that ``harvest`` (W) sustains: minus leakage at V_max, converted."""
    s = config.storage
    leak_w = s.max_voltage_v**2 / s.leakage_resistance_ohm
    return np.maximum(np.asarray(harvest) - leak_w, 0.0) * s.converter_efficiency


def mincam_budget(pixels: int, labels: Sequence[LabelSpec], config: EnergyConfig) -> FrameBudget:
    """Frame budget of ``pixels`` freeform pixels with the paper's head for ``labels``."""
    head = paper_head(pixels, labels)
    return mincam_frame_budget(
        config.consumption,
        pixels=pixels,
        flops=head_flops(head),
        outputs=head.out.out_features,
    )


def module_budget(
    match: Match, labels: Sequence[LabelSpec], config: EnergyConfig, consumption: ConsumptionConfig
) -> FrameBudget:
    """The conventional module's frame budget at the matched grid with ``consumption``'s policy."""
    rows, cols = match.grid
    head = paper_head(rows * cols, labels)
    return module_frame_budget(
        consumption,
        config.camera_module,
        grid=match.grid,
        flops=head_flops(head),
        outputs=head.out.out_features,
    )


def _day_run(
    light: PanelLight, budget: FrameBudget, config: EnergyConfig
) -> tuple[float, StorageDay]:
    """Hours running at ``config.fps`` on the last simulated day, and its storage trace."""
    dt = config.schedule.simulation_step_s
    steps = round(SIMULATED_DAYS * 86400.0 / dt)
    hours = (np.arange(steps) + 0.5) * dt / 3600.0
    harvest = harvest_w(day_irradiance(light, config.schedule, hours), config)
    trace = simulate_storage(
        harvest, dt_s=dt, load_w=budget.power_w(config.fps), storage=config.storage
    )
    last = slice(steps - round(86400.0 / dt), steps)
    every = max(1, round(config.schedule.step_min * 60.0 / dt))
    stored = trace.stored_j[last.start : last.stop + 1 : every]
    ran = float(np.sum(trace.running[last]) * dt / 3600.0)
    return ran, StorageDay(
        hours=tuple((np.arange(len(stored)) * every * dt / 3600.0).tolist()),
        voltage_v=tuple(trace.voltage_v[last.start : last.stop + 1 : every].tolist()),
        stored_j=tuple(stored.tolist()),
        balance_j=trace.balance_j(),
        harvested_j=trace.harvested_j,
        consumed_j=trace.consumed_j,
        leaked_j=trace.leaked_j,
        spilled_j=trace.spilled_j,
    )


def family_budget(
    light: PanelLight, pose: PanelPose, budgets: list[FrameBudget], config: EnergyConfig
) -> FamilyBudget:
    """Lux, power, frame rates and budgets of one rendered family over the day."""
    hours = light.hours
    irradiance = day_irradiance(light, config.schedule, hours)
    harvest = harvest_w(irradiance, config)
    avail = available_w(harvest, config)
    runs = [_day_run(light, b, config) for b in budgets]
    mean_avail = float(np.mean(available_w(harvest, config)))
    return FamilyBudget(
        hours=tuple(hours.tolist()),
        irradiance_w_m2=tuple(irradiance.tolist()),
        lux=tuple((irradiance * WHITE_LIGHT_EFFICACY_LM_PER_W).tolist()),
        harvest_w=tuple(harvest.tolist()),
        sustainable_fps={
            b.pixels: tuple(b.sustainable_fps(float(a)) for a in avail) for b in budgets
        },
        hours_at_fps={b.pixels: r[0] for b, r in zip(budgets, runs, strict=True)},
        day_mean_sustainable_fps={b.pixels: b.sustainable_fps(mean_avail) for b in budgets},
        storage_trace=runs[-1][1],
        lights_w_m2={n: _estimate(e) for n, e in light.lights.items()},
        daylight_w_m2=tuple(None if d is None else _estimate(d) for d in light.daylight),
        render=RenderStats(
            seconds=light.seconds,
            spp=config.render.spp * config.render.batches,
            max_depth=config.render.max_depth,
            max_relative_error_component=light.max_relative_error(),
            max_relative_error_total=light.max_relative_error_total(config.schedule),
        ),
        panel=pose,
        panel_area_m2=config.panel.area_m2,
        budgets=tuple(budget_record(b, config) for b in budgets),
    )


def _estimate(e: IrradianceEstimate) -> Estimate:
    return Estimate(mean_w_m2=e.mean_w_m2, stderr_w_m2=e.stderr_w_m2)


def budget_record(budget: FrameBudget, config: EnergyConfig) -> BudgetRecord:
    """A frame budget with its power and threshold illuminance at ``config.fps``."""
    return BudgetRecord(
        pixels=budget.pixels,
        energy_per_frame_j=budget.energy_per_frame_j,
        wake_j=budget.wake_j,
        readout_j=budget.readout_j,
        compute_j=budget.compute_j,
        radio_j=budget.radio_j,
        static_w=budget.static_w,
        payload_bytes=budget.payload_bytes,
        packets=budget.packets,
        head_flops=budget.head_flops,
        max_fps=budget.max_fps,
        power_at_fps_w=budget.power_w(config.fps),
        threshold_lux=threshold_lux(budget, config.fps, config),
    )


def _comparison(
    match: Match, labels: Sequence[LabelSpec], config: EnergyConfig, light: PanelLight | None
) -> Comparison:
    """The minimalist design and its matched module side by side."""
    mincam = mincam_budget(match.pixels, labels, config)
    # the module as configured, and at its best: the head on the MCU, outputs alone sent
    best = replace(config.consumption, head_on_device=True, send_samples=False)
    module = module_budget(match, labels, config, config.consumption)
    outputs_only = module_budget(match, labels, config, best)

    def hours(budget: FrameBudget) -> float | None:
        return None if light is None else _day_run(light, budget, config)[0]

    def compared(budget: FrameBudget) -> ComparedBudget:
        return ComparedBudget(
            budget=budget_record(budget, config),
            name=config.camera_module.name,
            power_ratio=budget.power_w(config.fps) / mincam.power_w(config.fps),
            hours_at_fps=hours(budget),
        )

    return Comparison(
        match=match,
        mincam=ComparedBudget(budget=budget_record(mincam, config), hours_at_fps=hours(mincam)),
        module=compared(module),
        module_outputs_only=compared(outputs_only),
    )


def run(
    config: EnergyConfig,
    out: str | Path,
    *,
    families: Sequence[str],
    studies_dir: str | Path | None = None,
) -> EnergyResult:
    """The self-powered budget of ``families`` (the study's entry; :func:`.report.write_report`).

    ``families`` and ``studies_dir`` are arguments, not fields of ``config``:
    the description is everything the budget needs besides the scenes (it is
    ``energy.json``'s ``config``, and ``scenes/energy.toml`` holds it), while
    the scenes and the study tables are the inputs it is applied to, as the
    robustness study takes its runs.

    Args:
        config: panel, storage, electronics, schedule and render settings.
        out: the study's directory: each family's rendered panel light is kept
            in ``out/panel_light/<family>.json`` as soon as it is rendered (a killed
            study run again renders only the families it had not finished), and
            :func:`.report.write_report` writes there; a refused input leaves no
            directory behind.
        families: indoor scene families (names or TOML paths) to render the day in
            (at least one).
        studies_dir: directory of ``study_<family>.json`` tables for the matched
            baseline (the paper's matches where a table is missing); the other
            families with a table there are compared too, without a day. None:
            the paper's matches only.

    Returns:
        ``config``; ``threshold`` (the first family's frame budget of ``max_pixels``
        and its threshold illuminance beside the paper's); ``families`` (per
        family: the panel's pose, lux and harvest over the day, the frame budgets
        of 1..max_pixels, sustainable fps per pixel count, hours at ``fps``, the
        storage trace, the render's error); ``comparisons`` (per family: the
        matched module's budget beside the minimalist camera's).

    Raises:
        ValueError: no family, an unknown or non-indoor family, or a malformed
            study table.
    """
    from mincam_render.studies.energy.panel import day_family

    if not families:
        raise ValueError("families is empty: name at least one indoor scene family")
    days: dict[str, FamilyBudget] = {}
    comparisons: dict[str, Comparison] = {}
    for name in families:
        fam = day_family(name, config)
        pose, light = _kept_or_rendered(fam, config, Path(out) / "panel_light")
        budgets = [mincam_budget(k, fam.labels, config) for k in range(1, config.max_pixels + 1)]
        days[fam.name] = family_budget(light, pose, budgets, config)
        study = Path(studies_dir) / f"study_{fam.name}.json" if studies_dir else None
        match = load_match(fam.name, study)
        comparisons[fam.name] = _comparison(match, fam.labels, config, light)
    comparisons |= _tabled_comparisons(studies_dir, set(comparisons), config)
    first = next(iter(days))
    threshold = Threshold(
        budget=days[first].budgets[-1], family=first, paper_lux=config.paper_threshold_lux
    )
    return EnergyResult(config=config, families=days, comparisons=comparisons, threshold=threshold)


def _kept_or_rendered(
    fam: IndoorFamily, config: EnergyConfig, kept_dir: Path
) -> tuple[PanelPose, PanelLight]:
    """The panel's pose and light kept in ``kept_dir`` for this description, or rendered and kept.

    The render is the study's long step (minutes per family at the shipped
    sizes); keeping each family's as soon as it is done means a killed study run
    again with the same description renders only the families it had not
    finished. A kept light of another description (or scene) is rendered again.
    """
    from mincam_render.data.dataset import atomic_write_bytes, json_bytes

    path = kept_dir / f"{fam.name}.json"
    key = {"family": fam.name, "scene": to_dict(fam.config), "config": to_dict(config)}
    if path.is_file():
        record = json.loads(path.read_text())
        if {k: record.get(k) for k in key} == json.loads(json_bytes(key)):
            log.info("%s: the panel's light read back from %s", fam.name, path)
            return PanelPose.from_json(record["pose"]), PanelLight.from_json(record["light"])
        log.info("%s: %s holds another description's light; rendering again", fam.name, path)
    pose, light = render_panel_light(fam, config)
    kept_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, json_bytes(key | {"pose": pose.as_json(), "light": light.as_json()}))
    return pose, light


def _tabled_comparisons(
    studies_dir: str | Path | None, done: set[str], config: EnergyConfig
) -> dict[str, Comparison]:
    """Comparisons of the shipped families with a study table in ``studies_dir``, not in ``done``.

    Their day is not rendered (no hours at the frame rate).
    """
    from mincam_render.scenes.registry import FAMILY_NAMES, load_family

    out: dict[str, Comparison] = {}
    for path in sorted(Path(studies_dir).glob("study_*.json")) if studies_dir else []:
        other = path.stem.removeprefix("study_")
        if other in FAMILY_NAMES and other not in done:
            labels = load_family(other, seed=0, num_frames=1).labels
            out[other] = _comparison(load_match(other, path), labels, config, None)
    return out
