"""The logs of a training run: TensorBoard event files and ``history.jsonl``.

Each event's wall time is the run's training time (:class:`TrainingClock`), so
TensorBoard's "relative" axis shows loss against training time across resumes.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from mincam_render.core import strict_json

#: Steps between training-loss events (their mean): a TensorBoard event per step
#: would cost more than a tenth of a step of a small camera.
LOG_EVERY = 10


def write_history(path: Path, history: list[dict[str, float]]) -> None:
    """``history.jsonl``: one JSON line per evaluation kept in the checkpoint (atomic)."""
    from mincam_render.data.dataset import atomic_write_bytes

    lines = "".join(strict_json.dumps(r, indent=None) + "\n" for r in history)
    atomic_write_bytes(path, lines.encode())


@dataclass(frozen=True)
class TrainingClock:
    """Training time (s) of a run across resumes.

    Args:
        t_start: ``time.perf_counter()`` at which the training time would be 0 (s).
        wall_start: ``time.time()`` at which the training time would be 0 (s since the epoch).

    """

    t_start: float
    wall_start: float

    @classmethod
    def resumed(cls, elapsed: float) -> TrainingClock:
        """A clock that reads ``elapsed`` (s) now."""
        t_start = time.perf_counter() - elapsed
        return cls(t_start, time.time() - elapsed)

    def elapsed(self) -> float:
        """Training time so far (s)."""
        return time.perf_counter() - self.t_start


class RunLog:
    """TensorBoard events and ``history.jsonl`` of a run directory; nothing without one.

    Opening a run directory makes resume exact: events after ``step`` (written
    by a killed run) are purged, and ``history.jsonl`` is cut back to
    ``history``, the checkpoint's evaluations.

    Args:
        out: the run directory (created), or None.
        step: the step the run starts (or resumes) at.
        history: the evaluations recorded before ``step``.

    """

    def __init__(self, out: Path | None, step: int, history: list[dict[str, float]]) -> None:
        self.out = out
        self.writer: Any = None
        if out is not None:
            from torch.utils.tensorboard import SummaryWriter

            out.mkdir(parents=True, exist_ok=True)
            self.writer = SummaryWriter(str(out), purge_step=step if step > 0 else None)
            write_history(out / "history.jsonl", history)
        self.loss_sum, self.loss_n = torch.zeros(()), 0

    def train_loss(self, loss: torch.Tensor, step: int, clock: TrainingClock) -> None:
        """Add a step's loss (torch scalar); every :data:`LOG_EVERY` steps, log their mean."""
        if self.writer is None:
            return
        self.loss_sum += loss
        self.loss_n += 1
        if step % LOG_EVERY == 0:
            wall = clock.wall_start + clock.elapsed()
            self.writer.add_scalar(
                "loss/train", float(self.loss_sum) / self.loss_n, step, walltime=wall
            )
            self.loss_sum.zero_()
            self.loss_n = 0

    def evaluation(self, record: Mapping[str, float], wall: float) -> None:
        """Log an evaluation: validation loss and error events, a ``history.jsonl`` line.

        Args:
            record: the history record (``step``, ``train_loss``, ``val_loss``,
                ``val_error``, ``wall_time_s``; under robust validation also
                ``val_loss_nominal``).
            wall: the events' wall time (s since the epoch).

        """
        if self.writer is None or self.out is None:
            return
        step = int(record["step"])
        self.writer.add_scalar("loss/val", record["val_loss"], step, walltime=wall)
        self.writer.add_scalar("error/val", record["val_error"], step, walltime=wall)
        if "val_loss_nominal" in record:  # robust validation: the design's own loss beside
            self.writer.add_scalar(
                "loss/val_nominal", record["val_loss_nominal"], step, walltime=wall
            )
        self.writer.flush()
        with (self.out / "history.jsonl").open("a") as fh:
            fh.write(strict_json.dumps(record, indent=None) + "\n")

    def close(self) -> None:
        """Close the event file."""
        if self.writer is not None:
            self.writer.close()
