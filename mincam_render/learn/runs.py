"""Training runs: one camera trained into a run directory, and what it leaves there.

:func:`train_run` writes ``run.json`` (what was trained on what, with which
recipe), trains resumably (:func:`~mincam_render.learn.loop.train_model`) and
writes ``metrics.json``; :func:`load_run`, :func:`load_mincam` and :func:`run_masks` read a
finished run.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch

from mincam_render.data.dataset import label_spec_to_dict
from mincam_render.learn.batches import RenderedBatches
from mincam_render.learn.builders import build_baseline, build_head, build_mincam, describe_model
from mincam_render.learn.checkpoint import load_checkpoint
from mincam_render.learn.evaluation import evaluate
from mincam_render.learn.loop import TrainResult, train_model
from mincam_render.learn.models import MincamCamera, Model
from mincam_render.learn.reference_masks import set_reference_masks
from mincam_render.learn.train_config import HeadKind, MaskReference, TrainConfig
from mincam_render.learn.training_data import TrainingData
from mincam_render.optics.camera import FreeformCamera


def train_run(
    train: TrainingData,
    val: TrainingData | Sequence[TrainingData] | Mapping[str, TrainingData],
    test: TrainingData | None,
    out_dir: str | os.PathLike,
    *,
    pixels: int | None = None,
    baseline_grid: tuple[int, int] | None = None,
    sensor_model: bool = True,
    config: TrainConfig = TrainConfig(),
    on_the_fly: RenderedBatches | None = None,
    episodes: Mapping[str, TrainingData] | None = None,
    frozen_masks_from: str | os.PathLike | None = None,
    reference: MaskReference | None = None,
    tune_reference: bool = False,
    resume: bool = True,
    progress: bool = False,
    on_progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Train one camera into ``out_dir`` (resumable) and write ``run.json`` + ``metrics.json``.

    A minimalist camera of ``pixels`` pixels unless ``baseline_grid`` is given.
    ``val``: the validation episode, or several pooled for early stopping; named
    ones (a mapping) are also evaluated one by one after training
    (``metrics["validation_episodes"][name]``).
    ``on_the_fly`` replaces ``train`` as the source of training batches (``train``
    still provides target statistics and the baseline exposure). ``episodes``:
    test episodes evaluated one by one (``metrics["episodes"][name]``), beside
    ``test``; the metrics also hold the validation ``history``.
    ``frozen_masks_from``: a finished minimalist run whose masks (and detectors)
    this camera takes, frozen; only a fresh head is trained (supplement A: masks
    learned without the detector model, head retrained with it).
    ``reference``: the minimalist camera's masks are that reference's, fitted
    on ``train`` (:mod:`~mincam_render.learn.reference_masks`), frozen; with
    ``tune_reference`` training starts from them instead (end to end).
    ``on_progress``: called after every evaluation with the steps since the last
    call (:func:`~mincam_render.learn.loop.train_model`).
    """
    from mincam_render.data.writer_lock import exclusive_writer

    named = dict(val) if isinstance(val, Mapping) else {}
    episodes_val = list(named.values()) if named else cast(TrainingData | list[TrainingData], val)
    with exclusive_writer(out_dir, "training") as out:
        if frozen_masks_from is not None:
            model: Model = _frozen_mask_camera(train, frozen_masks_from, sensor_model, config)
        else:
            model = _build_model(train, pixels, baseline_grid, sensor_model, config)
        if reference is not None:
            if not isinstance(model, MincamCamera):
                raise ValueError(f"reference masks ({reference}) are a minimalist camera's")
            set_reference_masks(model, reference, train, episodes_val, config, out / "teacher",
                                frozen=not tune_reference)  # fmt: skip
        run = describe_run(model, train, episodes_val, test, config, on_the_fly is not None)
        if frozen_masks_from is not None:
            run["frozen_masks_from"] = str(frozen_masks_from)
        if reference is not None:
            run["reference"] = {"masks": MaskReference(reference).value, "tuned": tune_reference}
        _refuse_other_data(out, run, resume)
        _write_json_atomic(out / "run.json", run)
        res = train_model(
            model,
            on_the_fly if on_the_fly is not None else train,
            episodes_val,
            config,
            out_dir=out,
            resume=resume,
            progress=progress,
            desc=f"{run['model']['kind']} {model.num_pixels} px",
            on_progress=on_progress,
        )
        metrics = _run_metrics(run, res, model, len(train), test, episodes)
        if named:
            metrics["validation_episodes"] = {k: evaluate(model, d) for k, d in named.items()}
        _write_json_atomic(out / "metrics.json", metrics)
        return metrics


