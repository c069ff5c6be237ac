"""The task-level fidelity check: acceptance, the chosen level, noise against signal."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from mincam_render.data import dataset as ds
from mincam_render.render.differential import DifferenceSeeds
from mincam_render.studies.comparison.figures import DesignFigure
from mincam_render.studies.task_fidelity import SampleLevel, TaskFidelityConfig, noise_figures
from mincam_render.studies.task_fidelity.study import (
    LevelFigures,
    acceptance,
    chosen_level,
    render_seconds_per_frame,
    supported,
)


def _figure(name: str, errors: list[list[float]]) -> DesignFigure:
    """A design's figure from per-seed, per-episode errors (mean and a made-up interval)."""
    e = np.asarray(errors)
    mean = float(e.mean())
    return DesignFigure(
        design=name,
        pixels=2,
        error=mean,
        ci95=(mean - 0.1, mean + 0.1),
        per_seed=tuple(e.mean(axis=1)),
        state="converged",
        steps=(100,) * len(e),
        train_s_per_run=1.0,
        episode_errors={"error": e.tolist(), "frames": [600] * e.shape[1], "pooling": "rms"},
    )


def _levels(tmp_path: Path) -> tuple[SampleLevel, ...]:
    return (
        SampleLevel(name="1x", factor=1, episodes=tmp_path, max_depth=None, planned=True),
        SampleLevel(name="0.25x", factor=0.25, episodes=tmp_path),
        SampleLevel(name="0.0625x", factor=0.0625, episodes=tmp_path),
        SampleLevel(name="0.25x-frame", factor=0.25, episodes=tmp_path, difference_seeds="frame"),
        SampleLevel(name="4x", factor=4, episodes=tmp_path),
    )


def _level(designs, replicate=None) -> LevelFigures:
    return LevelFigures(
        level="1x",
        factor=1.0,
        difference_seeds="window",
        render_s_per_frame=0.1,
        designs=designs,
        trivial=2.0,
        noise=None,
        replicate=replicate,
    )


def test_a_level_passes_when_every_figure_moves_less_than_a_quarter_of_its_half_width():
    ref = {"a": _figure("a", [[1.0, 1.2], [1.1, 0.9]]), "b": _figure("b", [[2.0, 2.0]] * 2)}
    # half-width 0.1: "a" moves by 0.02 (< 0.025), "b" by 0.03 (>= 0.025)
    level = {
        "a": _figure("a", [[1.02, 1.22], [1.12, 0.92]]),
        "b": _figure("b", [[2.03, 2.03]] * 2),
    }
    checks = {c.design: c for c in acceptance(_level(level), ref, 0.25)}
    assert checks["a"].passes and not checks["b"].passes
    np.testing.assert_allclose(checks["a"].moved, 0.02, atol=1e-12)
    np.testing.assert_allclose(checks["b"].half_width, 0.1, atol=1e-12)
    # paired on the same test episodes: every pair moved by +0.03, so its interval excludes 0
    np.testing.assert_allclose(checks["b"].paired.mean, 0.03, atol=1e-9)
    assert not checks["b"].within_seed_noise and not supported(tuple(checks.values()))


def test_a_move_the_seeds_spread_cannot_resolve_is_supported():
    # "b" moves by 0.05 (not accepted: half-width 0.1), its paired interval holds
    # 0 (seeds spread); other training seeds on the same renders move it by 0.08
    ref = {"b": _figure("b", [[2.0, 2.1], [1.8, 1.9]])}
    level = {"b": _figure("b", [[2.2, 2.2], [1.75, 1.85]])}
    replicate = {"b": _figure("b", [[2.1, 2.1], [2.06, 2.06]])}
    (check,) = acceptance(_level(level, replicate), ref, 0.25)
    assert not check.passes
    np.testing.assert_allclose([check.moved, check.replicate_moved], [0.05, 0.08], atol=1e-12)
    assert check.paired.ci95[0] <= 0 <= check.paired.ci95[1]
    assert check.within_seed_noise and supported((check,))


