"""Rendered datasets on disk: shards of transport images, labels, metadata, manifest.

Layout of a dataset directory (see ``docs/dataset_format.md`` for every field)::

    manifest.json              configuration, fidelity decisions, versions, splits,
                               and one record (with sha256 checksums) per finished shard
    shards/shard-00000.npy     T[frame, detector, row, col], float16 or float32 (.npy)
    shards/shard-00000.json    per-frame metadata (time, render seed, scale, scene
                               state) and labels; written after the .npy, so its
                               presence marks a finished shard
    render_log.jsonl           append-only log of render runs (timings; not compared)

Transport values are watts per unit transmittance. Stored values are
``T / scale`` with a per-frame power-of-two ``scale`` (exact in binary floating
point), so float16 keeps its 11-bit precision for scenes from moonlight to sun;
readers return ``stored * scale`` as float32.

Every file is written atomically (temporary file, fsync, ``os.replace``, fsync of
the directory): a reader or a resumed render sees either the old file or the
complete new one. This module is numpy/JSON only (torch only inside
:meth:`TransportDataset.torch_dataset`); it never imports Mitsuba.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import math
import os
import uuid
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NotRequired, TypedDict

import numpy as np

from mincam_render.core.checks import check_int
from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.core.strict_json import to_strict
from mincam_render.optics.camera import (
    DetectorElectronics,
    DetectorLayout,
    DirectionalResponse,
    FreeformCamera,
)
from mincam_render.render.precision import decode_transport

if TYPE_CHECKING:
    import torch
    import torch.utils.data

log = logging.getLogger(__name__)

FORMAT_NAME = "mincam_render.transport_dataset"
#: 2: differential backgrounds carry B_1 (window end) and frames interpolate daylight.
#: 3: the same files; renders stratify each texel's samples and, for families with
#: a window, sample the sun apart with sunlit-patch connections
#: (mincam_render.render.sun_patch): a version-2 dataset resumed now would mix estimators.
#: 4: the same files; every derived seed comes from ``core.seeds.stream_seed``, daylight
#: from pvlib (SPA sun, simplified Solis clear sky), people's paths from networkx, and
#: the workspace, lighting and traffic cameras have the S9119-01 directional response:
#: the same request renders other bytes, so a version-3 dataset is read and trained on
#: but not resumed (docs/format_v4.md).
FORMAT_VERSION = 4
MANIFEST_NAME = "manifest.json"
#: Key of the manifest's own checksum (sha256 of the canonical JSON of the rest).
MANIFEST_CHECKSUM_KEY = "manifest_sha256"
SHARD_DIR = "shards"
#: Static backgrounds of differentially rendered datasets (mincam_render.render.differential).
BACKGROUND_DIR = "backgrounds"
LOG_NAME = "render_log.jsonl"
SPLIT_NAMES = ("train", "val", "test")
#: Storage types of transport images.


class DatasetError(ValueError):
    """A dataset directory is missing, incomplete, corrupted or of another configuration."""


# ---- small file utilities ------------------------------------------------------------


def sha256_file(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def fsync_dir(path: Path) -> None:
    """Flush a directory's entries (a rename into it) to disk, where the system allows."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically: temporary file, fsync, ``os.replace``, dir fsync.

    The temporary name is unique per process and call, so concurrent writers of
    the same (identical) file cannot interfere.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    fsync_dir(path.parent)
    return path


def remove_stale_temporaries(root: str | os.PathLike) -> list[Path]:
    """Delete temporaries of :func:`atomic_write_bytes` left by killed processes.

    A process killed between opening and renaming its temporary leaves
    ``.<name>.<pid>.<hex>.tmp`` behind; files of processes still running are kept.

    Returns:
        the files removed.
    """
    removed = []
    for tmp in Path(root).rglob(".*.tmp"):
        parts = tmp.name.rsplit(".", 3)
        if len(parts) != 4 or not parts[1].isdigit():
            continue
        try:
            os.kill(int(parts[1]), 0)
            continue  # its writer is alive
        except ProcessLookupError:
            pass
        except PermissionError:
            continue  # alive, owned by someone else
        tmp.unlink(missing_ok=True)
        removed.append(tmp)
    return removed


