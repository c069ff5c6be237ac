r"""End-to-end training of minimalist and baseline cameras on rendered transport images.

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
  by default the paper's choice for the scene family (:data:`PAPER_COUNT_LOSS`).
* Early stopping on the validation loss (evaluated every ``eval_every`` steps;
  stop after ``patience`` evaluations without improvement; the best state is kept).
* Checkpoints after every evaluation (atomic ``checkpoint.pt``): a killed run
  started again with the same arguments resumes from it and reaches the same
  state as an uninterrupted run (random generator states are saved too).
* Logs: TensorBoard event files through ``torch.utils.tensorboard`` (training
  loss, validation loss and error against the step; each event's wall time is
  the run's training time, so TensorBoard's "relative" axis shows loss against
  training time across resumes), ``history.jsonl``, and ``mask_evolution.png``.

The training step (:func:`train_step`) is plain torch when the transport is a
torch tensor (every dataset on disk): one ``index_select`` of the batch's
frames from the (memory-mapped, float16) stored transport with its per-frame
scale applied to the power, the mask plane as one batched matrix product,
the electronics as a handful of fused ops, fused Adam. Batches are gathered into
one reused buffer (:class:`GatherBuffer`); float16 data that fits in RAM is
widened to float32 once. Temporal samples measure every frame of the batch's
union once (:meth:`TrainingData.sample`), or, when a batch's windows cover most
frames, every stored frame in place (:meth:`TrainingData.sample_all_frames`).

Evaluation applies the paper's post-processing in time order over a split:
counts are rounded (and clipped at 0), states thresholded at 0.5, then every
label is median filtered over ``LabelSpec.median_filter_s`` at the data's
frame rate (2 s for counts and speeds, 0.5 s for states). Arrays are numpy
unless a docstring says torch.
"""

from __future__ import annotations

import functools
import io
import json
import logging
import math
import os
import pickle
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.learn.models import BaselineCamera, CountLoss, Head, MincamCamera, task_loss
from mincam_render.learn.train_config import TrainConfig
from mincam_render.optics.camera import FreeformCamera

log = logging.getLogger(__name__)

Model = MincamCamera | BaselineCamera

#: Float16 transport is widened once to float32 in RAM up to this size (bytes of
#: the float32 copy, 2 GiB): 10,000 frames of 8 detectors at 64x64 take 1.3 GB.
WIDEN_MAX_BYTES = 2 * 2**30


# ---------------------------------------------------------------------------------------
# data
# ---------------------------------------------------------------------------------------


