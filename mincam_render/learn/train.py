"""End-to-end training of minimalist and baseline cameras: the training API in one namespace.

Re-exports the names that the command line, the studies, the benchmarks and the
tests use (``from mincam_render.learn import train as tr``); each concept lives
in its own module:

* :mod:`~mincam_render.learn.training_data` -- a split of transport images and
  labels, its samples and batches (:class:`TrainingData`, :class:`Batch`,
  :class:`GatherBuffer`);
* :mod:`~mincam_render.learn.batches` -- batch sources of the loop
  (:class:`DatasetBatches`, :class:`RenderedBatches` on the fly);
* :mod:`~mincam_render.learn.temporal_head` -- the temporal convolution head
  (:class:`TemporalConvHead`, ``TrainConfig(head=HeadKind.TCN)``);
* :mod:`~mincam_render.learn.builders` -- cameras and heads built for a task,
  the paper's count loss and learning rate, :func:`describe_model`, :func:`pixels_label`;
* :mod:`~mincam_render.learn.evaluation` -- :func:`predict`, the paper's
  :func:`postprocess`, :func:`metrics`, :func:`evaluate`;
* :mod:`~mincam_render.learn.step` -- the optimiser and one :func:`train_step`;
* :mod:`~mincam_render.learn.checkpoint` -- the resumable state, ``checkpoint.pt``;
* :mod:`~mincam_render.learn.run_log` -- TensorBoard events, ``history.jsonl``;
* :mod:`~mincam_render.learn.snapshots` -- mask snapshots, ``mask_evolution.png``;
* :mod:`~mincam_render.learn.loop` -- :func:`train_model` (the recipe);
* :mod:`~mincam_render.learn.runs` -- :func:`train_run` into a run directory;
* :mod:`~mincam_render.learn.restore` -- a run read back (:func:`open_run`), its
  camera (:func:`restore_model`) and masks (:func:`run_masks`), for every kind of run;
* :mod:`~mincam_render.learn.sweep` -- error against pixel count (:func:`sweep`);
* :mod:`~mincam_render.learn.prune` -- supplement C's :func:`greedy_prune`.
"""

from __future__ import annotations

from mincam_render.learn.batches import DatasetBatches, RenderedBatches
from mincam_render.learn.builders import (
    PAPER_COUNT_LOSS,
    build_baseline,
    build_head,
    build_mincam,
    count_classes_for,
    count_loss_for,
    describe_model,
    head_kind,
    learning_rate_for,
    pixels_label,
)
from mincam_render.learn.evaluation import (
    Evaluation,
    Headline,
    LabelMetrics,
    evaluate,
    median_filter,
    median_filter_window,
    metrics,
    postprocess,
    predict,
)
from mincam_render.learn.loop import TrainResult, train_model
from mincam_render.learn.models import (
    BaselineCamera,
    CountLoss,
    Head,
    MincamCamera,
    Model,
    task_loss,
)
from mincam_render.learn.prune import PruneStep, greedy_prune
from mincam_render.learn.restore import (
    ModelKind,
    TrainedRun,
    UnfinishedRunError,
    masks_of,
    open_run,
    restore_mincam,
    restore_model,
    run_finished,
    run_masks,
)
from mincam_render.learn.run_log import LOG_EVERY
from mincam_render.learn.runs import RunMetrics, train_run
from mincam_render.learn.snapshots import plot_mask_evolution
from mincam_render.learn.step import build_optimizer, train_step
from mincam_render.learn.sweep import (
    SweepPoint,
    SweepRow,
    default_pixel_counts,
    plot_sweep,
    sweep,
    sweep_table,
    write_sweep,
)
from mincam_render.learn.temporal_head import TemporalConvHead
from mincam_render.learn.train_config import HeadKind, TrainConfig
from mincam_render.learn.training_data import WIDEN_MAX_BYTES, Batch, GatherBuffer, TrainingData

__all__ = [
    "BaselineCamera",
    "Batch",
    "CountLoss",
    "DatasetBatches",
    "Evaluation",
    "GatherBuffer",
    "Head",
    "HeadKind",
    "Headline",
    "LOG_EVERY",
    "LabelMetrics",
    "MincamCamera",
    "Model",
    "ModelKind",
    "PAPER_COUNT_LOSS",
    "PruneStep",
    "RenderedBatches",
    "RunMetrics",
    "SweepPoint",
    "SweepRow",
    "TemporalConvHead",
    "TrainConfig",
    "TrainResult",
    "TrainedRun",
    "TrainingData",
    "UnfinishedRunError",
    "WIDEN_MAX_BYTES",
    "build_baseline",
    "build_head",
    "build_mincam",
    "build_optimizer",
    "count_classes_for",
    "count_loss_for",
    "default_pixel_counts",
    "describe_model",
    "evaluate",
    "greedy_prune",
    "head_kind",
    "learning_rate_for",
    "masks_of",
    "median_filter",
    "median_filter_window",
    "metrics",
    "open_run",
    "pixels_label",
    "plot_mask_evolution",
    "plot_sweep",
    "postprocess",
    "predict",
    "restore_mincam",
    "restore_model",
    "run_finished",
    "run_masks",
    "sweep",
    "sweep_table",
    "task_loss",
    "train_model",
    "train_run",
    "train_step",
    "write_sweep",
]
