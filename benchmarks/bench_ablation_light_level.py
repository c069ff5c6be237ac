"""Supplement A over the light level: freeform pixels trained with vs without the sensor model.

The paper (supplement A) trained 4 patches-counting masks without the detector
model, froze them, retrained the head with the model and tested with it: 2.28
count RMSE, against 0.93 for masks trained with the model -- one light level.
This benchmark draws the curve over the scene's light level: the patches
episodes are rendered once (Mitsuba, measured fidelity) and every level
multiplies every emitter's radiance by a factor (transport is linear in it,
:meth:`TrainingData.with_light_scaled`), so the levels differ only in how much
light reaches the detectors against their fixed noise, gain and full scale.

At each level a study (:func:`mincam_render.studies.comparison.study.run`)
trains ``mincam-4px`` (with the model) and ``mincam-4px-nosensor`` (masks
without it, head retrained with it) with ``--seeds`` training seeds, tests both
with the model on independent test episodes, and reports the mean and the 95 %
bootstrap interval over seeds and test episodes.

Light level as illuminance at the camera (lux): the mean radiance ``L`` of the
plane (over the training episode's frames, at factor 1) times the projected
solid angle of the plane seen from the board centre
(:func:`mincam_render.core.photometry.rectangle_projected_solid_angle`) is the
irradiance in the visible band, converted at the white-light efficacy of
:mod:`mincam_render.core.photometry` (300 lm/W). A level of ``E`` lux is the
factor ``E / E_1`` with ``E_1`` the illuminance at factor 1.

Writes ``ablation_light_level.json``, ``.md`` and ``.png`` into ``--results``
(machine, git revision and ``git_dirty`` in the JSON); the work directory keeps
the episodes and every run (killed runs resume).

Usage:
    PYTHONPATH=. python benchmarks/bench_ablation_light_level.py [--work /tmp/ablation]
        [--lux 1,10,100,1000,10000] [--seeds 3] [--train-frames 3000]
        [--val-frames 1000] [--test-frames 700] [--test-episodes 3]
        [--steps 20000] [--workers 1] [--results benchmarks/results]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from provenance import machine

from mincam_render.core import strict_json
from mincam_render.core.photometry import (
    WHITE_LIGHT_EFFICACY_LM_PER_W,
    irradiance_to_lux,
    rectangle_projected_solid_angle,
)
from mincam_render.core.seeds import stream_seed
from mincam_render.learn.train_config import GAIN_AUGMENTATION_20, TrainConfig
from mincam_render.scenes import load_family
from mincam_render.studies.comparison import study as comparison
from mincam_render.studies.comparison.config import ComparisonConfig
from mincam_render.studies.comparison.records import DesignRecord
from mincam_render.studies.comparison.study import Design

#: The paper's single point (supplement A), count RMSE of 4 freeform pixels.
PAPER = {"with_sensor_model": 0.93, "without_sensor_model": 2.28, "light_level": "not stated"}


def illuminance_at_unit_scale(cfg: ComparisonConfig, frames: int) -> dict:
    """Mean illuminance (lx) at the board from the plane, at light factor 1, and its parts."""
    seed = stream_seed(cfg.seed, "episode/train", 0)
    fam = load_family(cfg.family, seed=seed, num_frames=frames)
    c = fam.config
    radiance = float(np.mean([fam.image(i)[0].mean() for i in range(frames)]))
    half = c.plane_distance_m * math.tan(math.radians(c.plane_fov_deg) / 2)
    omega = rectangle_projected_solid_angle(half, half, c.plane_distance_m)
    return {
        "mean_radiance_w_m2_sr": radiance,
        "frames_averaged": frames,
        "plane_half_width_m": half,
        "plane_distance_m": c.plane_distance_m,
        "projected_solid_angle_sr": omega,
        "irradiance_w_m2": radiance * omega,
        "efficacy_lm_per_w": WHITE_LIGHT_EFFICACY_LM_PER_W,
        "illuminance_lux": irradiance_to_lux(radiance * omega),
    }


def _design_record(d: DesignRecord) -> dict:
    return {
        "rmse_mean": d.error.mean,
        "rmse_ci95": [d.error.low, d.error.high],
        "per_seed": list(d.error_per_seed),
        "seeds": len(d.error_per_seed),
        "converged": d.converged,
        "state": d.state,
        "steps": list(d.steps),
        "train_wall_time_s": list(d.train_wall_time_s),
    }


def run_level(cfg: ComparisonConfig, work: Path, lux: float, workers: int) -> dict:
    """One light level: both designs trained and tested; their records and the verdict."""
    t0 = time.perf_counter()
    res = comparison.run(
        cfg,
        work / f"lux-{lux:g}",
        workers=workers,
        episodes_dir=work / "episodes",
        progress=False,
    )
    block = res.headline
    with_, without = (block.designs[d.name] for d in cfg.designs)
    return {
        "lux": lux,
        "light_scale": cfg.light_scale,
        "with_sensor_model": _design_record(with_),
        "without_sensor_model": _design_record(without),
        "trivial": block.trivial.error.as_dict(),
        "verdict": block.verdict,
        "seconds": time.perf_counter() - t0,
    }


def table(result: dict) -> str:
    """Markdown table of the curve."""
    lines = [
        "| illuminance (lx) | light factor | with sensor model [95 % CI] | converged | "
        "without (masks), head retrained with [95 % CI] | converged | verdict |",
        "|---:|---:|---|---|---|---|---|",
    ]
    for lv in result["levels"]:
        w, wo = lv["with_sensor_model"], lv["without_sensor_model"]
        lines.append(
            f"| {lv['lux']:g} | {lv['light_scale']:.3g} | {w['rmse_mean']:.3f} "
            f"[{w['rmse_ci95'][0]:.3f}, {w['rmse_ci95'][1]:.3f}] | {w['state']} | "
            f"{wo['rmse_mean']:.3f} [{wo['rmse_ci95'][0]:.3f}, {wo['rmse_ci95'][1]:.3f}] | "
            f"{wo['state']} | {lv['verdict']} |"
        )
    return "\n".join(lines)


def report(result: dict) -> str:
    """The Markdown report: command, light-level conversion, table, the paper's point."""
    u, c = result["illuminance_at_unit_scale"], result["config"]
    return "\n".join([
        "# Supplement A over the light level (patches, 4 freeform pixels)",
        "",
        f"`PYTHONPATH=. python benchmarks/{result['command']}` at "
        f"{result['machine']['git_revision'][:7]} (git_dirty: {result['machine']['git_dirty']}).",
        f"Episodes: {c['family']}, {c['train_episodes']} x {c['train_frames']} training, "
        f"{c['val_frames']} validation, {c['test_episodes']} x {c['test_frames']} test frames "
        "(other scene seeds), rendered once at the measured fidelity; every level multiplies "
        f"every emitter's radiance by its light factor. {c['seeds']} training seeds per design; "
        "mean and 95 % bootstrap interval over seeds and test episodes; both designs tested "
        "with the sensor model. 'without': masks trained without the sensor model, frozen, "
        "head retrained with it (the paper's protocol).",
        "",
        f"Illuminance at the camera: at light factor 1 the plane's mean radiance "
        f"{u['mean_radiance_w_m2_sr']:.3f} W m^-2 sr^-1 (over {u['frames_averaged']} training "
        f"frames) x projected solid angle {u['projected_solid_angle_sr']:.3f} sr (a "
        f"{2 * u['plane_half_width_m']:.3f} m square plane at {u['plane_distance_m']:g} m) = "
        f"{u['irradiance_w_m2']:.3f} W/m^2 (visible band) x {u['efficacy_lm_per_w']:g} lm/W = "
        f"{u['illuminance_lux']:.1f} lx; level E lx uses the factor E / "
        f"{u['illuminance_lux']:.1f}.",
        "",
        table(result),
        "",
        f"Paper (supplement A, light level not stated): with {PAPER['with_sensor_model']}, "
        f"without {PAPER['without_sensor_model']}.",
    ])  # fmt: skip