def json_bytes(obj: Any) -> bytes:
    """Canonical, strict JSON (sorted keys, fixed indentation): equal content, equal bytes.

    Non-finite numbers are written as null (:mod:`mincam_render.core.strict_json`).
    """
    text = json.dumps(
        to_strict(obj), indent=1, sort_keys=True, allow_nan=False, default=_json_default
    )
    return (text + "\n").encode()


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, tuple | set):
        return list(obj)
    if hasattr(obj, "value"):  # enums
        return obj.value
    return str(obj)


def npy_bytes(array: np.ndarray) -> bytes:
    """The ``.npy`` serialisation of ``array`` (no pickles)."""
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(array), allow_pickle=False)
    return buf.getvalue()


# ---- descriptions <-> JSON -------------------------------------------------------------


class LabelSpecRecord(TypedDict):
    """A label's description as manifests and run records hold it (:func:`label_spec_to_dict`)."""

    name: str
    kind: str
    size: int
    unit: str
    element_names: list[str]
    median_filter_s: float
    zero_below_true: NotRequired[float]
    headline: NotRequired[str]


def label_spec_to_dict(spec: LabelSpec) -> LabelSpecRecord:
    """JSON-ready description of a label.

    The evaluation rules ``zero_below_true`` and ``headline`` are written only
    when set, so manifests of labels without them are unchanged.
    """
    out: LabelSpecRecord = {
        "name": spec.name,
        "kind": spec.kind.value,
        "size": int(spec.size),
        "unit": spec.unit,
        "element_names": list(spec.element_names),
        "median_filter_s": float(spec.median_filter_s),
    }
    if spec.zero_below_true is not None:
        out["zero_below_true"] = float(spec.zero_below_true)
    if spec.headline:
        out["headline"] = spec.headline
    return out


def label_spec_from_dict(d: Mapping[str, Any]) -> LabelSpec:
    """Inverse of :func:`label_spec_to_dict`."""
    return LabelSpec(
        name=d["name"],
        kind=LabelKind(d["kind"]),
        size=int(d["size"]),
        unit=d.get("unit", ""),
        element_names=tuple(d.get("element_names", ())),
        median_filter_s=float(d.get("median_filter_s", 2.0)),
        zero_below_true=d.get("zero_below_true"),
        headline=str(d.get("headline", "")),
    )


def camera_to_dict(camera: FreeformCamera) -> dict:
    """JSON-ready description of a camera (SI units), read back by :func:`camera_from_dict`."""
    return json.loads(json.dumps(camera.to_dict(), default=_json_default))


def camera_from_dict(d: dict) -> FreeformCamera:
    """Rebuild a :class:`FreeformCamera` from :func:`camera_to_dict` (or ``to_dict``) output."""
    resp = d.get("directional_response")
    rows, cols = d["mask_resolution"]
    return FreeformCamera(
        detector_size_m=float(d["detector_size_m"]),
        mask_size_m=float(d["mask_size_m"]),
        mask_distance_m=float(d["mask_distance_m"]),
        mask_resolution=(int(rows), int(cols)),
        layout=DetectorLayout(
            positions_m=tuple((float(x), float(y)) for x, y in d["layout"]["positions_m"])
        ),
        position=tuple(d["position"]),
        look_at=tuple(d["look_at"]),
        up=tuple(d["up"]),
        directional_response=None
        if resp is None
        else DirectionalResponse(
            angles_deg=tuple(resp["angles_deg"]),
            relative_sensitivity=tuple(resp["relative_sensitivity"]),
        ),
        electronics=DetectorElectronics(**d["electronics"]),
        transmittance_range=tuple(d["transmittance_range"]),
    )


# ---- shards ----------------------------------------------------------------------------


def shard_paths(root: str | os.PathLike, index: int) -> tuple[Path, Path]:
    """``(transport .npy, metadata .json)`` paths of shard ``index``."""
    base = Path(root) / SHARD_DIR / f"shard-{index:05d}"
    return base.with_suffix(".npy"), base.with_suffix(".json")