def _build_model(
    train: TrainingData,
    pixels: int | None,
    baseline_grid: tuple[int, int] | None,
    sensor_model: bool,
    config: TrainConfig,
) -> Model:
    """A baseline camera of ``baseline_grid``, else a minimalist camera of ``pixels`` pixels.

    With ``config.privacy_weight`` > 0 the minimalist camera carries a
    :class:`~mincam_render.learn.privacy_term.PrivacyAdversary` (``model.adversary``).
    """
    if baseline_grid is not None:
        if config.privacy_weight > 0:
            raise ValueError(
                f"privacy_weight = {config.privacy_weight}: the privacy term trains masks; "
                "a baseline camera has none"
            )
        return build_baseline(
            train, baseline_grid, count_loss=config.count_loss, seed=config.seed, head=config.head
        )
    model = build_mincam(
        train,
        pixels,
        sensor_model=sensor_model,
        count_loss=config.count_loss,
        seed=config.seed,
        head=config.head,
        mask_block=config.mask_block,
    )
    if config.privacy_weight > 0:
        attach_adversary(model, seed=config.seed)
    return model


def attach_adversary(model: MincamCamera, *, seed: int) -> None:
    """Give ``model`` a privacy adversary (``model.adversary``, saved in its state).

    Raises:
        ValueError: a temporal camera (the term reconstructs single frames).
    """
    from mincam_render.learn.privacy_term import ADVERSARY_GRID, PrivacyAdversary

    if model.history != 1:
        raise ValueError(
            f"privacy_weight: a camera with a history of {model.history} frames; the privacy "
            "term is for static tasks"
        )
    grid = min(ADVERSARY_GRID, *model.camera.mask_resolution)
    model.adversary = PrivacyAdversary(model.num_pixels, grid=grid, seed=seed)


def _frozen_mask_camera(
    train: TrainingData, source: str | os.PathLike, sensor_model: bool, config: TrainConfig
) -> MincamCamera:
    """A minimalist camera with the masks of finished run ``source``, frozen, and a fresh head."""
    run, state = load_run(source)
    if run["model"]["kind"] != "mincam":
        raise ValueError(f"{source}: a {run['model']['kind']} run has no masks to freeze")
    model = build_mincam(
        train,
        detectors=run["model"]["detectors"],
        sensor_model=sensor_model,
        count_loss=config.count_loss,
        seed=config.seed,
    )
    with torch.no_grad():
        model.logits.copy_(state["logits"])
    model.logits.requires_grad_(False)
    return model


def describe_run(
    model: Model,
    train: TrainingData,
    val: TrainingData | Sequence[TrainingData],
    test: TrainingData | None,
    config: TrainConfig,
    on_the_fly: bool,
) -> dict[str, Any]:
    """``run.json``: the model, camera, data provenance, recipe and labels of a run.

    ``data.val`` is the validation episode's provenance, or a list of them.
    """
    vals = [val] if isinstance(val, TrainingData) else list(val)
    return {
        "model": describe_model(model),
        "camera": _camera_dict(train.camera),
        "data": {
            "train": train.source,
            "val": vals[0].source if len(vals) == 1 else [v.source for v in vals],
            "test": test.source if test is not None else None,
            "train_samples": len(train),
            "on_the_fly": on_the_fly,
        },
        "config": config_record(config),
        "fps": train.fps,
        "history": train.history,
        "label_specs": [label_spec_to_dict(s) for s in train.label_specs],
    }


def _run_metrics(
    run: Mapping[str, Any],
    res: TrainResult,
    model: Model,
    train_samples: int,
    test: TrainingData | None,
    episodes: Mapping[str, TrainingData] | None,
) -> dict[str, Any]:
    """``metrics.json``: the training's outcome, test metrics, per-episode metrics, history."""
    return {
        "model": run["model"],
        "steps": res.steps,
        "best_step": res.best_step,
        "best_val_loss": res.best_val_loss,
        "stopped_early": res.stopped_early,
        "train_wall_time_s": res.wall_time_s,
        "train_samples": train_samples,
        "test": evaluate(model, test) if test is not None else None,
        "episodes": {k: evaluate(model, d) for k, d in (episodes or {}).items()},
        "history": res.history,
    }