@dataclass
class TrainingData:
    """One contiguous split: transport images, labels and what produced them.

    Args:
        transport: ``T[frame, detector, row, col]`` (W), numpy or memmap, float32;
            or with ``scales`` the stored values ``T / scale`` (float16 or float32,
            as :func:`mincam_render.render.precision.encode_transport` writes them).
        labels: ``{name: [frame, size]}`` float32, physical units.
        label_specs: the task's labels.
        camera: the camera the transport was rendered for.
        fps: frame rate (1/s), for the temporal median filter.
        history: frames per sample (1 = static; 30 for traffic).
        source: provenance (dataset path, split, family, seed) for sidecars.
        scales: ``[frame]`` factor from ``transport`` to watts; None: already watts.

    """

    transport: np.ndarray
    labels: dict[str, np.ndarray]
    label_specs: tuple[LabelSpec, ...]
    camera: FreeformCamera
    fps: float
    history: int = 1
    source: dict[str, Any] = field(default_factory=dict)
    scales: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.transport.ndim != 4:
            raise ValueError(
                f"transport has shape {self.transport.shape}: expected (frame, detector, row, col)"
            )
        n = len(self.transport)
        for s in self.label_specs:
            if s.name not in self.labels:
                raise ValueError(f"labels lack {s.name!r}; have {sorted(self.labels)}")
            if self.labels[s.name].shape != (n, s.size):
                raise ValueError(
                    f"labels[{s.name!r}] has shape {self.labels[s.name].shape}; "
                    f"expected ({n}, {s.size})"
                )
        if not self.fps > 0:
            raise ValueError(f"fps = {self.fps!r} 1/s: need a positive frame rate")
        if not 1 <= self.history <= n:
            raise ValueError(f"history = {self.history}: need 1 <= history <= frames ({n})")
        if self.scales is not None and np.shape(self.scales) != (n,):
            raise ValueError(f"scales has shape {np.shape(self.scales)}; expected ({n},)")

    def __getstate__(self) -> dict:
        # torch views of a memory map are rebuilt where the data is unpickled
        return {k: v for k, v in self.__dict__.items() if k != "_torch"}

    def _tensors(self) -> tuple[torch.Tensor, torch.Tensor | None, dict[str, torch.Tensor]]:
        """Torch tensors of the stored frames, scales and labels, made once.

        Float32 frames are a view (no copy). Float16 frames are widened once to a
        float32 copy in RAM when it takes at most :data:`WIDEN_MAX_BYTES`: every
        batch is then one float32 gather, not a gather and a conversion pass.
        Larger float16 data stays a view of its memory map.
        """
        cached = self.__dict__.get("_torch")
        if cached is None:
            t = np.asarray(self.transport)
            if t.dtype != np.float32 and (t.dtype != np.float16 or t.size * 4 <= WIDEN_MAX_BYTES):
                t = t.astype(np.float32)  # exact: every float16 is a float32
            with warnings.catch_warnings():  # read-only memory maps: never written to
                warnings.filterwarnings("ignore", "The given NumPy array is not writable")
                frames = torch.from_numpy(np.ascontiguousarray(t))
            scales = None
            if self.scales is not None:
                scales = torch.from_numpy(np.asarray(self.scales, np.float32).copy())
            labels = {
                k: torch.from_numpy(np.ascontiguousarray(v, np.float32))
                for k, v in self.labels.items()
            }
            cached = self.__dict__["_torch"] = (frames, scales, labels)
        return cached

    def frames_w(self, index: torch.Tensor) -> torch.Tensor:
        """``T[i, detector, row, col]`` float32 (W) of frames ``index`` (long), torch.

        One ``index_select`` of the stored frames; the per-frame scale (and the
        float16 -> float32 conversion) is a single multiply into the output.
        """
        frames, scales, _ = self._tensors()
        x = frames.index_select(0, index)
        if scales is not None:
            return torch.mul(x, scales.index_select(0, index).reshape(-1, 1, 1, 1))
        return x if x.dtype == torch.float32 else x.float()

    def frames_np(self, start: int, stop: int) -> np.ndarray:
        """``T[frame, detector, row, col]`` float32 (W) of frames ``[start, stop)`` (numpy)."""
        return self.frames_w(torch.arange(start, min(stop, len(self.transport)))).numpy()

    def __len__(self) -> int:
        """Number of samples (frames with a full history)."""
        return len(self.transport) - self.history + 1

    @classmethod
    def from_dataset(cls, ds: Any, split: str) -> TrainingData:
        """A split of a dataset opened with ``mincam_render.data.dataset.open_dataset``."""
        if split not in ds.splits:
            raise ValueError(f"split {split!r} not in the dataset; have {sorted(ds.splits)}")
        check = getattr(ds, "check_intact", None)
        if check is not None:  # never train on a shard that fails its checksums
            check()
        family = getattr(ds, "family", None)
        name = family if isinstance(family, str) else getattr(family, "name", "")
        if isinstance(family, str):
            from mincam_render.scenes.registry import family_class

            try:
                needs = family_class(family).needs_history
            except Exception:  # unknown or not yet importable family: a static task
                needs = False
        else:
            needs = getattr(family, "needs_history", False)
        history = 30 if needs else 1
        labels = {k: np.asarray(v, np.float32) for k, v in ds.labels(split).items()}
        stored, scales = ds.stored_transport(split)
        return cls(
            transport=stored,
            scales=scales,
            labels=labels,
            label_specs=tuple(ds.label_specs),
            camera=ds.camera,
            fps=float(ds.fps),
            history=getattr(ds, "history", history),
            source={
                "dataset": str(getattr(ds, "path", "")),
                "split": split,
                "range": list(ds.splits[split]),
                "family": name,
            },
        )

    @classmethod
    def render(
        cls,
        family: Any,
        frames: Sequence[int],
        *,
        camera: FreeformCamera | None = None,
        spp: int = 4,
        seed: int = 0,
        progress: bool = False,
    ) -> TrainingData:
        """Render ``frames`` of a scene family in memory (no dataset on disk)."""
        from tqdm import tqdm

        from mincam_render.render.transport import render_transport

        cam = camera or family.camera()
        scene = family.build_scene()
        ts: list[np.ndarray] = []
        labs: dict[str, list] = {s.name: [] for s in family.labels}
        for i in tqdm(list(frames), desc=f"render {family.name}", disable=not progress):
            lab = family.set_frame(scene, int(i))
            ts.append(render_transport(scene, cam, spp=spp, seed=seed * 1_000_003 + int(i)))
            for s in family.labels:
                labs[s.name].append(np.asarray(lab[s.name], np.float32).reshape(s.size))
        return cls(
            transport=np.stack(ts).astype(np.float32),
            labels={k: np.stack(v) for k, v in labs.items()},
            label_specs=tuple(family.labels),
            camera=cam,
            fps=float(family.fps),
            history=30 if family.needs_history else 1,
            source={
                "family": family.name,
                "seed": family.seed,
                "spp": spp,
                "frames": [int(frames[0]), int(frames[-1]) + 1] if len(frames) else [],
            },
        )

    @classmethod
    def concat(cls, parts: Sequence[TrainingData]) -> TrainingData:
        """Several static episodes as one training set (a copy of their stored frames).

        Raises:
            ValueError: no parts, temporal data (windows would cross episode
                boundaries), or parts of other cameras, labels, frame rates or storage.
        """
        if not parts:
            raise ValueError("concat: no episodes given")
        first = parts[0]
        if len(parts) == 1:
            return first
        if any(p.history != 1 for p in parts):
            raise ValueError(
                "concat: temporal data (history > 1) would get windows across episode "
                "boundaries; train on one episode (--train-episodes 1)"
            )
        for p in parts[1:]:
            same = (p.camera, p.label_specs, p.fps, p.transport.dtype, p.scales is None)
            if same != (first.camera, first.label_specs, first.fps, first.transport.dtype,
                        first.scales is None):  # fmt: skip
                raise ValueError(
                    f"concat: episode {p.source} differs from {first.source} in camera, labels, "
                    "frame rate or storage"
                )
        return replace(
            first,
            transport=np.concatenate([np.asarray(p.transport) for p in parts]),
            labels={k: np.concatenate([p.labels[k] for p in parts]) for k in first.labels},
            scales=None if first.scales is None else np.concatenate([p.scales for p in parts]),
            source={"episodes": [p.source for p in parts]},
        )

    def subset(self, start: int, stop: int, name: str = "") -> TrainingData:
        """Frames ``[start, stop)`` as a new split (contiguous in time)."""
        src = dict(self.source, split=name or self.source.get("split", ""), range=[start, stop])
        return replace(
            self,
            transport=self.transport[start:stop],
            labels={k: v[start:stop] for k, v in self.labels.items()},
            source=src,
            scales=None if self.scales is None else self.scales[start:stop],
        )

    def split(self, fractions: Sequence[float] = (0.7, 0.1, 0.2)) -> tuple[TrainingData, ...]:
        """Contiguous train/val/test segments in the given proportions."""
        n = len(self.transport)
        edges = np.round(np.cumsum([0.0, *fractions]) / sum(fractions) * n).astype(int)
        names = ("train", "val", "test", "extra")
        pairs = zip(edges[:-1], edges[1:], strict=True)
        return tuple(self.subset(int(a), int(b), names[i]) for i, (a, b) in enumerate(pairs))

    def target_stats(self) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Mean and standard deviation of every label (for the head's standardisation)."""
        mean = {k: v.mean(axis=0) for k, v in self.labels.items()}
        std = {k: v.std(axis=0) for k, v in self.labels.items()}
        return mean, std

    def batch(self, index: np.ndarray) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Samples ``index`` (numpy ints) -> ``(T[b, history, K, R, C], labels)`` (torch).

        Every window's frames stacked (copies shared frames); training and
        evaluation use :meth:`sample`, which does not.
        """
        b = self.sample(torch.as_tensor(np.asarray(index, dtype=np.int64)))
        t = b.transport
        if b.frame_scales is not None:
            t = t * b.frame_scales.reshape(-1, 1, 1, 1)
        if b.windows is None:
            return t[:, None], b.labels
        t = t.index_select(0, b.windows.reshape(-1))
        return t.reshape(*b.windows.shape, *t.shape[1:]), b.labels

    def sample(self, index: torch.Tensor, buffer: GatherBuffer | None = None) -> Batch:
        """Samples ``index`` (torch long ``[b]``) as a :class:`Batch`, without per-sample Python.

        Static data: the ``b`` frames (one gather). Temporal data: the sorted union
        of the frames of all windows and ``windows[b, history]`` indices into it,
        so every frame is gathered (and later measured) once per batch.

        Args:
            index: ``[b]`` first frame of each sample (torch long).
            buffer: gather the frames into this reused float32 buffer (the
                batch's transport is then valid until the buffer's next use);
                None: a new tensor.

        """
        stored, scales, labels = self._tensors()
        last = index if self.history == 1 else index + (self.history - 1)
        y = {k: v.index_select(0, last) for k, v in labels.items()}
        windows = None
        if self.history > 1:
            frames = index[:, None] + torch.arange(self.history)
            index, windows = torch.unique(frames, sorted=True, return_inverse=True)
        t = _gather(stored, index, buffer)
        s = None if scales is None else scales.index_select(0, index)
        return Batch(t, windows, y, s)

    def sample_all_frames(self, index: torch.Tensor) -> Batch:
        """Temporal samples ``index`` over every stored frame: no union, no gather.

        The batch's transport is the stored float32 frames themselves (a view)
        and ``windows[b, history]`` index them directly, so the camera measures
        each frame once, in place. Worth it when a batch's windows cover most
        frames (:class:`DatasetBatches` decides); needs float32 storage.
        """
        stored, scales, labels = self._tensors()
        if stored.dtype != torch.float32 or self.history == 1:
            return self.sample(index)
        y = {k: v.index_select(0, index + (self.history - 1)) for k, v in labels.items()}
        windows = index[:, None] + torch.arange(self.history)
        return Batch(stored, windows, y, scales)


def _gather(stored: torch.Tensor, index: torch.Tensor, buffer: GatherBuffer | None) -> torch.Tensor:
    """``stored[index]`` as float32 ``T[i, detector, row, col]``: one gather (torch)."""
    if buffer is None:
        t = stored.index_select(0, index)
        return t if t.dtype == torch.float32 else t.float()
    out = buffer.rows(len(index), stored.shape[1:], stored.device)
    if stored.dtype == torch.float32:
        return torch.index_select(stored, 0, index, out=out)
    return out.copy_(stored.index_select(0, index))


class GatherBuffer:
    """A float32 buffer ``T[row, detector, row, col]`` that batches are gathered into, reused.

    A new batch-sized tensor at every step costs more than filling it once it
    reaches glibc's largest mmap threshold (32 MiB: 8 detectors, 64x64 masks,
    batch 256): the kernel hands out fresh zeroed pages, one fault per 4 KiB,
    and takes them back when the batch is freed (measured: 31 ms of a 31 ms step
    against 8 ms). Reusing one buffer keeps the
    pages. A batch gathered into it is overwritten by the next gather; a graph
    that still holds the old one fails loudly in backward (autograd's version
    counter), never silently.
    """

    def __init__(self) -> None:
        self._t: torch.Tensor | None = None

    def rows(self, n: int, shape: torch.Size, device: torch.device) -> torch.Tensor:
        """The first ``n`` rows, ``[n, *shape]`` float32, contiguous (grown when needed)."""
        t = self._t
        if t is None or len(t) < n or t.shape[1:] != shape or t.device != device:
            t = self._t = torch.empty((n, *shape), dtype=torch.float32, device=device)
        return t if len(t) == n else t[:n]


@dataclass(frozen=True)
class Batch:
    """Training samples (torch).

    Args:
        transport: ``T[frame, detector, row, col]`` (W) of the frames that
            ``windows`` index; with ``windows`` None, ``T[batch, (time,) K, R, C]``.
        windows: ``[batch, history]`` long indices into ``transport``, or None.
        labels: ``{name: [batch, size]}`` physical labels.
        frame_scales: ``[frame]`` factor from ``transport`` to watts, or None.

    """

    transport: torch.Tensor
    windows: torch.Tensor | None
    labels: dict[str, torch.Tensor]
    frame_scales: torch.Tensor | None = None

    def inputs(self) -> dict[str, Any]:
        """Keyword arguments of a camera's ``forward`` / ``measure`` for this batch."""
        return {
            "transport": self.transport,
            "windows": self.windows,
            "frame_scales": self.frame_scales,
        }

    def __len__(self) -> int:
        """Number of samples."""
        return len(self.transport) if self.windows is None else len(self.windows)