def write_shard(
    root: str | os.PathLike,
    index: int,
    stored: np.ndarray,
    metadata: dict,
) -> dict:
    """Write shard ``index`` atomically and return its manifest record.

    The ``.npy`` is written first, then the ``.json`` (which holds the ``.npy``'s
    checksum), so a finished ``.json`` marks a finished shard.

    Args:
        root: dataset directory.
        index: shard number.
        stored: encoded ``T[frame, detector, row, col]`` (see
            :func:`~mincam_render.render.precision.encode_transport`).
        metadata: JSON-ready shard metadata (frames, labels, scales).

    Returns:
        ``{"index", "start", "stop", "frames", "transport", "transport_sha256",
        "metadata", "metadata_sha256"}``.
    """
    npy_path, json_path = shard_paths(root, index)
    npy_path.parent.mkdir(parents=True, exist_ok=True)
    data = npy_bytes(stored)
    sha_npy = hashlib.sha256(data).hexdigest()
    atomic_write_bytes(npy_path, data)
    meta = dict(metadata, transport_sha256=sha_npy)
    meta_data = json_bytes(meta)
    atomic_write_bytes(json_path, meta_data)
    return _shard_record(index, meta, sha_npy, hashlib.sha256(meta_data).hexdigest())


def verify_shard(
    root: str | os.PathLike, index: int, expected: dict | None = None
) -> tuple[dict | None, str]:
    """Check shard ``index`` against its checksums.

    Args:
        root: dataset directory.
        index: shard number.
        expected: the manifest's record of the shard, if any; then both files
            must match its checksums, else the ``.npy`` must match the checksum
            stored in the shard's ``.json``.

    Returns:
        ``(record, "")`` when the shard is intact, else ``(None, reason)``.
    """
    npy_path, json_path = shard_paths(root, index)
    if not json_path.is_file() or not npy_path.is_file():
        return None, "missing"
    meta_bytes = json_path.read_bytes()
    sha_meta = hashlib.sha256(meta_bytes).hexdigest()
    if expected is not None and expected.get("metadata_sha256") != sha_meta:
        return None, f"{json_path.name} does not match its sha256 in the manifest"
    try:
        meta = json.loads(meta_bytes)
    except ValueError:
        return None, f"{json_path.name} is not valid JSON (truncated?)"
    sha_npy = sha256_file(npy_path)
    if sha_npy != meta.get("transport_sha256"):
        return None, f"{npy_path.name} does not match its sha256 (corrupted or truncated)"
    return _shard_record(index, meta, sha_npy, sha_meta), ""


def _shard_record(index: int, meta: dict, sha_npy: str, sha_meta: str) -> dict:
    """The manifest's record of shard ``index`` from its metadata and checksums."""
    npy_path, json_path = shard_paths("", index)
    return {
        "index": index,
        "start": int(meta["start"]),
        "stop": int(meta["stop"]),
        "transport": f"{SHARD_DIR}/{npy_path.name}",
        "transport_sha256": sha_npy,
        "metadata": f"{SHARD_DIR}/{json_path.name}",
        "metadata_sha256": sha_meta,
    }


def read_manifest(root: str | os.PathLike) -> dict:
    """The parsed ``manifest.json`` of a dataset directory.

    Raises:
        DatasetError: no manifest, not JSON, another format, or no or a wrong checksum.
    """
    path = Path(root) / MANIFEST_NAME
    if not path.is_file():
        raise DatasetError(f"{root}: no {MANIFEST_NAME}; not a mincam_render dataset")
    try:
        manifest = json.loads(path.read_text())
    except ValueError as err:
        raise DatasetError(f"{path}: not valid JSON ({err})") from None
    if manifest.get("format") != FORMAT_NAME:
        raise DatasetError(f"{path}: format {manifest.get('format')!r}, expected {FORMAT_NAME!r}")
    recorded = manifest.pop(MANIFEST_CHECKSUM_KEY, None)
    if recorded is None:
        # a removed checksum is indistinguishable from a removed-then-edited one
        raise DatasetError(
            f"{path} has no {MANIFEST_CHECKSUM_KEY} (written before manifests carried one, "
            "or removed by hand), so the fields that define the data cannot be verified; run "
            f"`mincam-render repair {Path(root)}` to rebuild it from its request and its shards"
        )
    if recorded != _manifest_sha256(manifest):
        raise DatasetError(
            f"{path} was changed after it was written (its {MANIFEST_CHECKSUM_KEY} does not "
            "match): the fields that define the data cannot be trusted; run `mincam-render "
            f"repair {Path(root)}` to rebuild it from its request and its shards"
        )
    if manifest.get("format_version", 0) > FORMAT_VERSION:
        raise DatasetError(
            f"{path}: format version {manifest['format_version']} is newer than this "
            f"mincam_render reads ({FORMAT_VERSION}); upgrade mincam_render"
        )
    return manifest


