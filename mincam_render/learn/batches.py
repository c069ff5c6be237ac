"""Batch sources of the training loop: random samples of a split, or frames rendered on the fly.

Both have ``next(generator) -> Batch`` and a resumable ``state()`` /
``load_state()`` that a checkpoint stores.
"""

from __future__ import annotations

from typing import Any, TypedDict

import torch

from mincam_render.learn.training_data import Batch, GatherBuffer, TrainingData, render_frames
from mincam_render.optics.camera import FreeformCamera
from mincam_render.render.capabilities import history_frames


class SourceState(TypedDict, total=False):
    """A batch source's resumable state, as a checkpoint stores it.

    Attributes:
        next_frame: the next frame an on-the-fly source renders (absent for a
            split's random samples: they depend only on the generator).
    """

    next_frame: int


class DatasetBatches:
    """Random samples of a :class:`TrainingData` (with replacement), from a torch generator."""

    def __init__(self, data: TrainingData, batch_size: int) -> None:
        self.data = data
        self.batch_size = batch_size
        self._buffer = GatherBuffer()
        self._all_frames = _windows_cover_most_frames(data, batch_size)

    def next(self, generator: torch.Generator) -> Batch:
        """One :class:`Batch` (torch): one random draw and one gather, no per-sample Python.

        The batch's transport lives in a buffer reused by the next call (see
        :class:`GatherBuffer`): use a batch before drawing the next one. When a
        temporal batch's windows are expected to cover most frames, it is
        measured over all stored frames instead (:meth:`TrainingData.sample_all_frames`).
        """
        idx = torch.randint(0, len(self.data), (self.batch_size,), generator=generator)
        if self._all_frames:
            return self.data.sample_all_frames(idx)
        return self.data.sample(idx, self._buffer)

    def state(self) -> SourceState:
        """Resumable state (none: batches depend only on the generator)."""
        return {}

    def load_state(self, state: SourceState) -> None:
        """Restore :meth:`state`."""


def _windows_cover_most_frames(data: TrainingData, batch_size: int) -> bool:
    """Whether ``batch_size`` random windows are expected to cover over half the stored frames.

    Measuring all ``F`` stored frames in place reads them twice (the mask
    product and its gradient); gathering the union of ``U`` frames first reads
    and writes ``U`` and then reads it twice: in place wins when ``U > F / 2``.
    A frame lies in ``history`` of the ``n`` windows, so one random window
    misses it with probability ``1 - history / n``.
    """
    if data.history == 1:
        return False
    n = len(data)
    return 1.0 - (1.0 - min(data.history, n) / n) ** batch_size > 0.5


class RenderedBatches:
    """On-the-fly batches: every batch renders fresh frames of a scene family.

    Frames are taken in order ``start_frame, start_frame + 1, ...`` (windows of
    ``history`` consecutive frames for temporal tasks), so a resumed run renders
    exactly the frames the interrupted one would have. Give the family enough
    ``num_frames`` for ``max_steps * batch_size`` samples.
    """

    def __init__(
        self,
        family: Any,
        batch_size: int,
        *,
        camera: FreeformCamera | None = None,
        spp: int = 4,
        seed: int = 0,
        start_frame: int = 0,
    ) -> None:
        self.family = family
        self.camera = camera or family.camera()
        self.batch_size = batch_size
        self.spp = spp
        self.seed = seed
        self.next_frame = start_frame
        self.history = history_frames(family)
        self._scene: Any = None

    def next(self, generator: torch.Generator) -> Batch:
        """Render one :class:`Batch` (``T[b, history, K, R, C]``, torch)."""
        if self._scene is None:
            self._scene = self.family.build_scene()
        n_needed = self.batch_size * self.history
        if self.next_frame + n_needed > self.family.num_frames:
            raise RuntimeError(
                f"on-the-fly training ran out of frames: the family has {self.family.num_frames}; "
                "create it with more num_frames"
            )
        frames = range(self.next_frame, self.next_frame + n_needed)
        t, labels = render_frames(
            self.family, self._scene, self.camera, frames, spp=self.spp, seed=self.seed
        )
        # labels of the last frame of each window
        labels = {k: v[self.history - 1 :: self.history] for k, v in labels.items()}
        self.next_frame += n_needed
        tt = torch.from_numpy(t).reshape(self.batch_size, self.history, *t.shape[1:])
        return Batch(tt, None, {k: torch.from_numpy(v) for k, v in labels.items()})

    def state(self) -> SourceState:
        """Resumable state: the next frame to render."""
        return {"next_frame": self.next_frame}

    def load_state(self, state: SourceState) -> None:
        """Restore :meth:`state`."""
        self.next_frame = int(state.get("next_frame", self.next_frame))