def plot(result: dict, path: Path) -> None:
    """Error against illuminance (log x), both designs with their 95 % intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lux = np.array([lv["lux"] for lv in result["levels"]])
    fig, ax = plt.subplots(figsize=(6, 4))
    for key, label, marker in (
        ("with_sensor_model", "masks trained with the sensor model", "o"),
        ("without_sensor_model", "masks trained without it (head retrained with it)", "s"),
    ):
        m = np.array([lv[key]["rmse_mean"] for lv in result["levels"]])
        ci = np.array([lv[key]["rmse_ci95"] for lv in result["levels"]])
        ax.errorbar(lux, m, yerr=[m - ci[:, 0], ci[:, 1] - m], marker=marker, capsize=3,
                    label=label)  # fmt: skip
    triv = np.array([lv["trivial"]["mean"] for lv in result["levels"]])
    ax.plot(lux, triv, "k:", label="trivial predictor (training mean)")
    ax.axhline(PAPER["with_sensor_model"], color="C0", lw=0.8, ls="--", label="paper: with (0.93)")
    ax.axhline(PAPER["without_sensor_model"], color="C1", lw=0.8, ls="--",
               label="paper: without (2.28)")  # fmt: skip
    ax.set_xscale("log")
    ax.set_xlabel("illuminance at the camera (lx)")
    ax.set_ylabel("test count RMSE (4 freeform pixels)")
    ax.set_title(
        "Supplement A over light level (patches, 4 px, tested with the sensor model)", fontsize=9
    )
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def write(result: dict, results: Path) -> None:
    """``ablation_light_level.json``, ``.png`` and ``.md`` in ``results``."""
    results.mkdir(parents=True, exist_ok=True)
    (results / "ablation_light_level.json").write_text(strict_json.dumps(result, indent=2) + "\n")
    plot(result, results / "ablation_light_level.png")
    (results / "ablation_light_level.md").write_text(report(result) + "\n")


def main(argv: list[str] | None = None) -> None:
    """Parse the options, run every light level, print and write the results."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", type=Path, default=Path("/tmp/ablation_light_level"))
    p.add_argument("--lux", default="1,10,100,1000,10000")
    p.add_argument("--family", default="patches")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--train-frames", type=int, default=3000)
    p.add_argument("--val-frames", type=int, default=1000)
    p.add_argument("--test-frames", type=int, default=700)
    p.add_argument("--test-episodes", type=int, default=3)
    p.add_argument("--steps", type=int, default=20000)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--results", type=Path, default=Path(__file__).parent / "results")
    a = p.parse_args(argv)
    levels = [float(v) for v in a.lux.split(",")]
    base = ComparisonConfig(
        family=a.family,
        train_episodes=1,
        train_frames=a.train_frames,
        val_frames=a.val_frames,
        test_frames=a.test_frames,
        test_episodes=a.test_episodes,
        val_episodes=1,  # as measured (ablation_light_level.json)
        seeds=a.seeds,
        designs=(Design(pixels=4), Design(pixels=4, sensor_model=False)),
        train=TrainConfig(max_steps=a.steps, gain_range=GAIN_AUGMENTATION_20),  # as measured
    )
    unit = illuminance_at_unit_scale(base, min(a.train_frames, 1000))
    print(f"illuminance at light factor 1: {unit['illuminance_lux']:.1f} lx "
          f"(mean radiance {unit['mean_radiance_w_m2_sr']:.3f} W/m^2/sr x "
          f"{unit['projected_solid_angle_sr']:.3f} sr x {unit['efficacy_lm_per_w']:g} lm/W)")  # fmt: skip
    result = {
        "benchmark": "ablation_light_level",
        "command": " ".join(
            [Path(sys.argv[0]).name, *(argv if argv is not None else sys.argv[1:])]
        ),
        "machine": machine(),
        "config": json.loads(json.dumps(dataclasses.asdict(base), default=str)),
        "illuminance_at_unit_scale": unit,
        "levels": [],
        "paper": PAPER,
    }
    for lux in levels:  # in the order given; the files list them by illuminance
        cfg = dataclasses.replace(base, light_scale=lux / unit["illuminance_lux"])
        lv = run_level(cfg, a.work, lux, a.workers)
        w, wo = lv["with_sensor_model"], lv["without_sensor_model"]
        print(f"{lux:>8g} lx  with {w['rmse_mean']:.3f} {w['rmse_ci95']}  without "
              f"{wo['rmse_mean']:.3f} {wo['rmse_ci95']}  ({lv['seconds']:.0f} s)", flush=True)  # fmt: skip
        result["levels"] = sorted([*result["levels"], lv], key=lambda v: v["lux"])
        write(result, a.results)  # after every level: a level run is kept if a later one is not
    print(table(result))


if __name__ == "__main__":
    main()