def write_manifest(root: str | os.PathLike, manifest: dict) -> Path:
    """Write ``manifest.json`` atomically (canonical JSON) with its own checksum.

    The checksum (:data:`MANIFEST_CHECKSUM_KEY`, sha256 of the canonical JSON of
    everything else) makes any later edit detectable by :func:`read_manifest`,
    which refuses a manifest without one (``mincam-render repair`` adds it).
    """
    body = {k: v for k, v in manifest.items() if k != MANIFEST_CHECKSUM_KEY}
    protected = body | {MANIFEST_CHECKSUM_KEY: _manifest_sha256(body)}
    return atomic_write_bytes(Path(root) / MANIFEST_NAME, json_bytes(protected))


def _manifest_sha256(body: dict) -> str:
    return hashlib.sha256(json_bytes(body)).hexdigest()


def split_ranges(num_frames: int, fractions: Sequence[float]) -> dict[str, tuple[int, int]]:
    """Contiguous ``[start, stop)`` ranges of train/val/test for ``fractions`` summing to 1.

    Raises:
        ValueError: not three non-negative fractions summing to 1 (within 1e-6).
    """
    fr = [float(f) for f in fractions]
    if len(fr) != 3 or any(not math.isfinite(f) or f < 0 for f in fr) or abs(sum(fr) - 1) > 1e-6:
        raise ValueError(
            f"splits = {list(fractions)}: allowed three fractions >= 0 (train, val, test) "
            "summing to 1"
        )
    b1 = round(num_frames * fr[0])
    b2 = round(num_frames * (fr[0] + fr[1]))
    return {"train": (0, b1), "val": (b1, b2), "test": (b2, num_frames)}


def parse_frame_list(text: str, num_frames: int) -> list[int]:
    """Frame indices from ``"0,5,10-12"`` (ranges inclusive), each in [0, num_frames).

    Raises:
        ValueError: malformed text or an index out of range.
    """
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        try:
            if "-" in part:
                a, b = (int(p) for p in part.split("-", 1))
                out.extend(range(a, b + 1))
            else:
                out.append(int(part))
        except ValueError:
            raise ValueError(f"frames = {text!r}: expected indices like 0,5,10-12") from None
    bad = [i for i in out if not 0 <= i < num_frames]
    if bad or not out:
        raise ValueError(f"frames = {text!r}: allowed indices in [0, {num_frames - 1}]")
    return out


# ---- reading -----------------------------------------------------------------------------