def config_record(config: TrainConfig) -> dict[str, Any]:
    """``run.json``'s recipe: the fields of ``config``, the optional ones only when used.

    ``head`` appears only when not the paper's MLP, ``perturbation`` and
    ``robust_validation_draws`` only when training is robust, ``privacy_weight``
    and the masks' priors and the transport noise only when not 0, ``mask_block``
    only above 1. Runs written before any was a choice then resume (their recipe
    compares equal).
    """
    record = asdict(config)
    for name in ("mask_tv_weight", "mask_logit_decay", "transport_noise"):
        if not record[name]:
            del record[name]
    if config.mask_block == 1:
        del record["mask_block"]
    if config.perturbation is None:
        del record["perturbation"], record["robust_validation_draws"]
    if not config.privacy_weight:
        del record["privacy_weight"]
    if config.head is HeadKind.MLP:
        del record["head"]
    else:
        record["head"] = config.head.value
    return record


def _refuse_other_data(out: Path, run: Mapping[str, Any], resume: bool) -> None:
    """A run resumed on other data or another recipe would mix two trainings: refuse it."""
    path, ckpt = out / "run.json", out / "checkpoint.pt"
    if not (resume and path.is_file() and ckpt.is_file()):
        return
    try:
        old = json.loads(path.read_text())
    except ValueError:
        return  # a damaged run.json is rewritten; the checkpoint check still applies
    new = json.loads(json.dumps(run, default=str))
    for key in ("data", "config"):
        if old.get(key) != new[key]:
            raise ValueError(
                f"{out} was trained with another {key} (see {path}); use another --out, "
                "delete it, or train with --no-resume"
            )


def _write_json_atomic(path: Path, obj: Any) -> None:
    from mincam_render.data.dataset import atomic_write_bytes

    atomic_write_bytes(path, (json.dumps(obj, indent=2, default=str) + "\n").encode())


def _camera_dict(camera: FreeformCamera) -> dict[str, Any]:
    return json.loads(json.dumps(camera.to_dict(), default=lambda o: getattr(o, "value", str(o))))


def load_run(run_dir: str | os.PathLike) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """``(run.json contents, best model state)`` of a finished :func:`train_run`."""
    run_dir = Path(run_dir)
    run_path, ckpt_path = run_dir / "run.json", run_dir / "checkpoint.pt"
    if not run_path.is_file() or not ckpt_path.is_file():
        raise ValueError(f"{run_dir}: not a training run (needs run.json and checkpoint.pt)")
    try:
        run = json.loads(run_path.read_text())
    except ValueError:
        raise ValueError(f"{run_path}: not valid JSON (truncated?)") from None
    ck = load_checkpoint(ckpt_path)
    return run, ck["best_state"]


def run_masks(run_dir: str | os.PathLike) -> tuple[np.ndarray, FreeformCamera, dict[str, Any]]:
    """Trained transmittance ``M[pixel, row, col]``, camera and run info of a mincam run."""
    from mincam_render.data.dataset import camera_from_dict
    from mincam_render.optics.maskplane import transmittance

    run, state = load_run(run_dir)
    if run["model"]["kind"] != "mincam":
        raise ValueError(f"{run_dir}: a {run['model']['kind']} run has no masks to export")
    camera = camera_from_dict(run["camera"])
    with torch.no_grad():
        m = transmittance(state["logits"], camera.transmittance_range).numpy()
    return m, camera, run


def load_mincam(run_dir: str | os.PathLike, data: TrainingData) -> MincamCamera:
    """The trained minimalist camera of a finished run, to be measured on ``data``.

    Built from the run's own camera, detectors, head (with its count classes) and
    weights; ``data`` must have the run's mask resolution and enough detectors.

    Raises:
        ValueError: not a minimalist-camera run, or ``data`` does not fit it.
    """
    from mincam_render.data.dataset import camera_from_dict

    run, state = load_run(run_dir)
    desc = run["model"]
    if desc["kind"] != "mincam":
        raise ValueError(f"{run_dir}: a {desc['kind']} run is not a minimalist camera")
    camera = camera_from_dict(run["camera"])
    if data.camera.mask_resolution != camera.mask_resolution:
        raise ValueError(
            f"{run_dir}: masks of {camera.mask_resolution} texels, but the data's transport "
            f"has {data.camera.mask_resolution}"
        )
    if max(desc["detectors"]) >= data.transport.shape[1]:
        raise ValueError(
            f"{run_dir}: reads detectors {desc['detectors']}; the data has "
            f"{data.transport.shape[1]}"
        )
    head = build_head(
        data,
        len(desc["detectors"]) * max(desc["history"] - 1, 1),
        count_classes=desc.get("count_classes"),
    )
    model = MincamCamera(
        camera,
        head,
        detectors=desc["detectors"],
        sensor_model=desc["sensor_model"],
        history=desc["history"],
        mask_block=desc.get("mask_block", 1),
    )
    # a privacy-trained run's adversary is not part of the camera that is measured
    model.load_state_dict({k: v for k, v in state.items() if not k.startswith("adversary.")})
    model.eval()
    return model