def test_the_cheapest_accepted_level_with_the_plans_seeds_is_chosen(tmp_path):
    cfg = TaskFidelityConfig(levels=_levels(tmp_path), reference="4x")
    accepted = {"1x": True, "0.25x": True, "0.0625x": False, "0.25x-frame": True}
    assert chosen_level(cfg, accepted) == "0.25x"
    assert chosen_level(cfg, accepted | {"0.25x": False}) == "1x"
    assert chosen_level(cfg, dict.fromkeys(accepted, False)) is None


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"reference": "16x"}, "not among the levels"),
        ({"second_reference": "2x"}, "not among the levels"),
        ({"acceptance_share": 0.0}, "acceptance_share"),
    ],
)
def test_a_check_that_cannot_be_judged_is_refused(tmp_path, changes, match):
    with pytest.raises(ValueError, match=match):
        TaskFidelityConfig(levels=_levels(tmp_path), **({"reference": "4x"} | changes))


def test_exactly_one_level_is_the_plan(tmp_path):
    levels = _levels(tmp_path)[1:]
    with pytest.raises(ValueError, match="exactly one is the plan"):
        TaskFidelityConfig(levels=levels, reference="4x")
    with pytest.raises(ValueError, match="factor 1"):
        SampleLevel(name="2x", factor=2, episodes=tmp_path, max_depth=None, planned=True)


def test_render_seconds_leave_planning_out(tmp_path):
    episode = tmp_path / "test-0"
    episode.mkdir()
    ds.write_manifest(
        episode, {"format": ds.FORMAT_NAME, "format_version": ds.FORMAT_VERSION, "num_frames": 100}
    )
    events = [
        {"event": "planned", "seconds": 30.0},
        {"event": "backgrounds", "seconds": 5.0},
        {"event": "end", "rendered": [0, 1], "seconds": 50.0},  # planning, backgrounds, frames
        {"event": "end", "rendered": [], "seconds": 1.0},  # a resume with nothing to do
    ]
    (episode / "render_log.jsonl").write_text("\n".join(json.dumps(e) for e in events))
    assert render_seconds_per_frame([episode]) == pytest.approx(0.2)