class TransportDataset:
    """A finished dataset directory, read lazily (shards are memory-mapped).

    Attributes:
        path: the directory.
        manifest: the parsed manifest.
        family: scene family name.
        fps: frames per second of the sequence.
        camera: the camera the transport images belong to.
        label_specs: the family's labels.
        num_frames: frames in the dataset.
        splits: ``{"train"|"val"|"test": (start, stop)}`` contiguous frame ranges.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self.manifest = read_manifest(self.path)
        m = self.manifest
        shards = m["shards"]
        missing = [i for i, s in enumerate(shards) if s is None]
        if missing or not m.get("complete", False):
            raise DatasetError(
                f"{self.path}: dataset is incomplete ({len(shards) - len(missing)} of "
                f"{len(shards)} shards); run the same render command again to finish it"
            )
        self.family: str = m["family"]["name"]
        self.fps = float(m["family"]["fps"])
        self.camera = camera_from_dict(m["camera"])
        self.label_specs = tuple(label_spec_from_dict(d) for d in m["label_specs"])
        self.num_frames = int(m["num_frames"])
        self.shard_frames = int(m["shard_frames"])
        self.splits = {k: (int(v[0]), int(v[1])) for k, v in m["splits"].items()}
        self._arrays: dict[int, np.ndarray] = {}
        self._meta: dict[int, dict] = {}

    def __repr__(self) -> str:
        k, (r, c) = self.camera.num_detectors, self.camera.mask_resolution
        return (
            f"TransportDataset({str(self.path)!r}, family={self.family!r}, "
            f"frames={self.num_frames}, T=[{k}, {r}, {c}], splits={self.splits})"
        )

    def __getstate__(self) -> dict:
        # memory maps do not travel to DataLoader workers; they reopen lazily
        state = dict(self.__dict__)
        state["_arrays"] = {}
        return state

    def __len__(self) -> int:
        return self.num_frames

    # ---- per-shard access ----------------------------------------------------------

    def _shard_of(self, index: int) -> int:
        if not 0 <= index < self.num_frames:
            raise IndexError(f"frame {index} outside [0, {self.num_frames})")
        return index // self.shard_frames

    def _array(self, shard: int) -> np.ndarray:
        arr = self._arrays.get(shard)
        if arr is None:
            path = shard_paths(self.path, shard)[0]
            try:
                arr = np.load(path, mmap_mode="r", allow_pickle=False)
            except (OSError, ValueError) as err:  # missing, truncated, not a .npy
                raise DatasetError(
                    f"{path}: shard unreadable ({str(err).splitlines()[0][:100]}); run the "
                    "same render command again to repair it"
                ) from None
            self._arrays[shard] = arr
        return arr

    def _metadata(self, shard: int) -> dict:
        meta = self._meta.get(shard)
        if meta is None:
            path = shard_paths(self.path, shard)[1]
            try:
                raw = json.loads(path.read_text())
            except (OSError, ValueError) as err:
                raise DatasetError(
                    f"{path}: shard metadata unreadable ({str(err).splitlines()[0][:100]}); "
                    "run the same render command again to repair it"
                ) from None
            meta = {
                "start": raw["start"],
                "frames": raw["frames"],
                "scales": np.asarray([f["scale"] for f in raw["frames"]], dtype=np.float64),
                "times_s": np.asarray([f["time_s"] for f in raw["frames"]], dtype=np.float64),
                "labels": {
                    s.name: np.asarray(raw["labels"][s.name], dtype=np.float32).reshape(-1, s.size)
                    for s in self.label_specs
                },
            }
            self._meta[shard] = meta
        return meta

    def _pieces(self, start: int, stop: int) -> Iterable[tuple[int, int, int]]:
        """``(shard, lo, hi)`` local ranges covering frames [start, stop)."""
        i = start
        while i < stop:
            shard = i // self.shard_frames
            base = shard * self.shard_frames
            hi = min(stop, base + self.shard_frames)
            yield shard, i - base, hi - base
            i = hi

    def _range(self, split_or_range: str | tuple[int, int]) -> tuple[int, int]:
        if isinstance(split_or_range, str):
            if split_or_range not in self.splits:
                raise KeyError(f"split {split_or_range!r}: allowed {', '.join(self.splits)}")
            return self.splits[split_or_range]
        start, stop = split_or_range
        if not 0 <= start <= stop <= self.num_frames:
            raise IndexError(f"frames [{start}, {stop}) outside [0, {self.num_frames}]")
        return int(start), int(stop)

    def frames(self, start: int, stop: int) -> np.ndarray:
        """``T[frame, detector, row, col]`` (float32 W) of frames [start, stop)."""
        k, (r, c) = self.camera.num_detectors, self.camera.mask_resolution
        out = np.empty((stop - start, k, r, c), dtype=np.float32)
        pos = 0
        for shard, lo, hi in self._pieces(start, stop):
            scales = self._metadata(shard)["scales"][lo:hi]
            out[pos : pos + hi - lo] = decode_transport(self._array(shard)[lo:hi], scales)
            pos += hi - lo
        return out

    def frame(self, index: int) -> np.ndarray:
        """``T[detector, row, col]`` (float32 W) of one frame."""
        shard = self._shard_of(index)
        lo = index - shard * self.shard_frames
        scale = np.float32(self._metadata(shard)["scales"][lo])
        return np.asarray(self._array(shard)[lo], dtype=np.float32) * scale

    def frame_labels(self, index: int) -> dict[str, np.ndarray]:
        """``{label: float32 [size]}`` of one frame."""
        shard = self._shard_of(index)
        lo = index - shard * self.shard_frames
        return {k: v[lo] for k, v in self._metadata(shard)["labels"].items()}

    def frame_metadata(self, index: int) -> dict:
        """Per-frame metadata: ``index``, ``time_s``, render ``seed``, ``scale``, ``state``."""
        shard = self._shard_of(index)
        return self._metadata(shard)["frames"][index - shard * self.shard_frames]

    # ---- per-split access (the training interface) -----------------------------------

    def transport(self, split: str | tuple[int, int]) -> np.ndarray:
        """``T[frame, detector, row, col]`` float32 (W) of a split, loaded into memory."""
        return self.frames(*self._range(split))

    def stored_transport(self, split: str | tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """Stored values ``T / scale`` of a split and their per-frame scales (the training view).

        Returns:
            ``(stored, scales)``: ``stored[frame, detector, row, col]`` in the file's
            type (float16 or float32), memory-mapped (no copy) when the split lies
            in one shard, else one concatenation of the stored values (half the
            memory of :meth:`transport` for float16); ``scales`` float32 ``[N]``,
            so that ``T = stored * scales[:, None, None, None]`` (W).
        """
        start, stop = self._range(split)
        pieces = list(self._pieces(start, stop))
        arrays = [self._array(shard)[lo:hi] for shard, lo, hi in pieces]
        scales = [self._metadata(shard)["scales"][lo:hi] for shard, lo, hi in pieces]
        if not arrays:
            k, (r, c) = self.camera.num_detectors, self.camera.mask_resolution
            return np.zeros((0, k, r, c), np.float32), np.zeros(0, np.float32)
        stored = arrays[0] if len(arrays) == 1 else np.concatenate(arrays)
        return stored, np.concatenate(scales).astype(np.float32)

    def labels(self, split: str | tuple[int, int]) -> dict[str, np.ndarray]:
        """``{label: float32 [N, size]}`` of a split."""
        start, stop = self._range(split)
        parts: dict[str, list[np.ndarray]] = {s.name: [] for s in self.label_specs}
        for shard, lo, hi in self._pieces(start, stop):
            for name, arr in self._metadata(shard)["labels"].items():
                parts[name].append(arr[lo:hi])
        return {
            s.name: (
                np.concatenate(parts[s.name])
                if parts[s.name]
                else np.zeros((0, s.size), np.float32)
            )
            for s in self.label_specs
        }

    def times_s(self, split: str | tuple[int, int]) -> np.ndarray:
        """Frame times (s, float64 [N]) of a split."""
        start, stop = self._range(split)
        parts = [self._metadata(s)["times_s"][lo:hi] for s, lo, hi in self._pieces(start, stop)]
        return np.concatenate(parts) if parts else np.zeros(0)

    def torch_dataset(self, split: str, history: int = 1) -> torch.utils.data.Dataset:
        """A ``torch.utils.data.Dataset`` over a split, reading shards lazily (mmap).

        Item ``j`` is frame ``i = start + history - 1 + j`` of the split:
        ``(T, labels)`` with ``T`` a float32 tensor ``[K, R, C]`` (``history == 1``)
        or ``[H, K, R, C]`` holding frames ``i-H+1 .. i`` (oldest first), and
        ``labels`` ``{name: float32 tensor [size]}`` of frame ``i``. The first
        ``H - 1`` frames of the split have no full history and are skipped, so
        windows never cross split boundaries.

        Raises:
            ValueError: ``history`` < 1 or longer than the split.
        """
        return __getattr__("TransportTorchDataset")(self, split, history)

    # ---- checks and export ----------------------------------------------------------

    def verify(self, shards: Iterable[int] | None = None) -> list[tuple[int, str]]:
        """Shards that fail their checksums: ``[(shard, reason), ...]`` (empty = intact).

        Args:
            shards: the shards to check; None checks all.
        """
        bad = []
        for i in range(len(self.manifest["shards"])) if shards is None else sorted(set(shards)):
            ok, reason = verify_shard(self.path, i, self.manifest["shards"][i])
            if ok is None:
                bad.append((i, reason))
        return bad

    def check_intact(self, frames: Iterable[int] | None = None) -> None:
        """Raise a one-line :class:`DatasetError` naming the first damaged shard.

        Every reader calls this before using the data: training readers check every
        shard (one checksum pass per opened dataset, about 0.3 s per 100 MB here);
        readers of a few ``frames`` check only the shards holding them. A shard is
        checked at most once per opened dataset.
        """
        verified = self.__dict__.setdefault("_verified", set())
        wanted = (
            set(range(len(self.manifest["shards"])))
            if frames is None
            else {self._shard_of(int(i)) for i in frames}
        )
        bad = self.verify(wanted - verified)
        if bad:
            shard, reason = bad[0]
            if reason == "missing":
                npy, meta = shard_paths(self.path, shard)
                reason = f"{npy.name} or {meta.name} is missing"
            raise DatasetError(
                f"{self.path}: shard {shard}: {reason} ({len(bad)} damaged shard(s) "
                "among those checked); "
                f"re-run the same `mincam-render render ... --out {self.path}` to re-render "
                "them"
            )
        verified |= wanted

    def export_exr(self, indices: Iterable[int], out_dir: str | os.PathLike) -> list[Path]:
        """Write chosen frames as OpenEXR (one float32 channel per detector, W).

        Each file ``frame-000123.exr`` carries the frame's metadata, labels and
        the camera in its header (``mincam_metadata``). The shards holding the
        frames are verified first: a damaged one is an error and nothing is written.

        Returns:
            The written paths.
        """
        from mincam_render.data.exr import write_transport_exr

        indices = list(indices)
        self.check_intact(indices)
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = []
        for i in indices:
            meta = {
                "dataset": str(self.path),
                "family": self.family,
                "frame": self.frame_metadata(i),
                "labels": {k: v.tolist() for k, v in self.frame_labels(i).items()},
                "camera": self.manifest["camera"],
                "units": "W per unit transmittance",
                "array_axes": "T[detector, row, col]; row 0 = up side, col 0 = left",
            }
            paths.append(write_transport_exr(out / f"frame-{i:06d}.exr", self.frame(i), meta))
        return paths


def open_dataset(path: str | os.PathLike) -> TransportDataset:
    """Open a finished dataset directory written by ``mincam-render render``.

    Raises:
        DatasetError: not a dataset, unreadable manifest, or unfinished render.
    """
    return TransportDataset(path)


_TORCH_CLASSES: dict[str, type] = {}


def __getattr__(name: str) -> type:
    # TransportTorchDataset subclasses torch's Dataset; it is built on first use so
    # that importing this module (e.g. in render workers) does not import torch.
    # Module-level __getattr__ (PEP 562) also lets pickle find it by name.
    if name == "TransportTorchDataset":
        if name not in _TORCH_CLASSES:
            _TORCH_CLASSES[name] = _make_torch_dataset_class()
        return _TORCH_CLASSES[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _make_torch_dataset_class() -> type:
    import torch
    import torch.utils.data

    class TransportTorchDataset(torch.utils.data.Dataset):
        """Torch view of one split (see :meth:`TransportDataset.torch_dataset`)."""

        def __init__(self, dataset: TransportDataset, split: str, history: int = 1) -> None:
            start, stop = dataset._range(split)
            check_int("history", history, 1, unit="frames")
            if history > stop - start:
                raise ValueError(
                    f"history = {history} frames is longer than split {split!r} "
                    f"({stop - start} frames)"
                )
            self.dataset = dataset
            self.split = split
            self.history = history
            #: dataset frame index of each item (the newest frame of its window)
            self.frame_indices = np.arange(start + history - 1, stop)

        def __len__(self) -> int:
            return len(self.frame_indices)

        def __getitem__(self, j: int) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
            if not -len(self) <= j < len(self):
                raise IndexError(f"item {j} outside [0, {len(self)})")
            i = int(self.frame_indices[j])
            if self.history == 1:
                t = self.dataset.frame(i)
            else:
                t = self.dataset.frames(i - self.history + 1, i + 1)
            labels = {
                k: torch.from_numpy(np.array(v)) for k, v in self.dataset.frame_labels(i).items()
            }
            return torch.from_numpy(t), labels

    TransportTorchDataset.__module__ = __name__
    TransportTorchDataset.__qualname__ = "TransportTorchDataset"
    return TransportTorchDataset