# ---------------------------------------------------------------------------------------
# configuration and models
# ---------------------------------------------------------------------------------------


#: The paper's loss for COUNT labels by scene family (``TrainingData.source["family"]``):
#: cross-entropy for the toy task (Sec. 5: "trained by minimizing the cross-entropy
#: loss"); the workspace people count was regressed (supplement C: "minimizing the mean
#: squared error"), and so is every count of a family not listed.
PAPER_COUNT_LOSS: dict[str, CountLoss] = {"patches": CountLoss.CROSS_ENTROPY}


def count_loss_for(data: TrainingData, count_loss: CountLoss | None = None) -> CountLoss:
    """``count_loss``, or when None the paper's choice for ``data``'s family."""
    if count_loss is not None:
        return CountLoss(count_loss)
    return PAPER_COUNT_LOSS.get(str(data.source.get("family", "")), CountLoss.MSE)


def count_classes_for(data: TrainingData, count_loss: CountLoss | None = None) -> dict[str, int]:
    """``{name: classes}`` of the COUNT labels to classify (empty for MSE).

    The classes are the counts ``0 .. max`` of the training labels (at least 2).
    """
    if count_loss_for(data, count_loss) is CountLoss.MSE:
        return {}
    out = {}
    for s in data.label_specs:
        if s.kind is LabelKind.COUNT:
            y = np.asarray(data.labels[s.name])
            top = int(np.rint(y.max())) if y.size else 0
            out[s.name] = max(2, top + 1)
    return out


def learning_rate_for(num_inputs: int) -> float:
    """The head's Adam learning rate: ``1e-3 * min(1, sqrt(16 / num_inputs))``."""
    return 1e-3 * min(1.0, math.sqrt(16.0 / max(1, num_inputs)))


def build_head(
    data: TrainingData,
    in_features: int,
    *,
    count_classes: dict[str, int] | None = None,
    seed: int = 0,
) -> Head:
    """A :class:`Head` for ``data``'s labels (targets standardised by its statistics).

    Its initial weights come from ``seed``; torch's global RNG (used by
    ``nn.Linear``) is restored afterwards.
    """
    mean, std = data.target_stats()
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        return Head(
            in_features,
            data.label_specs,
            target_mean=mean,
            target_std=std,
            count_classes=count_classes,
        )


