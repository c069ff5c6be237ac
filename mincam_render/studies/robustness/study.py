"""How fragile a trained design is: task error under fabrication and detector perturbations.

For a trained minimalist camera and its test episodes, :func:`robustness_curves`
measures, for every term of the
:class:`~mincam_render.optics.perturbation.PerturbationModel` alone and for all
of them at once (``"mix"``), the task error at magnitudes ``levels`` x the
default half-ranges (0 to 2x), each by Monte Carlo over ``draws`` built cameras.
The same draws (seeded by term and level) are used for every design, so
designs are compared on common random numbers; the sensor noise is the fixed
evaluation seed's. An error is pooled over the test episodes as in the main job
(RMSE over all frames, error rates as means).

The figure of a level is the relative error increase over the design's nominal
error, ``error / nominal - 1``, averaged over draws (and over training seeds
when several runs are pooled with :func:`pool_curves`), with a 95 % bootstrap
interval that resamples runs and draws
(:func:`~mincam_render.analysis.statistics.bootstrap_interval`). Beside it, each
level holds the error itself (``mean_error``, ``ci95_error``: each run's nominal
error times one plus its increase), so that a design that loses little because
it learned little is not mistaken for a better built camera. A term's
**tolerance** is the largest magnitude at which the mean increase stays within
``allowed_increase`` (10 %), interpolated linearly between levels; it is
written as a fabrication spec (:func:`fabrication_spec`).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mincam_render.analysis.statistics import (
    EpisodeErrors,
    Interval,
    Pooling,
    bootstrap_interval,
)
from mincam_render.core.seeds import stream_seed
from mincam_render.optics.perturbation import (
    TERM_FIELDS,
    PerturbationModel,
    PerturbationTerm,
    record_name,
)
from mincam_render.studies.robustness.config import CURVES, MIX, RobustnessConfig
from mincam_render.studies.robustness.result import (
    Curve,
    CurveLevel,
    DesignCurves,
    Tolerance,
)

if TYPE_CHECKING:
    from mincam_render.learn.models import MincamCamera
    from mincam_render.learn.training_data import TrainingData
    from mincam_render.optics.perturbation import PerturbationDraw

log = logging.getLogger(__name__)


def curve_model(base: PerturbationModel, curve: str) -> PerturbationModel:
    """The perturbation model of ``curve`` (a term alone, or :data:`MIX`) at level 1."""
    return base if curve == MIX else base.only(PerturbationTerm(curve))


def pooled_error(
    model: MincamCamera, tests: Mapping[str, TrainingData], draw: PerturbationDraw | None
) -> float:
    """The task error over every test episode (RMSE pooled over frames, rates averaged)."""
    from mincam_render.learn.evaluation import evaluate

    return pool_episode_metrics([evaluate(model, d, draw=draw).as_json() for d in tests.values()])


def pool_episode_metrics(res: Sequence[Mapping[str, Any]]) -> float:
    """One error from per-episode metrics (``error``, ``samples``, ``error_name``).

    RMSE is pooled over samples (the root of the sample-weighted mean square);
    rates are sample-weighted means.
    """
    n = np.array([r["samples"] for r in res], np.float64)
    e = np.array([r["error"] for r in res], np.float64)
    if res[0]["error_name"].endswith("RMSE"):
        return float(np.sqrt((e**2) @ n / n.sum()))
    return float(e @ n / n.sum())


def _draws(
    config: RobustnessConfig, curve: str, level_index: int, num_pixels: int
) -> list[PerturbationDraw | None]:
    """The built cameras of one level: one identity (None) at level 0, else ``draws``."""
    scaled = curve_model(config.perturbation, curve).scaled(config.levels[level_index])
    if scaled.is_zero():
        return [None]
    rng = np.random.default_rng(stream_seed(config.seed, f"robustness/{curve}", level_index))
    return [scaled.draw(num_pixels, rng) for _ in range(config.draws)]


def robustness_curves(
    model: MincamCamera,
    tests: Mapping[str, TrainingData],
    config: RobustnessConfig = RobustnessConfig(),  # noqa: B008 (frozen, so shared safely)
    *,
    name: str = "design",
    robust: bool = False,
) -> DesignCurves:
    """Error increase of one trained design under every perturbation term and the mix.

    Args:
        model: the trained minimalist camera (evaluated without training).
        tests: ``{episode: TrainingData}`` test episodes.
        config: levels, draws, seed and the allowed increase.
        name: the design's label in reports.
        robust: whether it was trained under perturbations (for reports).

    Returns:
        The design's curves (see :func:`design_record`) from one run.

    """
    nominal = pooled_error(model, tests, None)
    if not nominal > 0:
        raise ValueError(f"{name}: nominal error {nominal!r} is 0: no increase can be measured")
    increases: dict[str, list[list[float]]] = {}
    for curve in CURVES:
        per_level = []
        for i in range(len(config.levels)):
            errs = [
                pooled_error(model, tests, d)
                for d in _draws(config, curve, i, len(model.detectors))
            ]
            per_level.append([e / nominal - 1.0 for e in errs])
        increases[curve] = per_level
        log.info("%s: %s done", name, curve)
    return design_record(name, robust, [nominal], {c: [v] for c, v in increases.items()}, config)


def design_record(
    name: str,
    robust: bool,
    nominal_errors: Sequence[float],
    increases: Mapping[str, Sequence[Sequence[Sequence[float]]]],
    config: RobustnessConfig,
) -> DesignCurves:
    """The curves of a design from its runs: intervals, tolerances, specs.

    Args:
        name: the design's label.
        robust: trained under perturbations.
        nominal_errors: ``[run]`` nominal task error of each run.
        increases: ``{curve: [run][level][draw]}`` relative error increases.
        config: the measurement's configuration.

    """
    nominal = np.asarray(nominal_errors, np.float64)
    return DesignCurves(
        name=name,
        robust=bool(robust),
        runs=len(nominal_errors),
        nominal_error=float(np.mean(nominal_errors)),
        nominal_errors=tuple(float(e) for e in nominal_errors),
        config=config,
        curves={c: _curve(c, nominal, increases[c], config) for c in CURVES},
    )


def _curve(
    curve: str,
    nominal: np.ndarray,
    increases: Sequence[Sequence[Sequence[float]]],
    config: RobustnessConfig,
) -> Curve:
    """One curve from ``[run][level][draw]`` increases and ``[run]`` nominal errors."""
    levels = []
    for i, level in enumerate(config.levels):
        per_run = np.array([run[i] for run in increases], np.float64)
        ci = _draw_interval(per_run, config.seed)
        absolute = _draw_interval(nominal[:, None] * (1.0 + per_run), config.seed)
        levels.append(
            CurveLevel(
                level=level,
                draws=int(per_run.shape[1]),
                mean_increase=ci.mean,
                ci95_increase=(ci.low, ci.high),
                mean_error=absolute.mean,
                ci95_error=(absolute.low, absolute.high),
                increases=tuple(tuple(run) for run in per_run.tolist()),
            )
        )
    factor, bounded = tolerance(
        config.levels, [v.mean_increase for v in levels], config.allowed_increase
    )
    base = curve_model(config.perturbation, curve).to_record()  # in mm, deg, %, cm
    fields_ = _curve_fields(curve)
    tol = Tolerance(factor=factor, bounded=bounded, values={f: base[f] * factor for f in fields_})
    return Curve(
        default={f: base[f] for f in fields_},
        levels=tuple(levels),
        tolerance=tol,
        spec=fabrication_spec(curve, tol),
    )


def _draw_interval(per_run: np.ndarray, seed: int) -> Interval:
    """Mean and bootstrap interval of ``[run][draw]`` figures (runs and draws resampled)."""
    return bootstrap_interval(
        EpisodeErrors(error=per_run, frames=np.ones(per_run.shape[1]), pooling=Pooling.MEAN),
        seed=seed,
    )


def pool_curves(records: Sequence[DesignCurves], name: str) -> DesignCurves:
    """One design's curves from several runs' curves (training seeds) of one design.

    Intervals then resample runs and draws. The runs must share their configuration.

    Raises:
        ValueError: no records, or records measured with different configurations.
    """
    if not records:
        raise ValueError("pool_curves needs at least one record")
    configs = {repr(r.config) for r in records}
    if len(configs) != 1:
        raise ValueError(f"{name}: the records were measured with different configurations")
    increases = {curve: [run for r in records for run in _runs_of(r, curve)] for curve in CURVES}
    nominal = [e for r in records for e in r.nominal_errors]
    return design_record(
        name, all(r.robust for r in records), nominal, increases, records[0].config
    )


def _runs_of(record: DesignCurves, curve: str) -> list[list[tuple[float, ...]]]:
    """``[run][level][draw]`` increases of a record.

    Raises:
        ValueError: a summary's record (without its per-draw increases).
    """
    levels = record.curves[curve].levels
    if any(lv.increases is None for lv in levels):
        raise ValueError(f"{record.name}: a summary without per-draw increases cannot be pooled")
    return [
        [lv.increases[r] for lv in levels if lv.increases is not None] for r in range(record.runs)
    ]


def _curve_fields(curve: str) -> tuple[str, ...]:
    """The record names (mm, deg, %, cm) of the model fields a curve varies."""
    if curve == MIX:
        return tuple(record_name(f) for fs in TERM_FIELDS.values() for f in fs)
    return tuple(record_name(f) for f in TERM_FIELDS[PerturbationTerm(curve)])


def tolerance(
    levels: Sequence[float], mean_increase: Sequence[float], allowed_increase: float
) -> tuple[float, bool]:
    """``(factor, bounded)``: the largest level whose mean increase stays within the limit.

    Linear interpolation between the last level within and the first beyond;
    ``bounded`` is False when every level stays within (the tolerance is then
    at least the largest level).
    """
    for i, (level, inc) in enumerate(zip(levels, mean_increase, strict=True)):
        if inc > allowed_increase:
            if i == 0:
                return 0.0, True
            l0, i0 = levels[i - 1], mean_increase[i - 1]
            return float(l0 + (level - l0) * (allowed_increase - i0) / (inc - i0)), True
    return float(levels[-1]), False


def fabrication_spec(curve: str, tol: Tolerance) -> str:
    """A tolerance as a workshop instruction, e.g. ``"align each mask to +-0.3 mm"``."""
    v = tol.values
    texts = {
        "mask_shift": lambda: f"align each mask to ±{v['mask_shift_mm']:.2g} mm",
        "mask_rotation": lambda: f"square each mask to ±{v['mask_rotation_deg']:.2g}°",
        "tone": lambda: (
            f"print with tone-curve gamma within 1 ± {v['gamma_deviation']:.2g} and dot gain "
            f"within ±{100 * v['dot_gain_deviation']:.2g} %"
        ),
        "printable_range": lambda: (
            f"keep the film's darkest transmittance within ±{v['min_transmittance_error']:.2g} "
            f"and its clearest within ±{v['max_transmittance_error']:.2g} of the calibration"
        ),
        "mask_blur": lambda: f"print sharper than a {v['mask_blur_mm']:.2g}-mm Gaussian (sigma)",
        "gain_mismatch": lambda: f"match detector gains to ±{v['gain_mismatch_percent']:.2g} %",
        "dark_offset": lambda: f"trim output offsets to ±{1e3 * v['dark_offset_v']:.2g} mV",
        "pose_orientation": lambda: (
            f"mount the camera to ±{v['pose_orientation_deg']:.2g}° (pan, tilt and roll)"
        ),
        "pose_position": lambda: (
            f"place the camera to ±{v['pose_position_cm']:.2g} cm along each axis"
        ),
        MIX: lambda: f"all at once: {tol.factor:.2g}x the default ranges",
    }
    text = texts[curve]()
    if not tol.bounded:
        text += " (or looser: within the measured range the error never rose by the limit)"
    return text


def run(
    runs: Sequence[Path],
    data_dirs: Sequence[Path],
    config: RobustnessConfig,
    *,
    allow_unfinished: bool = False,
) -> list[DesignCurves]:
    """Every trained minimalist run under the perturbations: one design's curves per run.

    Args:
        runs: run directories (``mincam-render train``, nominal or robust).
        data_dirs: test datasets (each one's test split); empty: each run's own.
        config: what is measured.
        allow_unfinished: measure runs whose training did not finish (their
            best state so far), named ``(unfinished)``.

    Raises:
        ValueError: a run is not a minimalist camera's, is unfinished, or has no
            test dataset on disk while ``data_dirs`` is empty.
    """
    from mincam_render.learn.train import open_run, restore_mincam

    designs = []
    for run_dir in runs:
        trained = open_run(run_dir, allow_unfinished=allow_unfinished)
        tests = evaluation_data(trained.record, data_dirs)
        use = "a robustness report (it perturbs masks and diodes)"
        model = restore_mincam(trained, next(iter(tests.values())), use)
        robust = trained.record["config"].get("perturbation") is not None
        name = run_dir.name if trained.finished else f"{run_dir.name} (unfinished)"
        designs.append(robustness_curves(model, tests, config, name=name, robust=robust))
    return designs


def evaluation_data(
    record: Mapping[str, Any], data_dirs: Sequence[Path]
) -> dict[str, TrainingData]:
    """``{name: TrainingData}``: each of ``data_dirs``' test split, or the run dataset's."""
    from mincam_render.data.dataset import open_dataset
    from mincam_render.learn.training_data import TrainingData

    if not data_dirs:
        test = record["data"].get("test") or {}
        if not test.get("dataset"):
            raise ValueError(
                "the run has no test dataset on disk (trained in memory or on episodes): "
                "give --data DIRECTORY"
            )
        data_dirs = (Path(test["dataset"]),)
    return {p.name: TrainingData.from_dataset(open_dataset(p), "test") for p in data_dirs}
