"""Training data: one contiguous split of transport images and labels, and its batches.

:class:`TrainingData` holds a split (from a dataset on disk, rendered in memory,
or concatenated episodes) and draws samples from it without per-sample Python:
static samples are one gather of frames; temporal samples gather the union of
their windows' frames once (:meth:`TrainingData.sample`), or, when a batch's
windows cover most frames, index every stored frame in place
(:meth:`TrainingData.sample_all_frames`). Batches are gathered into one reused
buffer (:class:`GatherBuffer`); float16 data that fits in RAM is widened to
float32 once. Arrays are numpy unless a docstring says torch.
"""

from __future__ import annotations

import logging
import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, TypedDict

import numpy as np
import torch

from mincam_render.core.labels import LabelSpec
from mincam_render.core.seeds import stream_seed
from mincam_render.core.strict_json import JsonObject
from mincam_render.optics.camera import FreeformCamera
from mincam_render.render.capabilities import history_frames

log = logging.getLogger(__name__)

#: Float16 transport is widened once to float32 in RAM up to this size (bytes of
#: the float32 copy, 2 GiB): 10,000 frames of 8 detectors at 64x64 take 1.3 GB.
WIDEN_MAX_BYTES = 2 * 2**30


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
        source: provenance for sidecars, free-form JSON whose keys its maker
            chooses (a dataset's path, checksum, split and range; a render's family,
            seed and frames; concatenated episodes' sources; what a transform did).
        scales: ``[frame]`` factor from ``transport`` to watts; None: already watts.
        window_starts: ``[sample]`` first frame of each sample, for temporal
            episodes joined by :meth:`concat` (no window crosses an episode's
            end); None: every window of ``history`` consecutive frames.

    """

    transport: np.ndarray
    labels: dict[str, np.ndarray]
    label_specs: tuple[LabelSpec, ...]
    camera: FreeformCamera
    fps: float
    history: int = 1
    source: JsonObject = field(default_factory=dict)
    scales: np.ndarray | None = None
    window_starts: np.ndarray | None = None

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
        if self.window_starts is not None:
            self.window_starts = np.asarray(self.window_starts)
            self._check_window_starts(n)

    def _check_window_starts(self, n: int) -> None:
        """Refuse window starts that are not increasing ints with windows in the ``n`` frames."""
        starts = np.asarray(self.window_starts)
        if starts.ndim != 1 or not len(starts) or starts.dtype.kind not in "iu":
            raise ValueError(
                f"window_starts: need a non-empty 1-d integer array (a window or more), "
                f"got {starts!r}"
            )
        if np.any(np.diff(starts) <= 0):
            raise ValueError("window_starts: need increasing frames (samples in time order)")
        if starts.min() < 0 or starts.max() + self.history > n:
            raise ValueError(
                f"window_starts span [{starts.min()}, {starts.max()}]: windows of "
                f"{self.history} frames must start in [0, {n - self.history}]"
            )

    def __getstate__(self) -> dict:
        # torch views of a memory map are rebuilt where the data is unpickled
        return {k: v for k, v in self.__dict__.items() if k not in ("_torch", "_starts")}

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
        """Number of samples (windows of ``history`` frames within one episode)."""
        if self.window_starts is not None:
            return len(self.window_starts)
        return len(self.transport) - self.history + 1

    def sample_labels(self) -> dict[str, np.ndarray]:
        """``{name: [sample, size]}``: every sample's labels (a window's at its last frame)."""
        if self.window_starts is None:
            return {k: v[self.history - 1 :] for k, v in self.labels.items()}
        last = np.asarray(self.window_starts) + (self.history - 1)
        return {k: v[last] for k, v in self.labels.items()}

    @property
    def one_sequence(self) -> bool:
        """Whether the samples are consecutive in time (not episodes joined with their windows)."""
        return self.window_starts is None or bool(np.all(np.diff(self.window_starts) == 1))

    def _first_frames(self, index: torch.Tensor) -> torch.Tensor:
        """The first stored frame of each sample ``index`` (torch long)."""
        if self.window_starts is None:
            return index
        starts = self.__dict__.get("_starts")
        if starts is None:
            starts = torch.from_numpy(np.asarray(self.window_starts, np.int64).copy())
            self.__dict__["_starts"] = starts
        return starts.index_select(0, index)

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
        recorded = getattr(ds, "manifest", {}).get("family", {}).get("history_frames")
        if isinstance(recorded, int):  # what the family declared when it was rendered
            history = recorded
        elif isinstance(family, str):
            from mincam_render.scenes.registry import family_class

            try:
                history = history_frames(family_class(family))
            except Exception:  # unknown or not yet importable family: a static task
                history = 1
        else:
            history = history_frames(family)
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
                # the data's identity: a moved or re-spelled folder is the same data
                "manifest_sha256": _manifest_sha256(ds),
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
        cam = camera or family.camera()
        transport, labels = render_frames(
            family, family.build_scene(), cam, frames, spp=spp, seed=seed, progress=progress
        )
        return cls(
            transport=transport,
            labels=labels,
            label_specs=tuple(family.labels),
            camera=cam,
            fps=float(family.fps),
            history=history_frames(family),
            source={
                "family": family.name,
                "seed": family.seed,
                "spp": spp,
                "frames": [int(frames[0]), int(frames[-1]) + 1] if len(frames) else [],
            },
        )

    @classmethod
    def concat(cls, parts: Sequence[TrainingData]) -> TrainingData:
        """Several episodes as one training set (a copy of their stored frames).

        Temporal episodes (``history > 1``) keep their windows: a sample's
        frames all come from one episode (``window_starts``).

        Raises:
            ValueError: no parts, or parts of other cameras, labels, frame rates,
                histories or storage.
        """
        if not parts:
            raise ValueError("concat: no episodes given")
        first = parts[0]
        if len(parts) == 1:
            return first
        for p in parts[1:]:
            same = (p.camera, p.label_specs, p.fps, p.history, p.transport.dtype, p.scales is None)
            if same != (first.camera, first.label_specs, first.fps, first.history,
                        first.transport.dtype, first.scales is None):  # fmt: skip
                raise ValueError(
                    f"concat: episode {p.source} differs from {first.source} in camera, labels, "
                    "frame rate, history or storage"
                )
        return replace(
            first,
            transport=np.concatenate([np.asarray(p.transport) for p in parts]),
            labels={k: np.concatenate([p.labels[k] for p in parts]) for k in first.labels},
            scales=None if first.scales is None else np.concatenate([p.scales for p in parts]),
            source={"episodes": [p.source for p in parts]},
            window_starts=_joined_window_starts(parts),
        )

    def with_labels(self, names: Sequence[str]) -> TrainingData:
        """The same frames with only the labels ``names`` (a task's; no copy of the frames).

        Raises:
            ValueError: a name that is not a label of this split, or no names.
        """
        known = [s.name for s in self.label_specs]
        unknown = [n for n in names if n not in known]
        if unknown or not names:
            raise ValueError(f"labels {list(names)}: need one or more of {known}")
        specs = tuple(s for s in self.label_specs if s.name in names)
        data = replace(self, labels={s.name: self.labels[s.name] for s in specs}, label_specs=specs)
        if "_torch" in self.__dict__:  # keep the frames' tensors, drop the other labels'
            frames, scales, labels = self.__dict__["_torch"]
            data.__dict__["_torch"] = (frames, scales, {s.name: labels[s.name] for s in specs})
        return data

    def subset(self, start: int, stop: int, name: str = "") -> TrainingData:
        """Frames ``[start, stop)`` as a new split (contiguous in time).

        Joined temporal episodes keep the windows that lie within the range.
        """
        src = dict(self.source, split=name or self.source.get("split", ""), range=[start, stop])
        starts = self.window_starts
        if starts is not None:
            starts = starts[(starts >= start) & (starts + self.history <= stop)] - start
        return replace(
            self,
            transport=self.transport[start:stop],
            labels={k: v[start:stop] for k, v in self.labels.items()},
            source=src,
            scales=None if self.scales is None else self.scales[start:stop],
            window_starts=starts,
        )

    def with_static_part(self, static_w: np.ndarray, replacement_w: np.ndarray) -> TrainingData:
        """The frames with their static part replaced: ``T - static + replacement`` (W).

        E.g. every frame's converged background replaced by one fixed
        background: the movers in a room whose lighting never changes (an
        oracle's input). Float32 in memory.

        Args:
            static_w: ``[frame, detector, row, col]`` the frames' static part (W).
            replacement_w: ``[detector, row, col]`` what replaces it in every frame (W).

        Raises:
            ValueError: shapes that do not fit the frames.
        """
        if np.shape(static_w) != self.transport.shape:
            raise ValueError(
                f"static part has shape {np.shape(static_w)}; the frames {self.transport.shape}"
            )
        if np.shape(replacement_w) != self.transport.shape[1:]:
            raise ValueError(
                f"replacement has shape {np.shape(replacement_w)}; a frame "
                f"{self.transport.shape[1:]}"
            )
        frames = self.frames_np(0, len(self.transport)) - np.asarray(static_w, np.float32)
        frames += np.asarray(replacement_w, np.float32)
        src = dict(self.source, static_part="replaced")
        return replace(self, transport=frames, scales=None, source=src)

    def with_light_scaled(self, factor: float) -> TrainingData:
        """The same frames with every emitter's radiance times ``factor`` (> 0).

        Transport is linear in the radiance of the scene's emitters, so a scene
        ``factor`` times brighter has ``factor`` times the transport, frame by
        frame: only the per-frame ``scales`` change (no copy of the frames).
        """
        if not (math.isfinite(factor) and factor > 0):
            raise ValueError(f"light scale factor = {factor!r}: need a finite number > 0")
        n = len(self.transport)
        old = np.ones(n, np.float32) if self.scales is None else np.asarray(self.scales)
        src = dict(self.source, light_scale=float(factor) * self.source.get("light_scale", 1.0))
        return replace(self, scales=(old * np.float32(factor)).astype(np.float32), source=src)

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
            index: ``[b]`` samples (torch long, in ``[0, len(self))``).
            buffer: gather the frames into this reused float32 buffer (the
                batch's transport is then valid until the buffer's next use);
                None: a new tensor.

        """
        stored, scales, labels = self._tensors()
        index = self._first_frames(index)
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
        index = self._first_frames(index)
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


class CameraInputs(TypedDict):
    """A batch as the keyword arguments of a camera's ``forward`` / ``measure`` (torch)."""

    transport: torch.Tensor
    windows: torch.Tensor | None
    frame_scales: torch.Tensor | None


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

    def inputs(self) -> CameraInputs:
        """Keyword arguments of a camera's ``forward`` / ``measure`` for this batch."""
        return {
            "transport": self.transport,
            "windows": self.windows,
            "frame_scales": self.frame_scales,
        }

    def __len__(self) -> int:
        """Number of samples."""
        return len(self.transport) if self.windows is None else len(self.windows)


def render_frames(
    family: Any,
    scene: Any,
    camera: FreeformCamera,
    frames: Sequence[int],
    *,
    spp: int,
    seed: int,
    progress: bool = False,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Transport and labels of ``frames`` of a family, rendered in memory.

    Frame ``i`` is rendered with the family's estimator (as its datasets are)
    at seed ``stream_seed(seed, "render/in-memory", i)``.

    Args:
        family: the scene family.
        scene: its built Mitsuba scene.
        camera: the camera rendered.
        frames: frame indices, in order.
        spp: samples per texel.
        seed: root seed of the render streams, >= 0.
        progress: show a progress bar.

    Returns:
        ``(T[frame, detector, row, col]`` float32 (W), ``{label: values[frame, size]}``
        float32).
    """
    from tqdm import tqdm

    ts: list[np.ndarray] = []
    labs: dict[str, list] = {s.name: [] for s in family.labels}
    for i in tqdm(list(frames), desc=f"render {family.name}", disable=not progress):
        lab = family.set_frame(scene, int(i))
        seed_i = stream_seed(seed, "render/in-memory", int(i))
        ts.append(family.render_transport(scene, camera, spp=spp, seed=seed_i))
        for s in family.labels:
            labs[s.name].append(np.asarray(lab[s.name], np.float32).reshape(s.size))
    transport = np.stack(ts).astype(np.float32)
    return transport, {k: np.stack(v) for k, v in labs.items()}


def _manifest_sha256(ds: Any) -> str | None:
    """sha256 of the manifest of dataset ``ds`` (its content's identity); None without one."""
    from pathlib import Path

    from mincam_render.data.dataset import MANIFEST_NAME, sha256_file

    path = Path(getattr(ds, "path", "")) / MANIFEST_NAME
    return sha256_file(path) if path.is_file() else None


#: Fractions of an in-memory render that train, validate and test (in time order).
IN_MEMORY_SPLITS = (0.7, 0.1, 0.2)


def training_splits(
    dataset: str | os.PathLike | None, family: str | None, frames: int, spp: int, seed: int
) -> tuple[TrainingData, TrainingData, TrainingData]:
    """``(train, val, test)`` of a dataset directory, or of ``frames`` of ``family`` rendered here.

    Args:
        dataset: a dataset directory (``mincam-render render``); None: render ``family``.
        family: a family name or description, rendered in memory when ``dataset`` is None.
        frames: frames rendered, split :data:`IN_MEMORY_SPLITS` in time.
        spp: samples per texel of that render.
        seed: the family's and the render's seed.

    Raises:
        ValueError: the dataset has no training or no validation frames, or
            neither a dataset nor a family is given.
    """
    if dataset is not None:
        from mincam_render.data.dataset import open_dataset

        ds = open_dataset(dataset)
        sizes = {name: stop - start for name, (start, stop) in ds.splits.items()}
        empty = [name for name in ("train", "val") if sizes.get(name, 0) == 0]
        if empty:
            raise ValueError(
                f"{dataset} has no {' and no '.join(empty)} frames (split sizes {sizes}): "
                "training needs both; render it with e.g. --splits 0.7,0.1,0.2"
            )
        train, val, test = (TrainingData.from_dataset(ds, s) for s in ("train", "val", "test"))
        return train, val, test
    if family is None:
        raise ValueError("give a DATASET directory (mincam-render render) or --family")
    from mincam_render.scenes import load_family

    fam = load_family(family, seed=seed, num_frames=frames)
    log.info("rendering %d frames of %s in memory (%d spp)", frames, fam.name, spp)
    data = TrainingData.render(fam, range(frames), spp=spp, seed=seed, progress=True)
    train, val, test = data.split(IN_MEMORY_SPLITS)
    return train, val, test


def _joined_window_starts(parts: Sequence[TrainingData]) -> np.ndarray | None:
    """The first frame of every window of ``parts`` joined end to end (None: static parts)."""
    if parts[0].history == 1:
        return None
    starts, offset = [], 0
    for p in parts:
        own = np.arange(len(p)) if p.window_starts is None else np.asarray(p.window_starts)
        starts.append(own.astype(np.int64) + offset)
        offset += len(p.transport)
    return np.concatenate(starts)