def test_noise_figures_against_closed_forms():
    # a signal a_f * D, the reference exact, the level off by a pattern of
    # power sigma^2 held for windows of W frames: error RMS sigma * sqrt(share),
    # lag-1 autocorrelation (W - 1) / W
    rng = np.random.default_rng(5)
    frames, window, shape = 1200, 20, (2, 8, 8)
    mover = rng.uniform(0.0, 1.0, size=shape)
    amplitude = rng.integers(0, 4, size=frames).astype(np.float64)
    background = rng.uniform(5.0, 6.0, size=shape)
    signal = amplitude[:, None, None, None] * mover[None]
    exact = background[None] + signal
    pattern = np.repeat(rng.normal(0.0, 0.1, size=(frames // window, *shape)), window, axis=0)
    episodes = {Path("ref"): (exact, signal), Path("level"): (exact + pattern, signal)}
    figures = noise_figures(
        ([Path("level")], 1.0),
        ([Path("ref")], 1e9, "ref"),
        [Path("ref")],
        window_frames=window,
        load=episodes.__getitem__,
        transmittance_range=(0.01, 0.67),
    )
    box = figures.error_rms_w["box_1"]
    np.testing.assert_allclose(box, 0.1, rtol=0.05)
    np.testing.assert_allclose(figures.signal_rms_w["box_1"], np.sqrt(
        np.mean((signal - signal.mean(0)) ** 2)), rtol=1e-9)  # fmt: skip
    acf = figures.autocorrelation["box_1"]
    np.testing.assert_allclose(acf["lag_1_frame"], (window - 1) / window, atol=0.02)
    np.testing.assert_allclose(acf["lag_1_window"], 0.0, atol=0.05)
    assert figures.ratio()["box_1"] == pytest.approx(box / figures.signal_rms_w["box_1"])
    # frame steps: the pattern changes at 1 step in W, by a power of 2 sigma^2
    steps = np.diff(signal, axis=0)
    np.testing.assert_allclose(figures.step_error_rms_w["box_1"], 0.1 * np.sqrt(2 / window),
                               rtol=0.1)  # fmt: skip
    np.testing.assert_allclose(figures.step_signal_rms_w["box_1"], np.sqrt(
        np.mean((steps - steps.mean(0)) ** 2)), rtol=1e-9)  # fmt: skip
    assert figures.ratio("step_error_rms_w", "step_signal_rms_w")["box_1"] == pytest.approx(
        figures.step_error_rms_w["box_1"] / figures.step_signal_rms_w["box_1"]
    )


def test_a_window_as_long_as_the_episodes_leaves_its_lag_unmeasured():
    # the lighting room's test episodes: 1,800 frames, one 60 s window at 30 fps
    rng = np.random.default_rng(6)
    frames, shape = 300, (2, 8, 8)
    signal = rng.integers(0, 3, size=frames).astype(np.float64)[:, None, None, None] * np.ones(
        shape
    )
    exact = 5.0 + signal
    noisy = exact + rng.normal(0.0, 0.1, size=exact.shape)  # independent per frame
    episodes = {Path("ref"): (exact, signal), Path("level"): (noisy, signal)}
    figures = noise_figures(
        ([Path("level")], 1.0),
        ([Path("ref")], 1e9, "ref"),
        None,
        window_frames=frames,
        load=episodes.__getitem__,
        transmittance_range=(0.01, 0.67),
    )
    acf = figures.autocorrelation["box_1"]
    assert acf["lag_1_window"] is None
    np.testing.assert_allclose(acf["lag_1_frame"], 0.0, atol=0.1)
    np.testing.assert_allclose(figures.error_rms_w["box_1"], 0.1, rtol=0.05)
    # noise new in every frame: its frame steps have sqrt(2) times its RMS
    np.testing.assert_allclose(figures.step_error_rms_w["box_1"], 0.1 * np.sqrt(2), rtol=0.05)


def test_levels_take_the_plans_seeds_unless_told(tmp_path):
    level = SampleLevel(name="4x", factor=4, episodes=str(tmp_path))
    assert level.difference_seeds is DifferenceSeeds.WINDOW
    assert isinstance(level.episodes, Path)


def _three_levels(tmp_path: Path, reference: str, second: str | None) -> TaskFidelityConfig:
    levels = tuple(
        SampleLevel(name=n, factor=f, episodes=tmp_path / n, max_depth=None if n == "1x" else 16,
                    planned=n == "1x")
        for n, f in (("1x", 1.0), ("0.25x", 0.25), ("4x", 4.0))
    )  # fmt: skip
    return TaskFidelityConfig(levels=levels, reference=reference, second_reference=second)


def _noise_arguments(monkeypatch, cfg: TaskFidelityConfig, level: str) -> dict:
    from mincam_render.studies.task_fidelity import study

    seen: dict = {}
    monkeypatch.setattr(
        study, "noise_figures", lambda lv, ref, sec, **kw: seen.update(lv=lv, ref=ref, sec=sec)
    )
    study._noise(cfg, cfg.level(level))
    return seen


@pytest.mark.parametrize(
    ("reference", "second", "level", "against", "estimate"),
    [
        # the most samples judge; the next most give the signal's second estimate
        ("4x", "1x", "0.25x", "4x", "1x"),
        ("4x", "1x", "1x", "4x", "1x"),
        # a reduced check judged by the plan: the plan's noise against the cheaper level
        ("1x", "0.25x", "1x", "0.25x", "1x"),
        ("1x", "0.25x", "0.25x", "1x", "0.25x"),
    ],
)
def test_noise_is_taken_against_the_reference_or_the_plans_against_the_second(
    tmp_path, monkeypatch, reference, second, level, against, estimate
):
    cfg = _three_levels(tmp_path, reference, second)
    seen = _noise_arguments(monkeypatch, cfg, level)
    names = cfg.noise_episodes
    assert seen["lv"] == ([tmp_path / level / n for n in names], cfg.level(level).factor)
    assert seen["ref"] == (
        [tmp_path / against / n for n in names],
        cfg.level(against).factor,
        against,
    )
    assert seen["sec"] == [tmp_path / estimate / n for n in names]


@pytest.mark.parametrize(("level", "estimate"), [("4x", "1x"), ("1x", "1x"), ("0.25x", "1x")])
def test_a_test_level_above_the_reference_measures_every_levels_noise(
    tmp_path, monkeypatch, level, estimate
):
    cfg = _three_levels(tmp_path, "4x", "1x")
    above = SampleLevel(name="16x", factor=16, episodes=tmp_path / "16x", max_depth=16)
    frames = SampleLevel(name="64x-frame-seeds", factor=64, episodes=tmp_path / "64x",
                         difference_seeds=DifferenceSeeds.FRAME)  # fmt: skip
    cfg = dataclasses.replace(cfg, test_levels=(above, frames))
    seen = _noise_arguments(monkeypatch, cfg, level)  # the reference's too, against 16x
    names = cfg.noise_episodes
    assert seen["ref"] == ([tmp_path / "16x" / n for n in names], 16, "16x")
    assert seen["sec"] == [tmp_path / estimate / n for n in names]
    below = dataclasses.replace(above, name="2x", factor=2, episodes=tmp_path / "2x")
    cfg = dataclasses.replace(cfg, test_levels=(below,))  # below the reference: not used
    assert _noise_arguments(monkeypatch, cfg, "1x")["ref"][2] == "4x"


@pytest.mark.parametrize(("reference", "second"), [("4x", "1x"), ("1x", None)])
def test_a_reference_has_no_noise_of_its_own_to_measure(tmp_path, monkeypatch, reference, second):
    cfg = _three_levels(tmp_path, reference, second)
    assert _noise_arguments(monkeypatch, cfg, reference) == {}


def _cross_config(tmp_path: Path, cross) -> TaskFidelityConfig:
    cfg = _three_levels(tmp_path, "1x", "0.25x")
    test_level = SampleLevel(name="16x", factor=16, episodes=tmp_path / "16x")
    return TaskFidelityConfig(levels=cfg.levels[:2], reference="1x", second_reference="0.25x",
                              test_levels=(test_level,), cross=cross)  # fmt: skip


@pytest.mark.parametrize(
    "cross",
    [(("1x", "1x"),), (("16x", "1x"),), (("1x", "64x"),)],
    ids=["same level", "test level trained", "unknown level"],
)
def test_cross_pairs_train_at_a_level_and_test_at_another(tmp_path, cross):
    with pytest.raises(ValueError, match="train at one of the levels"):
        _cross_config(tmp_path, cross)


def test_a_test_level_is_not_the_plan_nor_a_second_level_of_one_name(tmp_path):
    cfg = _cross_config(tmp_path, (("1x", "16x"),))
    assert cfg.level("16x").factor == 16
    with pytest.raises(ValueError, match="give each name once"):
        TaskFidelityConfig(levels=cfg.levels, reference="1x", test_levels=(cfg.level("0.25x"),))
    plan = SampleLevel(name="p", factor=1, episodes=tmp_path, max_depth=None, planned=True)
    with pytest.raises(ValueError, match="cannot be the plan"):
        TaskFidelityConfig(levels=cfg.levels, reference="1x", test_levels=(plan,))


def test_a_test_level_renders_its_test_episodes_alone(tmp_path, monkeypatch):
    from mincam_render.data import render_job
    from mincam_render.studies.task_fidelity import study

    cfg = _cross_config(tmp_path, (("1x", "16x"),))
    names = study.episode_names(cfg)
    monkeypatch.setattr(study, "level_requests", lambda c, lv: dict.fromkeys(names))
    rendered: list[Path] = []
    monkeypatch.setattr(render_job, "render_dataset", lambda req, path, **kw: rendered.append(path))
    study.render_level(cfg, cfg.level("16x"))
    assert rendered == [tmp_path / "16x" / n for n in names if n.startswith("test-")]
    rendered.clear()
    study.render_level(cfg, cfg.level("0.25x"))
    assert rendered == [tmp_path / "0.25x" / n for n in names]


def test_cross_figures_copy_the_runs_and_pair_test_and_training_noise(tmp_path, monkeypatch):
    from mincam_render.studies.task_fidelity import study

    cfg = _cross_config(tmp_path, (("0.25x", "1x"), ("1x", "16x")))
    out = tmp_path / "runs"
    for level in ("0.25x", "1x"):
        (out / level / "runs" / "run-a").mkdir(parents=True)
        (out / level / "runs" / "run-a" / "metrics.json").write_text(level)
    # errors equal over a seed's episodes, so that pooling (RMS) keeps differences exact
    own = {
        "1x": _level(
            {"a": _figure("a", [[1.05, 1.05], [1.45, 1.45]]), "b": _figure("b", [[1.3] * 2] * 2)}
        ),
        "0.25x": _level(
            {"a": _figure("a", [[1.2, 1.2], [1.6, 1.6]]), "b": _figure("b", [[1.4] * 2] * 2)}
        ),
    }
    # the 0.25x runs on 1x test renders: each error 0.1 below their own, 0.05 above 1x's
    crossed = {"a": _figure("a", [[1.1, 1.1], [1.5, 1.5]]), "b": _figure("b", [[1.3, 1.3]] * 2)}
    seen = []

    def tested(c, episodes, here, workers, progress, *, replicate=True):
        assert not replicate  # the replicate's runs are not tested across levels
        seen.append((here, {n: episodes(n) for n in study.episode_names(c)}))
        return study._Tested(crossed, 2.0, None, "RMSE")

    monkeypatch.setattr(study, "_tested_designs", tested)
    stale = out / "0.25x-on-1x" / "runs" / "run-old"  # a copy of runs since trained again
    stale.mkdir(parents=True)
    c = study.cross_figures(cfg, cfg.level("0.25x"), cfg.level("1x"), out, own)
    here, episodes = seen[0]
    assert here == out / "0.25x-on-1x"
    assert (here / "runs" / "run-a" / "metrics.json").read_text() == "0.25x"  # a copy
    assert not stale.exists()
    assert c.test_noise["a"].key == "a (1x) - a (0.25x)"
    assert all(p.parent.name == ("1x" if n.startswith("test-") else "0.25x")
               for n, p in episodes.items())  # fmt: skip
    np.testing.assert_allclose(c.test_noise["a"].mean, -0.1, atol=1e-9)
    np.testing.assert_allclose(c.train_noise["a"].mean, 0.05, atol=1e-9)
    # seeds resampled on both sides: the interval spans the seeds' spread (1.1 - 1.6, 1.5 - 1.2)
    lo, hi = c.test_noise["a"].ci95
    assert -0.5 - 1e-9 <= lo < -0.1 < hi <= 0.3 + 1e-9
    # the designs ranked on the other renders: a (1.1 and 1.5 by seed) less b (1.3)
    assert list(c.between) == ["a - b"]
    np.testing.assert_allclose(c.between["a - b"].mean, 0.0, atol=1e-9)
    assert c.between["a - b"].ci95[0] < 0 < c.between["a - b"].ci95[1]
    c = study.cross_figures(cfg, cfg.level("1x"), cfg.level("16x"), out, own)
    assert c.train_noise is None  # 16x is a test level: nothing trained there


def test_every_two_designs_are_paired_in_order_on_their_common_episodes():
    from mincam_render.studies.task_fidelity.study import between_designs

    base = [[1.0, 1.0], [1.4, 1.4]]  # equal over a seed's episodes: RMS keeps shifts exact
    designs = {
        name: _figure(name, [[e + shift for e in seed] for seed in base])
        for name, shift in (("a", 0.0), ("b", 0.3), ("c", -0.1))
    }
    pairs = between_designs(designs)
    assert list(pairs) == ["a - b", "a - c", "b - c"]
    for key, expected in (("a - b", -0.3), ("a - c", 0.1), ("b - c", 0.4)):
        np.testing.assert_allclose(pairs[key].mean, expected, atol=1e-9)
    assert between_designs({"a": designs["a"]}) == {}


def test_the_report_shows_each_levels_figures_and_its_pairs_between_designs():
    from mincam_render.studies.task_fidelity.report import markdown
    from mincam_render.studies.task_fidelity.study import TaskFidelityResult, between_designs

    designs = {"a": _figure("a", [[1.0, 1.0], [1.2, 1.2]]), "b": _figure("b", [[1.5] * 2] * 2)}
    paired = dataclasses.replace(_level(designs), between=between_designs(designs))
    unpaired = dataclasses.replace(_level(designs), level="4x", factor=4.0)  # e.g. an old JSON's
    result = TaskFidelityResult(
        config={}, task="count", error_name="count RMSE", levels=(paired, unpaired),
        acceptance={}, chosen=None, versions={},
    )  # fmt: skip
    lines = markdown(result).splitlines()
    assert "| 1x | 1 | window | 0.100 | 1.100 [1.000, 1.200] | 1.500 [1.400, 1.600] |" in lines
    assert "| 4x | 4 | window | 0.100 | 1.100 [1.000, 1.200] | 1.500 [1.400, 1.600] |" in lines
    # per seed a - b is -0.5 and -0.3: the mean and the seeds' range
    assert "- 1x: a - b -0.400 [-0.500, -0.300]" in lines
    assert not [ln for ln in lines if ln.startswith("- 4x")]  # no pairs, no empty line
    result = dataclasses.replace(result, levels=(unpaired,))
    assert "Between designs at each level" not in markdown(result)


def test_the_reports_noise_table_and_plot_show_the_frame_steps(tmp_path):
    from mincam_render.studies.task_fidelity.noise import NoiseFigures
    from mincam_render.studies.task_fidelity.report import markdown, plot_paretos
    from mincam_render.studies.task_fidelity.study import TaskFidelityResult

    kinds = ("random_masks", "box_4", "box_1")

    def per_kind(*values: float) -> dict[str, float]:
        return dict(zip(kinds, values, strict=True))

    noise = NoiseFigures(
        episodes=("test-0",),
        reference="4x",
        error_rms_w=per_kind(1.0, 2.0, 3.0),
        noise_rms_w=per_kind(1.0, 2.0, 3.0),
        signal_rms_w=per_kind(10.0, 10.0, 10.0),
        step_error_rms_w=per_kind(1.5, 3.0, 4.5),
        step_signal_rms_w=per_kind(1.0, 2.0, 1.5),
        autocorrelation={k: {"lag_1_frame": 0.0, "lag_1_window": None} for k in kinds},
        window_frames=1800,
    )
    level = dataclasses.replace(_level({"a": _figure("a", [[1.0, 1.0]])}), noise=noise)
    result = TaskFidelityResult(
        config={}, task="speed", error_name="mph", levels=(level,),
        acceptance={}, chosen=None, versions={},
    )  # fmt: skip
    # frame scale: error / signal; steps: 1.5 / 1.0, 3.0 / 2.0, 4.5 / 1.5
    row = "| 1x | 4x | 0.100 / 0.200 / 0.300 | 0.100 / 0.200 / 0.300 | 1.500 / 1.500 / 3.000 |"
    assert any(ln.startswith(row) for ln in markdown(result).splitlines())
    assert plot_paretos([level], "mph", tmp_path / "p.png").stat().st_size > 0
