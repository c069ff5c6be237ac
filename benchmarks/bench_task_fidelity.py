r"""Fidelity in task units: a plan judged by the task figure, its error by the label signal.

Usage::

    python benchmarks/bench_task_fidelity.py --work /data/fidelity \
        [--sections render,check,plans] [--levels 1x,0.25x,4x,16x] [--lock /tmp/mincam-cpu.lock]
        [--one-x /data/episodes/ws8] [--family workspace|lighting|patches|traffic]
        [--families workspace,lighting,patches,traffic]
        [--seeds 8] [--replicate-seeds 8] [--episodes 2,4,3] [--key workspace-32]
        [--cross 0.25x:1x,1x:0.25x,1x:4x]

``check`` (``--family``, :data:`CHECKED`): the plan's episodes (workspace: 2
training episodes of 1,200 frames at 2 fps, 4 validation and 3 test episodes of
600 frames, the people count; lighting: the toggling room at 30 fps, episodes of
3,600 and 1,800 frames, the five lights; patches: 16 detectors, 3,000 and 1,000
independent frames, the count; traffic: the street at 30 fps, episodes of
3,600 and 1,800 frames, the mean speed of both directions) at every
level of :data:`LEVELS` (samples of frames and backgrounds times a factor, path
depth 16; per-window or per-frame seeds of ``X - C``), count-only cameras
(mincam 2 and 8 px, baselines 8x8 and 32x32, 8 seeds and a replicate of 8 other
seeds, no gain augmentation) trained *and* tested at each level; every level
against the reference (16x): accepted when every design's test RMSE moves by
less than a quarter of its 95 % half-width; each level's render error against
the label signal on the test episodes and its autocorrelation at lags of one
frame and one window (measured against the reference, or against a test level
with more samples where there is one: then the reference's own noise too).
``render`` renders the levels' episodes first (``WORK/<prefix>-<level>``, one episode
per acquisition of ``--lock``; the check's episodes of the plan are copied from
``--one-x`` when given, which is only read). ``plans``: each family's plan
measured by the planner (every figure relative to the total and to the label
signal).

``--cross TRAINED:TESTED``: the runs trained at one level also tested on
another level's test episodes (the same scene seeds), paired with their own
tests (what render noise in test data changes) and with the runs trained there
(what it changes in training data); a tested level not in ``--levels`` is a
*test level*: only its test episodes are rendered, nothing is trained on it.

Each family's check merges under its own key of the JSON (``--key``, the
family's name by default) and writes ``task_fidelity_<key>.md`` and ``.png``;
give each check its own ``--work``.

The level with the most samples is the reference, the next the label signal's
second estimate. A *reduced* check, e.g. ``--levels 1x,0.25x`` on a machine
that cannot afford 16x, has the plan itself as the reference: its verdict says
whether the cheaper level moves the task figures from the plan's (so whether the
plan could be cheaper), not whether the plan has converged; the plan's own
noise is then measured against the cheaper level, its share of their
difference's power taken by samples (1/samples). The JSON's
``<family>.check_scope`` records the levels, reference, episodes and seeds, and
says so. ``--seeds``, ``--replicate-seeds`` and ``--episodes`` cut it further.
The checks sized for a 2-core machine (3 and 3 seeds, 2 training, 2 validation
and 2 test episodes; the plan's episodes copied from the design protocol's, the
others rendered), as kept in ``benchmarks/results/task_fidelity.json``::

    python benchmarks/bench_task_fidelity.py --work /work/tf38 \
        --sections render,check --levels 0.25x,4x --one-x /work/episodes/ws8 \
        --seeds 3 --replicate-seeds 3 --episodes 2,2,2 --lock /tmp/mincam-cpu.lock
    python benchmarks/bench_task_fidelity.py --work /work/tf38-light --family lighting \
        --sections render,check --levels 0.25x,4x --one-x /work/episodes/light \
        --seeds 3 --replicate-seeds 3 --episodes 2,2,2 --lock /tmp/mincam-cpu.lock
    python benchmarks/bench_task_fidelity.py --work /work/tf38-patches --family patches \
        --sections render,check --levels 0.25x,4x --one-x /work/episodes/patches \
        --seeds 3 --replicate-seeds 3 --episodes 2,2,2 --lock /tmp/mincam-cpu.lock
    python benchmarks/bench_task_fidelity.py --work /work/tf38-traffic --family traffic \
        --sections render,check --levels 1x,4x --cross 1x:4x,4x:1x \
        --one-x /work/protocol-traffic/episodes --seeds 3 --replicate-seeds 3 \
        --episodes 2,2,2 --train-workers 2 --lock /tmp/mincam-cpu.lock

(traffic without 0.25x, its 32x32 runs taking 10-16 minutes each) and the
workspace's reduced check at the learning curves' size (32 training, 4
validation and 10 test episodes, the plan as the reference; 4x renders of the
test episodes alone)::

    python benchmarks/bench_task_fidelity.py --work /work/tf38-full --key workspace-32 \
        --sections render,check --levels 1x,0.25x,0.25x-frame-seeds \
        --cross 0.25x:1x,1x:0.25x,1x:4x \
        --one-x /work/episodes/ws8 --seeds 3 --replicate-seeds 3 --episodes 32,4,10 \
        --lock /tmp/mincam-cpu.lock

and the workspace trained and tested at 4x (16 training episodes; ``WORK/ws-1x``
and ``WORK/ws-4x`` linked to the 32-episode check's, so only the 4x training
and validation episodes render), both levels' runs also tested on 16x renders
of the test episodes (a test level: render noise in the 4x test data, and the
4x level's own noise against 16x)::

    python benchmarks/bench_task_fidelity.py --work /work/tf38-16 --key workspace-16 \
        --sections render,check --levels 1x,4x --cross 1x:4x,4x:16x,1x:16x \
        --seeds 3 --replicate-seeds 3 --episodes 16,4,10 --lock /tmp/mincam-cpu.lock

Writes ``benchmarks/results/task_fidelity.json`` (per family: label-signal RMS,
render noise at the plan for random masks and the finest box pixel, their
ratio, the chosen target, the noise's autocorrelation, the check per design
and level, verdicts; a ``machine`` block), ``task_fidelity_<family>.md`` and
``task_fidelity_<family>.png`` (measurement error and task error against
render seconds per frame). Training runs are kept in ``WORK/runs`` (resumable).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import fcntl
import json
import logging
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from provenance import machine, write_result

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mincam_render.render.differential import DifferenceSeeds  # noqa: E402
from mincam_render.studies.task_fidelity import (  # noqa: E402
    SampleLevel,
    TaskFidelityConfig,
    render_level,
    run,
    write_report,
)

RESULTS = Path(__file__).parent / "results"
SCENES = Path(__file__).resolve().parents[1] / "scenes"
#: ``(name, samples factor, path depth (None: the plan's), seeds)`` of each level.
LEVELS = (
    ("1x", 1.0, None, DifferenceSeeds.WINDOW),
    ("0.0625x", 0.0625, 16, DifferenceSeeds.WINDOW),
    ("0.25x", 0.25, 16, DifferenceSeeds.WINDOW),
    ("4x", 4.0, 16, DifferenceSeeds.WINDOW),
    ("16x", 16.0, 16, DifferenceSeeds.WINDOW),
    ("1x-frame-seeds", 1.0, None, DifferenceSeeds.FRAME),
    ("0.25x-frame-seeds", 0.25, 16, DifferenceSeeds.FRAME),
)
#: The plan each family is measured with for ``plans``: its study's episode length.
PLAN_REQUESTS: dict[str, dict[str, Any]] = {
    "workspace": {"family": "workspace", "num_frames": 1200, "overrides": {"fps": 2.0}},
    "lighting": {"family": str(SCENES / "lighting_toggling.toml"), "num_frames": 3600},
    "patches": {
        "family": "patches",
        "num_frames": 3000,
        "overrides": {"camera": {"detectors": 16}},
    },
    "traffic": {"family": "traffic", "num_frames": 1800},
    # traffic's plan at 1 % of the total, as it planned before its frame steps
    # (its figures against the steps' signal)
    "traffic-total": {"family": "traffic", "num_frames": 1800, "error_scale": "frame"},
}
#: The families the task-level check runs on: ``(episode directory prefix,
#: ComparisonConfig fields)``; the design protocol's episode sizes and task.
CHECKED: dict[str, tuple[str, dict[str, Any]]] = {
    "workspace": ("ws", {}),
    "lighting": (
        "light",
        {
            "family": str(SCENES / "lighting_toggling.toml"),
            "fps": 30.0,
            "train_frames": 3600,
            "val_frames": 1800,
            "test_frames": 1800,
            "tasks": ("lights",),
        },
    ),
    "patches": (
        "patches",
        {
            "family": "patches",
            "overrides": {"camera": {"detectors": 16}},
            "train_frames": 3000,
            "val_frames": 1000,
            "test_frames": 1000,
            "tasks": ("count",),
        },
    ),
    "traffic": (
        "traffic",
        {
            "family": "traffic",
            "fps": 30.0,
            "train_frames": 3600,
            "val_frames": 1800,
            "test_frames": 1800,
            "tasks": ("mean speed",),
        },
    ),
}


def config(
    work: Path,
    names: list[str],
    seeds: int | None = None,
    replicate_seeds: int | None = None,
    episodes: tuple[int, int, int] | None = None,
    family: str = "workspace",
    cross: tuple[tuple[str, str], ...] = (),
) -> TaskFidelityConfig:
    """The check of ``family`` (:data:`CHECKED`) over the named levels (``1x`` always).

    Episodes under ``work``. ``cross``: ``(trained, tested)`` level names; a
    tested level not among ``names`` is a test level (its test episodes only).
    ``seeds`` and ``replicate_seeds``: training seeds per design and of the
    replicate; ``episodes``: ``(train, val, test)`` episode counts, render noise
    measured on the first three test episodes (None: :class:`TaskFidelityConfig`'s:
    8 and 8 seeds, 2, 4 and 3 episodes).
    """
    if family not in CHECKED:
        raise ValueError(f"family {family!r}: the check runs on {sorted(CHECKED)}")
    prefix, fields = CHECKED[family]
    levels, test_levels = [], []
    for name, factor, depth, difference_seeds in LEVELS:
        trained = name == "1x" or name in names
        if not trained and name not in {tested for _, tested in cross}:
            continue
        (levels if trained else test_levels).append(
            SampleLevel(
                name=name,
                factor=factor,
                episodes=work / f"{prefix}-{name}",
                max_depth=depth,
                difference_seeds=difference_seeds,
                planned=name == "1x",
            )
        )
    # the most samples judge the rest; the next most give the signal's second estimate
    ranked = sorted(
        (lv for lv in levels if lv.difference_seeds is DifferenceSeeds.WINDOW),
        key=lambda lv: -lv.factor,
    )
    second = ranked[1].name if len(ranked) > 1 else None
    cfg = TaskFidelityConfig(
        levels=tuple(levels),
        reference=ranked[0].name,
        second_reference=second,
        test_levels=tuple(test_levels),
        cross=cross,
    )
    cfg = dataclasses.replace(cfg, comparison=dataclasses.replace(cfg.comparison, **fields))
    if seeds is not None:
        cfg = dataclasses.replace(cfg, comparison=dataclasses.replace(cfg.comparison, seeds=seeds))
    if replicate_seeds is not None:
        cfg = dataclasses.replace(cfg, replicate_seeds=replicate_seeds)
    if episodes is not None:
        train, val, test = episodes
        comparison = dataclasses.replace(
            cfg.comparison, train_episodes=train, val_episodes=val, test_episodes=test
        )
        cfg = dataclasses.replace(
            cfg,
            comparison=comparison,
            noise_episodes=tuple(f"test-{i}" for i in range(min(test, 3))),
        )
    return cfg


def scope(cfg: TaskFidelityConfig) -> dict[str, Any]:
    """What the check ran, and what its verdicts can say (a reduced check says so)."""
    full = {name for name, *_ in LEVELS} <= {lv.name for lv in cfg.levels}
    c = cfg.comparison
    out: dict[str, Any] = {
        "full": full,
        "levels": [lv.name for lv in cfg.levels],
        "reference": cfg.reference,
        "second_reference": cfg.second_reference,
        "episodes": {
            "train": [c.train_episodes, c.train_frames],
            "val": [c.val_episodes, c.val_frames],
            "test": [c.test_episodes, c.test_frames],
        },
        "seeds": c.seeds,
        "replicate_seeds": cfg.replicate_seeds,
        "designs": [d.name for d in c.designs],
        "test_levels": [lv.name for lv in cfg.test_levels],
        "cross": [list(pair) for pair in cfg.cross],
    }
    if cfg.reference == cfg.plan.name:
        out["reduced"] = (
            f"no level above the plan: every level is judged against the plan "
            f"({cfg.reference}), so a verdict says whether that level moves the task "
            f"figures from the plan's, not whether the plan has converged; the plan's "
            f"render noise is measured against {cfg.second_reference}, its share of "
            f"their difference's power taken by samples (1/samples)"
        )
    return out


@contextlib.contextmanager
def holding(lock: Path | None) -> Iterator[None]:
    """Hold an exclusive lock on ``lock`` (a machine's CPUs) while inside; nothing if None."""
    if lock is None:
        yield
        return
    with open(lock, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def render(cfg: TaskFidelityConfig, one_x: Path | None, lock: Path | None) -> None:
    """Copy the check's episodes of the plan from ``one_x`` (if given), render the rest.

    ``one_x`` is only read: the episodes the check uses are copied and taken as
    rendered (the check verifies them as it reads them), so nothing is written there.
    """
    from mincam_render.studies.task_fidelity.study import episode_names

    for level in (*cfg.levels, *cfg.test_levels):
        if level.planned and one_x is not None:
            for name in episode_names(cfg):
                src, dst = one_x / name, level.episodes / name
                if not src.is_dir():
                    raise FileNotFoundError(f"--one-x {one_x}: no episode {name} to copy")
                if not dst.exists():
                    shutil.copytree(src, dst)
            continue
        render_level(cfg, level, hold=lambda: holding(lock))


def summary(result: dict[str, Any], cfg: TaskFidelityConfig) -> dict[str, Any]:
    """The done-when figures of the check: signal, noise at the plan, ratio, lags, verdicts."""
    plan = next(lv for lv in result["levels"] if lv["level"] == cfg.plan.name)
    noise = plan["noise"]
    chosen = result["chosen"]
    chosen_noise = next((lv["noise"] for lv in result["levels"] if lv["level"] == chosen), None)
    kinds = {"random_masks": "random_masks", "finest_box": "box_1"}
    return {
        "label_signal_rms_w": {k: noise["signal_rms_w"][v] for k, v in kinds.items()},
        "render_noise_rms_at_plan_w": {k: noise["error_rms_w"][v] for k, v in kinds.items()},
        "noise_over_signal_at_plan": {
            k: noise["error_rms_w"][v] / noise["signal_rms_w"][v] for k, v in kinds.items()
        },
        "step_noise_over_step_signal_at_plan": {
            k: noise["step_error_rms_w"][v] / noise["step_signal_rms_w"][v]
            for k, v in kinds.items()
        },
        "noise_autocorrelation_at_plan": noise["autocorrelation"]["random_masks"],
        "window_frames": noise["window_frames"],
        "chosen_level": chosen,
        "chosen_signal_target_error": None
        if chosen_noise is None
        else chosen_noise["error_rms_w"]["random_masks"]
        / chosen_noise["signal_rms_w"]["random_masks"],
        "task_check": {
            lv["level"]: {
                d: {"error": f["error"], "ci95": f["ci95"]} for d, f in lv["designs"].items()
            }
            for lv in result["levels"]
        },
        "verdicts": result["verdicts"],
    }


def plans(families: list[str], lock: Path | None) -> dict[str, Any]:
    """Each family's plan, measured afresh, with its figures in both metrics."""
    from mincam_render.data.render_job import RenderRequest, plan_render

    out = {}
    for name in families:
        with holding(lock):
            manifest = plan_render(RenderRequest(**PLAN_REQUESTS[name]), use_cache=False)
        decisions = manifest["fidelity"]
        out[name] = {
            "request": PLAN_REQUESTS[name],
            "settings": manifest["job"]["render"],
            "achieved": decisions.get("achieved"),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, required=True, help="episodes and runs (resumable)")
    ap.add_argument("--sections", default="render,check,plans")
    ap.add_argument("--levels", default=",".join(name for name, *_ in LEVELS))
    ap.add_argument("--one-x", type=Path, default=None, help="the plan's rendered episodes")
    ap.add_argument("--lock", type=Path, default=None, help="a CPU lock held per episode")
    ap.add_argument("--family", default="workspace", choices=sorted(CHECKED),
                    help="the family of render and check")  # fmt: skip
    ap.add_argument("--families", default=",".join(PLAN_REQUESTS), help="the plans'")
    ap.add_argument("--train-workers", type=int, default=1)
    ap.add_argument("--seeds", type=int, default=None, help="training seeds per design (8)")
    ap.add_argument("--replicate-seeds", type=int, default=None, help="the replicate's (8)")
    ap.add_argument("--episodes", default=None, help="TRAIN,VAL,TEST episode counts (2,4,3)")
    ap.add_argument("--cross", default="",
                    help="TRAINED:TESTED level pairs, e.g. 0.25x:1x,1x:4x")  # fmt: skip
    ap.add_argument("--key", default=None,
                    help="the check's entry in the JSON and its report's name (--family)")  # fmt: skip
    ap.add_argument("--out", type=Path, default=RESULTS / "task_fidelity.json")
    args = ap.parse_args()
    key = args.key or args.family
    logging.basicConfig(level=logging.WARNING)
    sections = [s.strip() for s in args.sections.split(",") if s.strip()]
    episodes = None
    if args.episodes is not None:
        train, val, test = map(int, args.episodes.split(","))
        episodes = (train, val, test)
    pairs = [pair.strip() for pair in args.cross.split(",") if pair.strip()]
    if any(":" not in pair for pair in pairs):
        ap.error(f"--cross {args.cross!r}: give TRAINED:TESTED level pairs, e.g. 0.25x:1x")
    cross = tuple((a.strip(), b.strip()) for a, _, b in (p.partition(":") for p in pairs))
    cfg = config(args.work, args.levels.split(","), args.seeds, args.replicate_seeds, episodes,
                 args.family, cross)  # fmt: skip
    merged = json.loads(args.out.read_text()) if args.out.is_file() else {}
    if "render" in sections:
        render(cfg, args.one_x, args.lock)
    if "check" in sections:
        result = run(cfg, args.work / "runs", train_workers=args.train_workers,
                     hold=lambda: holding(args.lock), progress=True)  # fmt: skip
        paths = write_report(result, args.out.parent, stem=f"{args.out.stem}_{key}")
        print(paths["md"].read_text())
        entry = result.as_json()
        merged.setdefault(key, {})
        merged[key] |= {"check": entry, "check_scope": scope(cfg), **summary(entry, cfg)}
    if "plans" in sections:
        for name, record in plans(args.families.split(","), args.lock).items():
            merged.setdefault(name, {})["plan"] = record
    merged["machine"] = machine()
    merged["command"] = " ".join(["python", *sys.argv])
    # sections and families run one at a time merge here: keep every run's command
    merged["commands"] = list(dict.fromkeys([*merged.get("commands", []), merged["command"]]))
    write_result(args.out, merged)


if __name__ == "__main__":
    main()
