"""The sim2real study: a recording against its simulation, per pixel and per task, with verdicts.

:func:`run` renders the recording's scene twin (a SURROGATE recording is made
first if the config asks for one) with the designed camera and printed masks,
compares every pixel (:mod:`.fit`), evaluates the task heads (:mod:`.tasks`) and
states a verdict. Arrays are numpy float64; voltages in volts.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from mincam_render.render.capabilities import history_frames
from mincam_render.studies.sim2real.config import Sim2RealConfig
from mincam_render.studies.sim2real.fit import THRESHOLDS, compare_pixels, distribution_gap
from mincam_render.studies.sim2real.recording import (
    SURROGATE_BANNER,
    Recording,
    load_recording,
    recording_checksums,
)
from mincam_render.studies.sim2real.result import (
    PixelComparison,
    PixelVerdict,
    Series,
    Sim2RealResult,
    TaskMetrics,
    Verdict,
)
from mincam_render.studies.sim2real.simulation import simulate_volts
from mincam_render.studies.sim2real.tasks import task_metrics


def run(config: Sim2RealConfig, out: str | Path, *, progress: bool = False) -> Sim2RealResult:
    """Compare a recording with its simulation (see the module doc).

    Args:
        config: the recording (or the family of a SURROGATE recording to make)
            and the renders' samples, training steps and seed.
        out: the study's directory: a SURROGATE recording is written to
            ``out/surrogate_input``; :func:`.report.write_report` writes the report.
        progress: show progress bars (the surrogate's render, the simulated
            frames); the result does not depend on it.

    Raises:
        Sim2RealError: invalid recording.
        ValueError: a surrogate of an unknown family.
    """
    path = config.recording
    if path is None:
        from mincam_render.studies.sim2real.surrogate import make_surrogate

        assert config.surrogate_family is not None  # the config holds exactly one
        path = make_surrogate(
            config.surrogate_family,
            Path(out) / "surrogate_input",
            num_frames=config.surrogate_frames,
            spp=config.spp,
            seed=config.seed,
            progress=progress,
        )
    rec = load_recording(path)
    sim_volts = _simulate_recording(rec, spp=config.spp, seed=config.seed, progress=progress)
    pixels = tuple(compare_pixels(sim_volts, rec.volts, rec.pixels, rec.injected))
    metrics = (
        task_metrics(rec, sim_volts, steps=config.steps, seed=config.seed) if config.tasks else None
    )
    root = Path(path)
    return Sim2RealResult(
        surrogate=rec.surrogate,
        banner=SURROGATE_BANNER if rec.surrogate else None,
        recording=str(root.resolve()),
        recording_sha256=recording_checksums(root),
        family=rec.meta["family"],
        num_samples=int(len(rec.time_s)),
        fps=float(rec.meta["fps"]),
        units_in_file=rec.meta["units"],
        spp=config.spp,
        seed=config.seed,
        thresholds=THRESHOLDS,
        pixels=pixels,
        distribution_gap=distribution_gap(list(pixels)),
        injected=rec.injected,
        series=Series(time_s=rec.time_s, sim_v=sim_volts, real_v=rec.volts),
        tasks=metrics,
        video_simulation_note="omitted: the paper's video-based simulation needs the "
        "auxiliary camera's frames"
        + (
            ""
            if not (root / "frames").is_dir()
            else " (frames found but their analysis is not implemented)"
        ),
        verdict=verdict(pixels, metrics, surrogate=rec.surrogate),
    )


def _simulate_recording(rec: Recording, *, spp: int, seed: int, progress: bool) -> np.ndarray:
    """Noiseless simulated voltages ``V[N, P]`` of the recording's scene twin (V).

    Also records in ``rec.meta`` whether the family's task needs history, unless
    the recording says so itself.
    """
    from mincam_render.scenes import load_family

    family = load_family(
        rec.meta["family"],
        seed=int(rec.meta["family_seed"]),
        num_frames=int(rec.frame_index.max()) + 1,
    )
    rec.meta.setdefault("needs_history", history_frames(family) > 1)
    sim_volts, _ = simulate_volts(
        family,
        rec.camera,
        rec.frame_index,
        rec.masks,
        rec.pixels,
        spp=spp,
        seed=seed,
        progress="simulate the recording" if progress else None,
    )
    return sim_volts


def verdict(
    pixels: Sequence[PixelComparison], tasks: TaskMetrics | None, *, surrogate: bool
) -> Verdict:
    """Overall verdict from per-pixel verdicts and task errors (thresholds in THRESHOLDS)."""
    counts: dict[str, int] = {}
    for p in pixels:
        counts[p.verdict.value] = counts.get(p.verdict.value, 0) + 1
    n = len(pixels)
    lines = [f"{v.value}: {counts.get(v.value, 0)} of {n} pixels" for v in PixelVerdict]
    disagrees = counts.get(PixelVerdict.DISAGREES.value, 0)
    if disagrees == 0 and counts.get(PixelVerdict.AGREES.value, 0) == n:
        overall = "simulation matches the measurements without calibration"
    elif disagrees == 0:
        overall = "simulation matches the measurements after a per-pixel gain/offset fit"
    else:
        overall = "simulation does not reproduce some pixels' time series (see per pixel)"
    task_line = _task_verdict(tasks) if tasks else ""
    prefix = "SURROGATE data: " if surrogate else ""
    summary = prefix + overall + "; " + ", ".join(lines) + (f"; {task_line}" if task_line else "")
    return Verdict(overall=overall, counts=counts, task=task_line, summary=summary)


def _task_verdict(t: TaskMetrics) -> str:
    """One line: does the sim-trained head transfer to real data (``max_task_gap``)?"""
    real = t.real_on_real.error
    gap = THRESHOLDS.max_task_gap
    name = t.real_on_real.error_name

    def ok(e: float) -> bool:
        return e <= real * (1 + gap) + 1e-9

    return (
        f"task ({name}): sim-trained head on real {t.sim_on_real.error:.3g} "
        f"({'transfers' if ok(t.sim_on_real.error) else 'does not transfer'}), "
        f"retrained on real {t.sim_head_retrained_on_real.error:.3g} "
        f"({'ok' if ok(t.sim_head_retrained_on_real.error) else 'worse'}), "
        f"real-trained {real:.3g}, sim on sim {t.sim_on_sim.error:.3g} "
        f"(tolerance {gap:.0%} over real-trained)"
    )
