"""Training runs: one camera trained into a run directory, and what it leaves there.

:func:`train_run` writes ``run.json`` (what was trained on what, with which
recipe), trains resumably (:func:`~mincam_render.learn.loop.train_model`) and
writes ``metrics.json`` last (it marks a finished run; :mod:`~mincam_render.learn.restore`
reads runs back). A run is the same run when its data have the same content
(:func:`data_identity`: each dataset's manifest hash, not the path it was given by).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, cast

import torch

from mincam_render.core import strict_json
from mincam_render.core.strict_json import JsonObject
from mincam_render.data.dataset import label_spec_to_dict
from mincam_render.learn.batches import RenderedBatches
from mincam_render.learn.builders import (
    ModelRecord,
    build_baseline,
    build_mincam,
    describe_model,
    pixels_label,
)
from mincam_render.learn.evaluation import Evaluation, evaluate
from mincam_render.learn.loop import TrainResult, train_model
from mincam_render.learn.models import MincamCamera, Model
from mincam_render.learn.reference_masks import set_reference_masks
from mincam_render.learn.restore import FINISHED_MARK, ModelKind, RunRecord, open_run
from mincam_render.learn.train_config import HIDDEN_UNITS, HeadKind, MaskReference, TrainConfig
from mincam_render.learn.training_data import TrainingData
from mincam_render.optics.camera import FreeformCamera


@dataclass(frozen=True, kw_only=True)
class RunMetrics:
    """A finished run's outcome, as its ``metrics.json`` holds it (:func:`train_run`).

    Attributes:
        model: the model's description (``run.json``'s).
        steps: training steps taken.
        best_step: the step of the best validation loss (the state kept).
        best_val_loss: that loss.
        stopped_early: whether early stopping ended the run.
        train_wall_time_s: training's wall time across resumes (s).
        train_samples: samples of the training split.
        test: metrics on the test split, or None without one.
        episodes: metrics on each named test episode.
        history: the validation history (one record per evaluation).
        validation_episodes: metrics on each named validation episode, or None.
    """

    model: ModelRecord
    steps: int
    best_step: int
    best_val_loss: float
    stopped_early: bool
    train_wall_time_s: float
    train_samples: int
    test: Evaluation | None
    episodes: Mapping[str, Evaluation]
    history: Sequence[Mapping[str, float]]
    validation_episodes: Mapping[str, Evaluation] | None = None

    def as_json(self) -> JsonObject:
        """``metrics.json``'s content."""
        out: JsonObject = {
            "model": self.model,
            "steps": self.steps,
            "best_step": self.best_step,
            "best_val_loss": self.best_val_loss,
            "stopped_early": self.stopped_early,
            "train_wall_time_s": self.train_wall_time_s,
            "train_samples": self.train_samples,
            "test": None if self.test is None else self.test.as_json(),
            "episodes": {k: e.as_json() for k, e in self.episodes.items()},
            "history": list(self.history),
        }
        if self.validation_episodes is not None:
            out["validation_episodes"] = {
                k: e.as_json() for k, e in self.validation_episodes.items()
            }
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> RunMetrics:
        """Inverse of :meth:`as_json` (extra keys beside them are ignored)."""
        test, val = d.get("test"), d.get("validation_episodes")
        return cls(
            model=d["model"],
            steps=d["steps"],
            best_step=d["best_step"],
            best_val_loss=d["best_val_loss"],
            stopped_early=d["stopped_early"],
            train_wall_time_s=d["train_wall_time_s"],
            train_samples=d["train_samples"],
            test=None if test is None else Evaluation.from_json(test),
            episodes={k: Evaluation.from_json(e) for k, e in d["episodes"].items()},
            history=d["history"],
            validation_episodes=None
            if val is None
            else {k: Evaluation.from_json(e) for k, e in val.items()},
        )


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
) -> RunMetrics:
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
        if not (resume and (out / "checkpoint.pt").is_file()):
            _remove_training_outputs(out)
        _write_json_atomic(out / "run.json", run)
        res = train_model(
            model,
            on_the_fly if on_the_fly is not None else train,
            episodes_val,
            config,
            out_dir=out,
            resume=resume,
            progress=progress,
            desc=pixels_label(model),
            on_progress=on_progress,
        )
        metrics = _run_metrics(run, res, model, len(train), test, episodes)
        if named:
            validation = {k: evaluate(model, d) for k, d in named.items()}
            metrics = replace(metrics, validation_episodes=validation)
        _write_json_atomic(out / FINISHED_MARK, metrics.as_json())  # last: the run is finished
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
        for name in ("privacy_weight", "signed_pixels"):
            if getattr(config, name):
                raise ValueError(
                    f"{name} = {getattr(config, name)}: an option of freeform pixels; a "
                    "baseline camera has none"
                )
        return build_baseline(train, baseline_grid, **config.head_options())
    model = build_mincam(
        train,
        pixels,
        sensor_model=sensor_model,
        mask_block=config.mask_block,
        signed=config.signed_pixels,
        **config.head_options(),
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
    model.adversary = PrivacyAdversary(model.num_outputs, grid=grid, seed=seed)


def _frozen_mask_camera(
    train: TrainingData, source: str | os.PathLike, sensor_model: bool, config: TrainConfig
) -> MincamCamera:
    """A minimalist camera with the masks of finished run ``source``, frozen, and a fresh head."""
    run = open_run(source)
    run.require(ModelKind.MINCAM, "freezing masks")
    model = build_mincam(
        train,
        detectors=run.record["model"]["detectors"],
        sensor_model=sensor_model,
        signed=bool(run.record["model"].get("signed", False)),
        **config.head_options(),
    )
    with torch.no_grad():
        model.logits.copy_(run.state["logits"])
    model.logits.requires_grad_(False)
    return model


def describe_run(
    model: Model,
    train: TrainingData,
    val: TrainingData | Sequence[TrainingData],
    test: TrainingData | None,
    config: TrainConfig,
    on_the_fly: bool,
) -> RunRecord:
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
    run: RunRecord,
    res: TrainResult,
    model: Model,
    train_samples: int,
    test: TrainingData | None,
    episodes: Mapping[str, TrainingData] | None,
) -> RunMetrics:
    """``metrics.json``: the training's outcome, test metrics, per-episode metrics, history."""
    return RunMetrics(
        model=run["model"],
        steps=res.steps,
        best_step=res.best_step,
        best_val_loss=res.best_val_loss,
        stopped_early=res.stopped_early,
        train_wall_time_s=res.wall_time_s,
        train_samples=train_samples,
        test=evaluate(model, test) if test is not None else None,
        episodes={k: evaluate(model, d) for k, d in (episodes or {}).items()},
        history=res.history,
    )