def build_mincam(
    data: TrainingData,
    pixels: int | None = None,
    *,
    detectors: Sequence[int] | None = None,
    sensor_model: bool = True,
    count_loss: CountLoss | None = None,
    seed: int = 0,
) -> MincamCamera:
    """A minimalist camera of ``pixels`` freeform pixels for ``data``'s task.

    Pixel ``j`` reads detector ``j`` of the data unless ``detectors`` is given
    (None: every rendered detector). More pixels than rendered detectors is an
    error: reusing a detector's transport for a second mask must be asked for
    with an explicit ``detectors`` list.
    COUNT labels are learned by ``count_loss`` (None: :func:`count_loss_for` the data).
    """
    k_data = data.transport.shape[1]
    if detectors is None:
        n = k_data if pixels is None else int(pixels)
        if n < 1:
            raise ValueError(f"pixels = {pixels!r}: need at least 1")
        if n > k_data:
            raise ValueError(
                f"pixels = {n}: the data has only {k_data} rendered detectors; render it with "
                f"more (`render --detectors {n}`, or camera.detectors = {n} in the scene "
                "description), or ask for fewer pixels"
            )
        detectors = list(range(n))
    detectors = list(detectors)
    if any(not 0 <= d < k_data for d in detectors):
        raise ValueError(f"detectors {detectors} outside the data's [0, {k_data})")
    head = build_head(
        data,
        len(detectors) * max(data.history - 1, 1),
        count_classes=count_classes_for(data, count_loss),
        seed=seed,
    )
    return MincamCamera(
        data.camera,
        head,
        detectors=detectors,
        sensor_model=sensor_model,
        history=data.history,
        init_seed=seed,
    )


def build_baseline(
    data: TrainingData,
    grid: tuple[int, int],
    *,
    count_loss: CountLoss | None = None,
    seed: int = 0,
) -> BaselineCamera:
    """A baseline camera of ``grid`` box pixels for ``data``'s task (exposure from ``data``).

    COUNT labels are learned by ``count_loss`` (None: :func:`count_loss_for` the data).
    """
    head = build_head(
        data,
        grid[0] * grid[1] * max(data.history - 1, 1),
        count_classes=count_classes_for(data, count_loss),
        seed=seed,
    )
    return BaselineCamera(
        grid,
        head,
        exposure_w=BaselineCamera.exposure_from(data.frames_np(0, 2048), grid),
        history=data.history,
    )


def describe_model(model: Model) -> dict[str, Any]:
    """A JSON-ready description of a model (kind, pixels, options).

    ``count_classes`` appears only for classified counts, so descriptions (and the
    resume check against checkpoints) of regressing models are unchanged.
    """
    if isinstance(model, MincamCamera):
        desc = {
            "kind": "mincam",
            "pixels": model.num_pixels,
            "detectors": model.detectors.tolist(),
            "sensor_model": model.sensor_model,
            "history": model.history,
        }
    else:
        desc = {
            "kind": "baseline",
            "pixels": model.num_pixels,
            "grid": list(model.grid),
            "exposure_w": float(model.exposure_w),
            "history": model.history,
        }
    if model.head.count_classes:
        desc["count_classes"] = dict(model.head.count_classes)
    return desc


