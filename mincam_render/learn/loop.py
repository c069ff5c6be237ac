r"""The training loop: Adam on the task loss, evaluation, early stopping, checkpoints, logs.

The paper's recipe (Sec. 5, supplement C) with these choices of ours, all in
:class:`TrainConfig`:

* Adam; the head's learning rate follows the number of head inputs ``n``
  (pixels x time steps): ``lr = 1e-3 * min(1, sqrt(16 / n))`` -- 1e-3 up to 16
  inputs, then falling as ``1/sqrt(n)`` so that a 32x32 baseline (1024 inputs)
  trains at 1.25e-4 (the first layer's output moves ~sqrt(n) times faster with
  Adam's per-weight steps). The mask logits use their own rate
  (``mask_lr``, logit units per step).
* A random global gain U(0.8, 1.2) per sample multiplies the light (augmentation).
* COUNT labels are regressed (MSE) or classified (cross-entropy over the counts
  ``0 .. max``, predicting the expected count), :class:`~mincam_render.learn.models.CountLoss`;
  by default the paper's choice for the scene family
  (:data:`~mincam_render.learn.builders.PAPER_COUNT_LOSS`).
* Learning-rate decay on plateaus, then early stopping, on the validation loss
  (evaluated every ``eval_every`` steps): after ``patience`` evaluations without
  improvement every learning rate is multiplied by ``lr_decay``, up to
  ``lr_decays`` times; the next plateau stops the run. The best state is kept.
  Robust training (``perturbation``) validates by default under a fixed set of
  built cameras (``robust_validation_draws``, drawn once from the seed): the
  validation loss is their mean, and the history also records the nominal
  camera's (``val_loss_nominal``). The head's input norm then standardises by
  its running statistics in training too
  (:class:`~mincam_render.learn.models.InputNorm`): a batch is measured through
  one built camera, and normalising it by its own statistics would remove that
  camera's per-pixel gain and offset errors for free.
* Checkpoints after every evaluation (atomic ``checkpoint.pt``,
  :mod:`~mincam_render.learn.checkpoint`): a killed run started again with the
  same arguments resumes from it and reaches the same state as an
  uninterrupted run (random generator states are saved too).
* Logs: TensorBoard event files through ``torch.utils.tensorboard`` (training
  loss, validation loss and error against the step; each event's wall time is
  the run's training time, so TensorBoard's "relative" axis shows loss against
  training time across resumes), ``history.jsonl``
  (:mod:`~mincam_render.learn.run_log`), and ``mask_evolution.png``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from mincam_render.core.seeds import stream_seed
from mincam_render.learn.batches import DatasetBatches, RenderedBatches
from mincam_render.learn.checkpoint import TrainingState, restore_checkpoint, save_checkpoint
from mincam_render.learn.evaluation import pooled_validation
from mincam_render.learn.models import MincamCamera, Model
from mincam_render.learn.run_log import RunLog, TrainingClock
from mincam_render.learn.snapshots import mask_snapshot, plot_mask_evolution
from mincam_render.learn.step import build_optimizer, train_step, validation_draws
from mincam_render.learn.train_config import TrainConfig
from mincam_render.learn.training_data import TrainingData
from mincam_render.optics.perturbation import PerturbationDraw

log = logging.getLogger(__name__)


@dataclass
class TrainResult:
    """Outcome of :func:`train_model`."""

    steps: int
    best_step: int
    best_val_loss: float
    stopped_early: bool
    wall_time_s: float
    history: list[dict[str, float]]
    snapshots: list[tuple[int, np.ndarray]] = field(default_factory=list)


@dataclass
class _Run:
    """What the loop works on: the model, its optimiser, random generator, batches and state."""

    model: Model
    source: DatasetBatches | RenderedBatches
    opt: torch.optim.Optimizer
    gen: torch.Generator
    config: TrainConfig
    ckpt_path: Path | None
    state: TrainingState
    val_draws: list[PerturbationDraw] = field(default_factory=list)

    def done(self) -> bool:
        """Whether training has ended (early stopping or ``max_steps``)."""
        return self.state.stopped_early or self.state.step >= self.config.max_steps

    def save(self) -> None:
        """Write the checkpoint, when the run has a directory."""
        if self.ckpt_path is None:
            return
        args = (self.model, self.config, self.opt, self.gen, self.source, self.state)
        save_checkpoint(self.ckpt_path, *args)


def train_model(
    model: Model,
    train: TrainingData | DatasetBatches | RenderedBatches,
    val: TrainingData | Sequence[TrainingData],
    config: TrainConfig = TrainConfig(),
    *,
    out_dir: str | os.PathLike | None = None,
    resume: bool = True,
    stop_after_steps: int | None = None,
    progress: bool = False,
    desc: str = "train",
    on_progress: Callable[[int], None] | None = None,
) -> TrainResult:
    """Train ``model`` in place with Adam and early stopping on ``val``; keep the best state.

    Args:
        model: a :class:`MincamCamera` or :class:`BaselineCamera`.
        train: a training split, or a batch source (:class:`RenderedBatches` for
            on-the-fly training).
        val: validation episode, or several pooled (:func:`pooled_validation`; loss
            with sensor noise at a fixed seed).
        config: the recipe.
        out_dir: where checkpoints, event files, ``history.jsonl`` and
            ``mask_evolution.png`` go; None keeps everything in memory.
        resume: continue from ``out_dir/checkpoint.pt`` when it exists.
        stop_after_steps: checkpoint and return after this many steps in total
            (simulates a killed run; the result is not final).
        progress: show a tqdm progress bar.
        desc: progress-bar label.
        on_progress: called after every evaluation (and checkpoint) with the
            steps taken since the previous call (a worker's sign of life).

    Returns:
        A :class:`TrainResult`; ``model`` holds the best validation state.

    """
    from tqdm import tqdm

    out = Path(out_dir) if out_dir is not None else None
    run = _start(model, train, config, out, resume)
    logs = RunLog(out, run.state.step, run.state.history)
    if isinstance(model, MincamCamera):
        model.project_logits_()  # e.g. a start with masks pinned at their limits
    bar = tqdm(
        total=config.max_steps,
        initial=run.state.step,
        desc=desc,
        disable=not progress,
        leave=False,
        dynamic_ncols=True,
    )
    model.train()
    clock = TrainingClock.resumed(run.state.elapsed)
    threads = torch.get_num_threads()
    if config.torch_threads is not None:
        torch.set_num_threads(config.torch_threads)
    try:
        episodes = (val,) if isinstance(val, TrainingData) else tuple(val)
        _train_steps(run, episodes, logs, bar, clock, stop_after_steps, on_progress)
    finally:
        torch.set_num_threads(threads)
        bar.close()
        logs.close()
    # the training time as of its last evaluation or checkpoint: a finished run read back
    # (resumed at its end) reports the same figures as when it finished
    return _finish(run, run.state.elapsed, out)


def _start(
    model: Model,
    train: TrainingData | DatasetBatches | RenderedBatches,
    config: TrainConfig,
    out: Path | None,
    resume: bool,
) -> _Run:
    """The run's optimiser, generator and batches, resumed from its checkpoint if there is one."""
    source = DatasetBatches(train, config.batch_size) if isinstance(train, TrainingData) else train
    opt = build_optimizer(model, config)
    gen = torch.Generator().manual_seed(stream_seed(config.seed, "train/batches"))
    ckpt_path = out / "checkpoint.pt" if out is not None else None
    if ckpt_path is not None and resume and ckpt_path.is_file():
        state = restore_checkpoint(ckpt_path, model, opt, gen, source)
        log.info(
            "resumed %s at step %d (best val loss %.4g)", ckpt_path, state.step, state.best_loss
        )
    else:
        state = TrainingState(best_state=_copy_state(model))
        if (first := mask_snapshot(model)) is not None:
            state.snapshots.append((0, first))
    return _Run(model, source, opt, gen, config, ckpt_path, state, validation_draws(model, config))


def _train_steps(
    run: _Run,
    val: Sequence[TrainingData],
    logs: RunLog,
    bar: Any,
    clock: TrainingClock,
    stop_after_steps: int | None,
    on_progress: Callable[[int], None] | None,
) -> None:
    """Steps until the run is done, or checkpoint and return after ``stop_after_steps``."""
    st, config = run.state, run.config
    reported = st.step
    while not run.done():
        loss = train_step(
            run.model, run.source, run.opt, run.gen, config.gain_range, config.perturbation,
            config.privacy_weight, transport_noise=config.transport_noise,
            mask_tv_weight=config.mask_tv_weight, mask_logit_decay=config.mask_logit_decay,
        )  # fmt: skip
        st.step += 1
        bar.update(1)
        logs.train_loss(loss, st.step, clock)
        if st.step % config.eval_every == 0 or st.step >= config.max_steps:
            _evaluate(run, val, loss, logs, clock)
            bar.set_postfix(val=f"{st.history[-1]['val_loss']:.4g}", best=f"{st.best_loss:.4g}")
            run.save()
            if on_progress is not None:
                on_progress(st.step - reported)
                reported = st.step
        if stop_after_steps is not None and st.step >= stop_after_steps and not run.done():
            st.elapsed = clock.elapsed()
            run.save()
            break


def _evaluate(
    run: _Run,
    val: Sequence[TrainingData],
    loss: torch.Tensor,
    logs: RunLog,
    clock: TrainingClock,
) -> None:
    """Validation after a step: history, mask snapshot, logs, best state, early stopping.

    The validation loss pools every validation episode (:func:`pooled_validation`);
    under robust validation it is the mean over the fixed built cameras.
    """
    st = run.state
    pooled = pooled_validation(
        run.model, val, limit=run.config.max_eval_samples, draws=run.val_draws
    )
    rec = {"step": st.step, "train_loss": loss.item(), "val_loss": pooled["loss"]}
    if "loss_nominal" in pooled:
        rec["val_loss_nominal"] = pooled["loss_nominal"]
    rec["val_error"] = pooled["error"]
    val_loss = rec["val_loss"]
    st.elapsed = rec["wall_time_s"] = clock.elapsed()
    st.history.append(rec)
    snap = mask_snapshot(run.model)
    if snap is not None:
        st.snapshots.append((st.step, snap))
    logs.evaluation(rec, clock.wall_start + st.elapsed)
    if val_loss < st.best_loss:
        st.best_loss, st.best_step, st.bad = val_loss, st.step, 0
        st.best_state = _copy_state(run.model)
    else:
        st.bad += 1
    if st.bad < run.config.patience:
        return
    if st.lr_decays < run.config.lr_decays:
        _decay_learning_rate(run)
    else:
        st.stopped_early = True


def _decay_learning_rate(run: _Run) -> None:
    """A plateau: every learning rate times ``lr_decay``; the patience count starts again."""
    st = run.state
    for group in run.opt.param_groups:
        group["lr"] *= run.config.lr_decay
    st.lr_decays += 1
    st.bad = 0
    log.info(
        "step %d: validation loss flat for %d evaluations; learning rates x %g (decay %d of %d)",
        st.step, run.config.patience, run.config.lr_decay, st.lr_decays, run.config.lr_decays,
    )  # fmt: skip


def _finish(run: _Run, elapsed: float, out: Path | None) -> TrainResult:
    """The result; a finished run's model is set to its best state and its masks plotted."""
    st = run.state
    if run.done():
        run.model.load_state_dict(st.best_state)
        if out is not None and st.snapshots:
            plot_mask_evolution(st.snapshots, out / "mask_evolution.png")
    return TrainResult(
        steps=st.step,
        best_step=st.best_step,
        best_val_loss=st.best_loss,
        stopped_early=st.stopped_early,
        wall_time_s=elapsed,
        history=st.history,
        snapshots=st.snapshots,
    )


def _copy_state(model: Model) -> dict[str, torch.Tensor]:
    """A detached copy of ``model.state_dict()`` (torch)."""
    return {k: v.detach().clone() for k, v in model.state_dict().items()}