def config_record(config: TrainConfig) -> JsonObject:
    """``run.json``'s recipe: the fields of ``config``, the optional ones only when used.

    ``head`` appears only when not the paper's MLP, ``head_hidden`` only when not
    the paper's width, ``head_bottleneck`` only when not 0, ``signed_pixels`` only
    when true, ``perturbation`` (in its record's units,
    :meth:`~mincam_render.optics.perturbation.PerturbationModel.to_record`)
    and ``robust_validation_draws`` only when training is robust, ``privacy_weight``
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
    else:  # in the record's units (mm, deg, %, cm), as the options take them
        record["perturbation"] = config.perturbation.to_record()
    if not config.privacy_weight:
        del record["privacy_weight"]
    if config.head_hidden == HIDDEN_UNITS:
        del record["head_hidden"]
    if not config.head_bottleneck:
        del record["head_bottleneck"]
    if not config.signed_pixels:
        del record["signed_pixels"]
    if config.head is HeadKind.MLP:
        del record["head"]
    else:
        record["head"] = config.head.value
    return record


#: What a training writes into its run directory besides ``run.json``; a training that
#: starts afresh removes them first, so nothing of an earlier one is left beside it.
TRAINING_OUTPUTS = ("checkpoint.pt", "history.jsonl", "mask_evolution.png", FINISHED_MARK)
#: TensorBoard's event files (one per start of a training).
EVENT_FILES = "events.out.tfevents.*"


def _remove_training_outputs(out: Path) -> None:
    """Remove an earlier training's outputs from ``out`` (a training starting afresh)."""
    for name in TRAINING_OUTPUTS:
        (out / name).unlink(missing_ok=True)
    for events in out.glob(EVENT_FILES):
        events.unlink()


#: A source's content identity (its dataset's manifest hash), and the path it replaces.
CONTENT_KEY, PATH_KEY = "manifest_sha256", "dataset"


def data_identity(data: Any, *, by_content: bool = True) -> Any:
    """What defines the data of a run (``run.json``'s ``data``), to compare two runs.

    Args:
        data: the record (nested dicts and lists of sources).
        by_content: a source with its dataset's manifest hash is identified by it,
            not by the path its dataset was given by (a moved or re-spelled
            folder is the same data); False: by path, the hashes left out (how
            runs written before sources carried hashes compare).
    """
    if isinstance(data, list):
        return [data_identity(v, by_content=by_content) for v in data]
    if not isinstance(data, dict):
        return data
    drop = PATH_KEY if by_content and data.get(CONTENT_KEY) else CONTENT_KEY
    return {k: data_identity(v, by_content=by_content) for k, v in data.items() if k != drop}


def _has_content(data: Any) -> bool:
    """Whether any source in ``data`` carries its dataset's manifest hash."""
    if isinstance(data, list):
        return any(map(_has_content, data))
    return isinstance(data, dict) and (
        bool(data.get(CONTENT_KEY)) or any(map(_has_content, data.values()))
    )


def _refuse_other_data(out: Path, run: RunRecord, resume: bool) -> None:
    """A run resumed on other data or another recipe would mix two trainings: refuse it."""
    path, ckpt = out / "run.json", out / "checkpoint.pt"
    if not (resume and path.is_file() and ckpt.is_file()):
        return
    try:
        old = json.loads(path.read_text())
    except ValueError:
        return  # a damaged run.json is rewritten; the checkpoint check still applies
    new = json.loads(strict_json.dumps(run))
    # a run written before sources carried their manifest's hash compares by path
    by_content = _has_content(old.get("data"))
    changed = {
        "data": data_identity(old.get("data"), by_content=by_content)
        != data_identity(new["data"], by_content=by_content),
        "config": old.get("config") != new["config"],
    }
    for key, differs in changed.items():
        if differs:
            raise ValueError(
                f"{out} was trained with another {key} (see {path}); use another --out, "
                "delete it, or train with --no-resume"
            )


def _write_json_atomic(path: Path, obj: Any) -> None:
    from mincam_render.data.dataset import atomic_write_bytes

    atomic_write_bytes(path, (strict_json.dumps(obj) + "\n").encode())


def _camera_dict(camera: FreeformCamera) -> JsonObject:
    return json.loads(json.dumps(camera.to_dict(), default=lambda o: getattr(o, "value", str(o))))