# ---------------------------------------------------------------------------------------
# batches
# ---------------------------------------------------------------------------------------


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

    def state(self) -> dict[str, Any]:
        """Resumable state (none: batches depend only on the generator)."""
        return {}

    def load_state(self, state: Mapping[str, Any]) -> None:
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
        self.history = 30 if family.needs_history else 1
        self._scene: Any = None

    def next(self, generator: torch.Generator) -> Batch:
        """Render one :class:`Batch` (``T[b, history, K, R, C]``, torch)."""
        from mincam_render.render.transport import render_transport

        if self._scene is None:
            self._scene = self.family.build_scene()
        n_needed = self.batch_size * self.history
        if self.next_frame + n_needed > self.family.num_frames:
            raise RuntimeError(
                f"on-the-fly training ran out of frames: the family has {self.family.num_frames}; "
                "create it with more num_frames"
            )
        ts: list[np.ndarray] = []
        labs: dict[str, list] = {s.name: [] for s in self.family.labels}
        for b in range(self.batch_size):
            for h in range(self.history):
                i = self.next_frame + b * self.history + h
                lab = self.family.set_frame(self._scene, i)
                ts.append(
                    render_transport(
                        self._scene, self.camera, spp=self.spp, seed=self.seed * 1_000_003 + i
                    )
                )
            for s in self.family.labels:
                labs[s.name].append(np.asarray(lab[s.name], np.float32).reshape(s.size))
        self.next_frame += n_needed
        t = torch.from_numpy(np.stack(ts).astype(np.float32))
        t = t.reshape(self.batch_size, self.history, *t.shape[1:])
        return Batch(t, None, {k: torch.from_numpy(np.stack(v)) for k, v in labs.items()})

    def state(self) -> dict[str, Any]:
        """Resumable state: the next frame to render."""
        return {"next_frame": self.next_frame}

    def load_state(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state`."""
        self.next_frame = int(state.get("next_frame", self.next_frame))


# ---------------------------------------------------------------------------------------
# evaluation
# ---------------------------------------------------------------------------------------


def median_filter_window(median_filter_s: float, fps: float) -> int:
    """Odd number of frames spanning ``median_filter_s`` at ``fps`` (1 = no filtering)."""
    n = int(round(median_filter_s * fps))
    if n <= 1:
        return 1
    return n if n % 2 else n + 1


def median_filter(x: np.ndarray, window: int) -> np.ndarray:
    """Centred running median of ``x[time, ...]`` over ``window`` frames (edges replicated)."""
    if window <= 1:
        return np.array(x, copy=True)
    half = window // 2
    pad = np.concatenate([np.repeat(x[:1], half, axis=0), x, np.repeat(x[-1:], half, axis=0)])
    win = np.lib.stride_tricks.sliding_window_view(pad, window, axis=0)
    return np.median(win, axis=-1).astype(x.dtype)


def postprocess(
    pred: Mapping[str, np.ndarray], specs: Sequence[LabelSpec], fps: float
) -> dict[str, np.ndarray]:
    """The paper's test-time post-processing of predictions ``{name: [time, size]}``.

    COUNT: round to the nearest integer >= 0, then median filter; REGRESSION:
    median filter; BINARY: threshold probabilities at 0.5, then median filter.
    """
    out = {}
    for s in specs:
        y = np.asarray(pred[s.name], np.float64)
        if s.kind is LabelKind.COUNT:
            y = np.maximum(np.rint(y), 0.0)
        elif s.kind is LabelKind.BINARY:
            y = (y >= 0.5).astype(np.float64)
        out[s.name] = median_filter(y, median_filter_window(s.median_filter_s, fps))
    return out


def _even_indices(n: int, limit: int | None) -> np.ndarray:
    if limit is None or n <= limit:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, limit).round().astype(np.int64))


@torch.no_grad()
def predict(
    model: Model,
    data: TrainingData,
    *,
    batch_size: int = 1024,
    noise: bool = True,
    seed: int = 1234,
    limit: int | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], float]:
    """Predictions, labels (``{name: [n, size]}``) and mean loss over a split, in time order.

    Batches of consecutive samples: a temporal batch measures each frame once.
    """
    was_training = model.training
    model.eval()
    g = torch.Generator().manual_seed(seed)
    idx = _even_indices(len(data), limit)
    preds: dict[str, list] = {s.name: [] for s in data.label_specs}
    labs: dict[str, list] = {s.name: [] for s in data.label_specs}
    loss_sum = 0.0
    for a in range(0, len(idx), batch_size):
        batch = data.sample(torch.from_numpy(idx[a : a + batch_size]))
        y = batch.labels
        out = model(**batch.inputs(), noise=noise, generator=g)
        loss, _ = task_loss(model.head, out, y)
        loss_sum += float(loss) * len(batch)
        for k, v in model.head.predict(out).items():
            preds[k].append(v.numpy())
            labs[k].append(y[k].numpy())
    model.train(was_training)
    cat = {k: np.concatenate(v) for k, v in preds.items()}
    return cat, {k: np.concatenate(v) for k, v in labs.items()}, loss_sum / max(1, len(idx))


def evaluate(
    model: Model, data: TrainingData, *, noise: bool = True, seed: int = 1234
) -> dict[str, Any]:
    """Test metrics after post-processing (every sample of ``data``, in time order).

    Returns ``{"loss": ..., "labels": {name: {...}}, "error": primary error}`` where
    COUNT/REGRESSION report ``rmse`` (post-processed), ``rmse_raw`` and ``mae`` in the
    label's unit, BINARY ``accuracy`` (mean over elements) and ``accuracy_per_element``;
    ``error`` is the first label's ``rmse`` or ``1 - accuracy``.
    """
    pred, lab, loss = predict(model, data, noise=noise, seed=seed)
    return metrics(pred, lab, loss, data)


def metrics(
    pred: Mapping[str, np.ndarray],
    lab: Mapping[str, np.ndarray],
    loss: float,
    data: TrainingData,
) -> dict[str, Any]:
    """:func:`evaluate`'s metrics of :func:`predict`'s output (time-ordered samples of ``data``)."""
    post = postprocess(pred, data.label_specs, data.fps)
    n = len(next(iter(lab.values())))
    res: dict[str, Any] = {"loss": loss, "samples": n, "labels": {}}
    for s in data.label_specs:
        y = lab[s.name].astype(np.float64)
        if s.kind is LabelKind.BINARY:
            acc = (post[s.name] == y).mean(axis=0)
            res["labels"][s.name] = {
                "accuracy": float(acc.mean()),
                "accuracy_per_element": acc.tolist(),
                "unit": "",
            }
        else:
            raw = pred[s.name].astype(np.float64)
            res["labels"][s.name] = {
                "rmse": float(np.sqrt(np.mean((post[s.name] - y) ** 2))),
                "rmse_raw": float(np.sqrt(np.mean((raw - y) ** 2))),
                "mae": float(np.mean(np.abs(post[s.name] - y))),
                "unit": s.unit,
            }
    first = data.label_specs[0]
    m = res["labels"][first.name]
    res["error"] = m["rmse"] if "rmse" in m else 1.0 - m["accuracy"]
    res["error_name"] = f"{first.name} " + ("RMSE" if "rmse" in m else "error rate")
    return res


# ---------------------------------------------------------------------------------------
# training
# ---------------------------------------------------------------------------------------


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


def _optimizer(model: Model, config: TrainConfig) -> torch.optim.Adam:
    lr = config.lr if config.lr is not None else learning_rate_for(model.head.in_features)
    groups = [{"params": [p for p in model.head.parameters() if p.requires_grad], "lr": lr}]
    if isinstance(model, MincamCamera) and model.logits.requires_grad:
        groups.append({"params": [model.logits], "lr": config.mask_lr})
    try:
        # one kernel for all parameters: 0.08 ms per step against 0.22 ms (8 px head)
        return torch.optim.Adam(groups, fused=True)
    except (RuntimeError, ValueError):  # a device or dtype without the fused kernel
        return torch.optim.Adam(groups)


def _adam_step(opt: torch.optim.Optimizer) -> None:
    """``opt.step()``; for a plain fused Adam, its fused kernel called directly.

    ``Optimizer.step`` and the functional ``torch.optim.adam.adam`` spend
    ~0.1 ms of Python per call (hooks, profiler record, lazy state checks,
    grouping by device) around one fused kernel per parameter group (measured
    in a step at 1 px, 32x32, batch 64: 0.16 ms through ``adam``, 0.09 ms
    direct, of a 1.2 ms step). Here the step counters are advanced and
    ``torch._fused_adam_`` -- the op ``torch.optim.Adam(fused=True)`` itself
    calls -- runs on the optimiser's own state tensors: bit-identical, state
    and ``state_dict`` unchanged. Anything else -- other optimisers or
    options, a torch without the op, parameters of mixed device or dtype, a
    parameter without a gradient or without state yet (the first step) --
    goes through ``opt.step()``. Step hooks are not called.
    """
    groups = opt.param_groups
    fused = getattr(torch, "_fused_adam_", None)
    if fused is None or type(opt) is not torch.optim.Adam or not all(map(_plain_fused, groups)):
        opt.step()
        return
    state = opt.state
    if any(p.grad is None or p not in state for g in groups for p in g["params"]):
        opt.step()
        return
    with torch.no_grad():
        for g in groups:
            params = g["params"]
            st = [state[p] for p in params]
            steps = [s["step"] for s in st]
            beta1, beta2 = g["betas"]
            torch._foreach_add_(steps, 1)
            fused(
                params, [p.grad for p in params], [s["exp_avg"] for s in st],
                [s["exp_avg_sq"] for s in st], [], steps, amsgrad=False, lr=g["lr"],
                beta1=beta1, beta2=beta2, weight_decay=0.0, eps=g["eps"], maximize=False,
            )  # fmt: skip


def _plain_fused(group: Mapping[str, Any]) -> bool:
    """A fused Adam group on one device and dtype, without amsgrad, weight decay, etc."""
    params = group["params"]
    return (
        bool(group["fused"])
        and not (
            group["amsgrad"] or group["weight_decay"] or group["maximize"]
            or group["capturable"] or group["differentiable"]
            or group["decoupled_weight_decay"] or isinstance(group["lr"], torch.Tensor)
        )
        and len({(p.device, p.dtype) for p in params}) == 1
    )  # fmt: skip


def train_step(
    model: Model,
    source: DatasetBatches | RenderedBatches,
    opt: torch.optim.Optimizer,
    generator: torch.Generator,
    gain_range: tuple[float, float],
) -> torch.Tensor:
    """One optimisation step of :func:`train_model` (Adam on the task loss); the loss, detached.

    A batch, a random global gain per sample (augmentation), the camera with
    sensor noise, the loss, backward, the optimiser, and the projection of the
    mask logits (a saturated mask must be able to move back).
    """
    batch = source.next(generator)
    gain = torch.empty(len(batch)).uniform_(*gain_range, generator=generator)
    out = model(**batch.inputs(), gain=gain, noise=True, generator=generator)
    loss, _ = task_loss(model.head, out, batch.labels)
    for group in opt.param_groups:  # zero_grad(set_to_none=True) without its overhead
        for p in group["params"]:
            p.grad = None
    loss.backward()
    _adam_step(opt)
    if isinstance(model, MincamCamera):
        model.project_logits_()
    return loss.detach()


#: Steps between training-loss events (their mean): a TensorBoard event per step
#: would cost more than a tenth of a step of a small camera.
LOG_EVERY = 10


def _atomic_save(obj: Any, path: Path) -> None:
    from mincam_render.data.dataset import atomic_write_bytes

    buf = io.BytesIO()
    torch.save(obj, buf)
    # temporary file, fsync, rename: a kill or a full disk leaves the old checkpoint
    atomic_write_bytes(path, buf.getvalue())


def _write_history(path: Path, history: list[dict[str, float]]) -> None:
    """``history.jsonl``: one JSON line per evaluation kept in the checkpoint (atomic)."""
    from mincam_render.data.dataset import atomic_write_bytes

    atomic_write_bytes(path, "".join(json.dumps(r) + "\n" for r in history).encode())


def _load_checkpoint(path: Path) -> dict[str, Any]:
    """``torch.load`` of a checkpoint; a damaged file is a one-line ValueError naming it."""
    try:
        return torch.load(path, weights_only=False)
    except (RuntimeError, EOFError, OSError, ValueError, pickle.UnpicklingError) as err:
        raise ValueError(
            f"{path}: checkpoint unreadable ({str(err).splitlines()[0][:120]}); delete it or "
            "train with --no-resume"
        ) from None


def _snapshot(model: Model) -> np.ndarray | None:
    if isinstance(model, MincamCamera):
        with torch.no_grad():
            return model.transmittance().numpy().copy()
    return None


def train_model(
    model: Model,
    train: TrainingData | DatasetBatches | RenderedBatches,
    val: TrainingData,
    config: TrainConfig = TrainConfig(),
    *,
    out_dir: str | os.PathLike | None = None,
    resume: bool = True,
    stop_after_steps: int | None = None,
    progress: bool = False,
    desc: str = "train",
) -> TrainResult:
    """Train ``model`` in place with Adam and early stopping on ``val``; keep the best state.

    Args:
        model: a :class:`MincamCamera` or :class:`BaselineCamera`.
        train: a training split, or a batch source (:class:`RenderedBatches` for
            on-the-fly training).
        val: validation split (loss with sensor noise at a fixed seed).
        config: the recipe.
        out_dir: where checkpoints, event files, ``history.jsonl`` and
            ``mask_evolution.png`` go; None keeps everything in memory.
        resume: continue from ``out_dir/checkpoint.pt`` when it exists.
        stop_after_steps: checkpoint and return after this many steps in total
            (simulates a killed run; the result is not final).
        progress: show a tqdm progress bar.
        desc: progress-bar label.

    Returns:
        A :class:`TrainResult`; ``model`` holds the best validation state.

    """
    from tqdm import tqdm

    source = DatasetBatches(train, config.batch_size) if isinstance(train, TrainingData) else train
    opt = _optimizer(model, config)
    gen = torch.Generator().manual_seed(config.seed + 7919)
    out = Path(out_dir) if out_dir is not None else None
    ckpt_path = out / "checkpoint.pt" if out is not None else None
    step, best_step, bad = 0, 0, 0
    best_loss = math.inf
    best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
    history: list[dict[str, float]] = []
    snaps: list[tuple[int, np.ndarray]] = []
    elapsed = 0.0
    stopped_early = False
    if ckpt_path is not None and resume and ckpt_path.is_file():
        ck = _load_checkpoint(ckpt_path)
        if ck["model_description"] != describe_model(model):
            raise ValueError(
                f"{ckpt_path} was written for {ck['model_description']}, not "
                f"{describe_model(model)}; use another --out or delete the checkpoint"
            )
        model.load_state_dict(ck["model"])
        opt.load_state_dict(ck["optimizer"])
        gen.set_state(ck["generator"])
        source.load_state(ck["source"])
        step, best_step, bad, best_loss = ck["step"], ck["best_step"], ck["bad"], ck["best_loss"]
        best_state, history, snaps = ck["best_state"], ck["history"], ck["snapshots"]
        elapsed, stopped_early = ck["elapsed"], ck["stopped_early"]
        log.info("resumed %s at step %d (best val loss %.4g)", ckpt_path, step, best_loss)
    elif (first := _snapshot(model)) is not None:
        snaps.append((0, first))
    writer = None
    if out is not None:
        from torch.utils.tensorboard import SummaryWriter

        out.mkdir(parents=True, exist_ok=True)
        # resume is exact: events after the checkpoint's step (written by a killed run)
        # are purged, and history.jsonl is cut back to the checkpoint's evaluations
        writer = SummaryWriter(str(out), purge_step=step if step > 0 else None)
        _write_history(out / "history.jsonl", history)

    def save_checkpoint() -> None:
        if ckpt_path is None:
            return
        _atomic_save(
            {
                "model_description": describe_model(model),
                "config": asdict(config),
                "model": model.state_dict(),
                "optimizer": opt.state_dict(),
                "generator": gen.get_state(),
                "source": source.state(),
                "step": step,
                "best_step": best_step,
                "bad": bad,
                "best_loss": best_loss,
                "best_state": best_state,
                "history": history,
                "snapshots": snaps,
                "elapsed": elapsed,
                "stopped_early": stopped_early,
            },
            ckpt_path,
        )

    if isinstance(model, MincamCamera):
        model.project_logits_()  # e.g. a start with masks pinned at their limits
    done = stopped_early or step >= config.max_steps
    bar = tqdm(
        total=config.max_steps,
        initial=step,
        desc=desc,
        disable=not progress,
        leave=False,
        dynamic_ncols=True,
    )
    model.train()
    t_start = time.perf_counter() - elapsed
    wall_start = time.time() - elapsed  # event wall times: training time, across resumes
    loss_sum, loss_n = torch.zeros(()), 0
    threads = torch.get_num_threads()
    if config.torch_threads is not None:
        torch.set_num_threads(config.torch_threads)
    try:
        while not done:
            loss = train_step(model, source, opt, gen, config.gain_range)
            step += 1
            bar.update(1)
            if writer is not None:
                loss_sum += loss
                loss_n += 1
                if step % LOG_EVERY == 0:
                    wall = wall_start + time.perf_counter() - t_start
                    writer.add_scalar("loss/train", float(loss_sum) / loss_n, step, walltime=wall)
                    loss_sum.zero_()
                    loss_n = 0
            if step % config.eval_every == 0 or step >= config.max_steps:
                pred, lab, val_loss = predict(model, val, limit=config.max_eval_samples)
                elapsed = time.perf_counter() - t_start
                rec = {
                    "step": step,
                    "train_loss": loss.item(),
                    "val_loss": val_loss,
                    "wall_time_s": elapsed,
                }
                history.append(rec)
                snap = _snapshot(model)
                if snap is not None:
                    snaps.append((step, snap))
                if writer is not None and out is not None:
                    val_metrics = metrics(pred, lab, val_loss, val)
                    wall = wall_start + elapsed
                    writer.add_scalar("loss/val", val_loss, step, walltime=wall)
                    writer.add_scalar("error/val", val_metrics["error"], step, walltime=wall)
                    writer.flush()
                    with (out / "history.jsonl").open("a") as fh:
                        fh.write(json.dumps(rec) + "\n")
                if val_loss < best_loss:
                    best_loss, best_step, bad = val_loss, step, 0
                    best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
                else:
                    bad += 1
                bar.set_postfix(val=f"{val_loss:.4g}", best=f"{best_loss:.4g}")
                if bad >= config.patience:
                    stopped_early = True
                done = stopped_early or step >= config.max_steps
                save_checkpoint()
            if stop_after_steps is not None and step >= stop_after_steps and not done:
                elapsed = time.perf_counter() - t_start
                save_checkpoint()
                break
    finally:
        torch.set_num_threads(threads)
        bar.close()
        if writer is not None:
            writer.close()
    elapsed = time.perf_counter() - t_start
    if done:
        model.load_state_dict(best_state)
        if out is not None and snaps:
            plot_mask_evolution(snaps, out / "mask_evolution.png")
    return TrainResult(
        steps=step,
        best_step=best_step,
        best_val_loss=best_loss,
        stopped_early=stopped_early,
        wall_time_s=elapsed,
        history=history,
        snapshots=snaps,
    )


def plot_mask_evolution(
    snapshots: Sequence[tuple[int, np.ndarray]], path: str | os.PathLike, max_rows: int = 6
) -> Path:
    """Grid of mask transmittance (rows: training steps, columns: pixels), saved as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pick = _even_indices(len(snapshots), max_rows)
    rows = [snapshots[i] for i in pick]
    k = rows[0][1].shape[0]
    cols = min(k, 16)
    fig, axes = plt.subplots(
        len(rows), cols, figsize=(1.3 * cols + 0.8, 1.3 * len(rows) + 0.4), squeeze=False
    )
    for r, (step, m) in enumerate(rows):
        for c in range(cols):
            ax = axes[r, c]
            ax.imshow(m[c], cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(f"pixel {c}", fontsize=8)
            if c == 0:
                ax.set_ylabel(f"step {step}", fontsize=8)
    fig.suptitle("mask transmittance during training (0 black, 1 white)", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------
# pruning, sweeps, pipeline
# ---------------------------------------------------------------------------------------


@torch.no_grad()
def _val_loss_without(model: MincamCamera, data: TrainingData, pixel: int, limit: int) -> float:
    """Validation loss when pixel ``pixel``'s inputs are replaced by their running mean."""
    model.eval()
    g = torch.Generator().manual_seed(1234)
    idx = _even_indices(len(data), limit)
    k = model.num_pixels
    cols = torch.arange(pixel, model.head.in_features, k)
    total = 0.0
    from mincam_render.learn.models import temporal_features

    for a in range(0, len(idx), 1024):
        b = data.sample(torch.from_numpy(idx[a : a + 1024]))
        x = temporal_features(model.measure(**b.inputs(), noise=True, generator=g))
        means = model.head.input_norm.running_mean
        assert means is not None  # BatchNorm1d tracks running statistics by default
        x[:, cols] = means[cols]
        loss, _ = task_loss(model.head, model.head(x), b.labels)
        total += float(loss) * len(b)
    return total / max(1, len(idx))


def greedy_prune(
    model: MincamCamera,
    train: TrainingData,
    val: TrainingData,
    test: TrainingData | None = None,
    config: TrainConfig = TrainConfig(),
    *,
    min_pixels: int = 1,
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Supplement C's greedy pruning of a trained minimalist camera.

    At each step the pixel whose removal raises the validation loss least is
    dropped (its head inputs held at their running mean, so every candidate is
    scored without retraining), the masks are frozen, and a fresh head is
    trained on the remaining pixels with ``config``.

    Returns:
        One record per pixel count, from ``K`` down to ``min_pixels``:
        ``{"pixels", "detectors", "removed", "val_loss", "test"}`` (test metrics
        when ``test`` is given); ``removed`` lists original pixel indices in order.

    """
    current = model
    keep = list(range(model.num_pixels))  # indices into the original model's pixels
    removed: list[int] = []
    records = [
        {
            "pixels": len(keep),
            "kept": list(keep),
            "removed": [],
            "val_loss": predict(current, val, limit=config.max_eval_samples)[2],
            "test": evaluate(current, test) if test is not None else None,
        }
    ]
    while len(keep) > min_pixels:
        scores = [
            _val_loss_without(current, val, j, config.max_eval_samples)
            for j in range(current.num_pixels)
        ]
        j = int(np.argmin(scores))
        removed.append(keep.pop(j))
        dets = [int(d) for d in model.detectors[keep]]
        head = build_head(
            train,
            len(keep) * max(train.history - 1, 1),
            count_classes=model.head.count_classes,
            seed=config.seed + len(keep),
        )
        nxt = MincamCamera(
            model.camera,
            head,
            detectors=dets,
            sensor_model=model.sensor_model,
            history=model.history,
        )
        with torch.no_grad():
            nxt.logits.copy_(model.logits[keep])
        nxt.logits.requires_grad_(False)
        res = train_model(nxt, train, val, config, progress=progress, desc=f"prune {len(keep)} px")
        current = nxt
        records.append(
            {
                "pixels": len(keep),
                "kept": list(keep),
                "removed": list(removed),
                "score_val_loss_without": float(scores[j]),
                "val_loss": res.best_val_loss,
                "test": evaluate(current, test) if test is not None else None,
            }
        )
    return records


def _parse_grid(g: Any) -> tuple[int, int]:
    if isinstance(g, str):
        r, c = g.lower().split("x")
        return int(r), int(c)
    if isinstance(g, int):
        return g, g
    return int(g[0]), int(g[1])


def default_pixel_counts(num_detectors: int) -> list[int]:
    """Pixel counts of a sweep: 1, 2, 4, ... up to ``num_detectors`` (and it, if not a power)."""
    out = [1 << i for i in range(num_detectors.bit_length()) if 1 << i <= num_detectors]
    return out if out[-1] == num_detectors else [*out, num_detectors]


def sweep(
    train: TrainingData,
    val: TrainingData,
    test: TrainingData,
    *,
    pixel_counts: Sequence[int] | None = None,
    baseline_grids: Sequence[Any] = ((1, 1), (2, 2), (4, 4), (8, 8), (16, 16)),
    config: TrainConfig = TrainConfig(),
    out_dir: str | os.PathLike | None = None,
    progress: bool = False,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Train minimalist cameras and baselines at several pixel counts; error vs pixels.

    ``pixel_counts`` None: :func:`default_pixel_counts` of the rendered detectors.
    Every model gets the same ``config`` (equal training budget). With
    ``out_dir``, each run trains in ``out_dir/<name>/`` (resumable) and
    ``sweep.json``, ``sweep.md`` and ``sweep.png`` (log-x axis) are written.
    """
    rows: list[dict[str, Any]] = []
    out = Path(out_dir) if out_dir is not None else None
    jobs: list[tuple[str, Callable[[], Model]]] = []
    for k in pixel_counts or default_pixel_counts(train.transport.shape[1]):
        jobs.append(
            (
                f"mincam_{k}px",
                functools.partial(
                    build_mincam, train, k, count_loss=config.count_loss, seed=config.seed
                ),
            )
        )
    for g in baseline_grids:
        grid = _parse_grid(g)
        jobs.append(
            (
                f"baseline_{grid[0]}x{grid[1]}",
                functools.partial(
                    build_baseline, train, grid, count_loss=config.count_loss, seed=config.seed
                ),
            )
        )
    for name, make in jobs:
        model = make()
        res = train_model(
            model,
            train,
            val,
            config,
            out_dir=(out / name) if out is not None else None,
            progress=progress,
            desc=name,
        )
        metrics = evaluate(model, test)
        row = {
            "name": name,
            **describe_model(model),
            "error": metrics["error"],
            "error_name": metrics["error_name"],
            "metrics": metrics,
            "steps": res.steps,
            "best_step": res.best_step,
            "train_wall_time_s": res.wall_time_s,
            "train_samples": len(train),
        }
        rows.append(row)
        if on_result is not None:
            on_result(row)
        log.info(
            "%s: %s = %.4g after %d steps (%.1f s)",
            name,
            metrics["error_name"],
            metrics["error"],
            res.steps,
            res.wall_time_s,
        )
    if out is not None:
        write_sweep(rows, out, title=str(train.source.get("family", "")))
    return rows


def sweep_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """A Markdown table of sweep rows."""
    lines = [
        "| camera | pixels | test error | steps | train time (s) |",
        "|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['pixels']} | {r['error']:.4f} | {r['steps']} | "
            f"{r['train_wall_time_s']:.1f} |"
        )
    return "\n".join(lines)


def write_sweep(
    rows: Sequence[Mapping[str, Any]], out_dir: str | os.PathLike, title: str = ""
) -> dict[str, Path]:
    """Write ``sweep.json``, ``sweep.md`` and ``sweep.png`` (error vs pixel count, log x)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "sweep.json").write_text(json.dumps(list(rows), indent=2, default=str))
    (out / "sweep.md").write_text(sweep_table(rows) + "\n")
    plot_sweep(rows, out / "sweep.png", title)
    return {"json": out / "sweep.json", "table": out / "sweep.md", "figure": out / "sweep.png"}


def plot_sweep(rows: Sequence[Mapping[str, Any]], path: str | os.PathLike, title: str = "") -> None:
    """Save test error vs pixel count (log x) of sweep rows ``{"kind", "pixels", "error"}``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    for kind, style, label in (
        ("mincam", "o-", "minimalist camera"),
        ("baseline", "s--", "baseline camera"),
    ):
        pts = sorted((r["pixels"], r["error"]) for r in rows if r["kind"] == kind)
        if pts:
            ax.plot(*zip(*pts, strict=True), style, label=label)
    ax.set_xscale("log", base=2)
    ax.set_xlabel("pixel count")
    ax.set_ylabel(rows[0]["error_name"] if rows else "test error")
    ax.set_title(f"{title} test error vs pixel count".strip())
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def train_run(
    train: TrainingData,
    val: TrainingData,
    test: TrainingData | None,
    out_dir: str | os.PathLike,
    *,
    pixels: int | None = None,
    baseline_grid: tuple[int, int] | None = None,
    sensor_model: bool = True,
    config: TrainConfig = TrainConfig(),
    on_the_fly: RenderedBatches | None = None,
    episodes: Mapping[str, TrainingData] | None = None,
    resume: bool = True,
    progress: bool = False,
) -> dict[str, Any]:
    """Train one camera into ``out_dir`` (resumable) and write ``run.json`` + ``metrics.json``.

    A minimalist camera of ``pixels`` pixels unless ``baseline_grid`` is given.
    ``on_the_fly`` replaces ``train`` as the source of training batches (``train``
    still provides target statistics and the baseline exposure). ``episodes``:
    test episodes evaluated one by one (``metrics["episodes"][name]``), beside
    ``test``; the metrics also hold the validation ``history``.
    """
    from mincam_render.data.writer_lock import exclusive_writer

    with exclusive_writer(out_dir, "training") as out:
        if baseline_grid is not None:
            model: Model = build_baseline(
                train, baseline_grid, count_loss=config.count_loss, seed=config.seed
            )
        else:
            model = build_mincam(
                train,
                pixels,
                sensor_model=sensor_model,
                count_loss=config.count_loss,
                seed=config.seed,
            )
        run: dict[str, Any] = {
            "model": describe_model(model),
            "camera": _camera_dict(train.camera),
            "data": {
                "train": train.source,
                "val": val.source,
                "test": test.source if test is not None else None,
                "train_samples": len(train),
                "on_the_fly": on_the_fly is not None,
            },
            "config": asdict(config),
            "fps": train.fps,
            "history": train.history,
            "label_specs": [
                {
                    "name": s.name,
                    "kind": s.kind.value,
                    "size": s.size,
                    "unit": s.unit,
                    "median_filter_s": s.median_filter_s,
                }
                for s in train.label_specs
            ],
        }
        _refuse_other_data(out, run, resume)
        _write_json_atomic(out / "run.json", run)
        res = train_model(
            model,
            on_the_fly if on_the_fly is not None else train,
            val,
            config,
            out_dir=out,
            resume=resume,
            progress=progress,
            desc=f"{run['model']['kind']} {model.num_pixels} px",
        )
        metrics = {
            "model": run["model"],
            "steps": res.steps,
            "best_step": res.best_step,
            "best_val_loss": res.best_val_loss,
            "stopped_early": res.stopped_early,
            "train_wall_time_s": res.wall_time_s,
            "train_samples": len(train),
            "test": evaluate(model, test) if test is not None else None,
            "episodes": {k: evaluate(model, d) for k, d in (episodes or {}).items()},
            "history": res.history,
        }
        _write_json_atomic(out / "metrics.json", metrics)
        return metrics


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
    ck = _load_checkpoint(ckpt_path)
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
