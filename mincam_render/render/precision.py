"""Storage precision of transport images and the measurement errors of renders (numpy).

Stored values are ``T / scale`` with a per-frame power-of-two ``scale`` (exact in
binary floating point), so float16 keeps its 11-bit precision for scenes from
moonlight to sun. The fidelity planner picks the storage dtype from
:func:`measurement_relative_error`; datasets store with :func:`encode_transport`
and read with :func:`decode_transport`.

Measurement errors are relative to an :class:`ErrorScale`: the frame's total
power, its mean over frames, or the *label signal* (:class:`LabelSignal`): the
spread over frames of what the state the labels are computed from changes in
each measurement. In the indoor tasks one person changes a measurement by about
1 % of its total, so an error "within 1 % of the total" can equal the signal
the camera must read; relative to the signal it reads as what it is.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


class StorageDtype(enum.StrEnum):
    """Storage type of transport images in a dataset's shards (:func:`encode_transport`)."""

    FLOAT16 = "float16"  # scaled per frame by a power of two (frame_scales)
    FLOAT32 = "float32"  # as rendered, scale 1


#: The storage types' names (:class:`StorageDtype`).
DTYPES = tuple(d.value for d in StorageDtype)


def storage_dtype(value: str, name: str = "dtype") -> StorageDtype:
    """``value`` as a :class:`StorageDtype`.

    Raises:
        ValueError: another value, naming ``name`` and the allowed ones.
    """
    try:
        return StorageDtype(value)
    except ValueError:
        raise ValueError(f"{name} = {value!r}: allowed {', '.join(DTYPES)}") from None


class ErrorScale(enum.StrEnum):
    """What a measurement error is relative to (:func:`measurement_relative_error`)."""

    FRAME = "frame"  # each frame's own measurement |P_ref|
    MEAN = "mean"  # the mean of |P_ref| over the frames, per detector and mask
    SIGNAL = "signal"  # the label signal's RMS over frames (LabelSignal)


#: The error scales' names (:class:`ErrorScale`).
ERROR_SCALES = tuple(s.value for s in ErrorScale)


class UnmeasurableSignalError(ValueError):
    """An error relative to a label signal whose RMS is 0 (:meth:`LabelSignal.rms`)."""


@dataclass(frozen=True)
class LabelSignal:
    """Transport images of the label signal: what the labels' state changes, over frames.

    Each part is one thing the labels read (the movers; or one switched light
    each), rendered as two estimates with independent Monte Carlo noise,
    ``S[estimate, frame, detector, row, col]`` (W, numpy). The signal of a
    measurement is the spread over frames of the part's measurement about its
    mean (the static background, constant over frames, drops out); the
    covariance of the two estimates has no noise term, so the figure is the
    signal's, not the signal's plus its estimate's noise. With one estimate
    (``S[1, ...]``) it is the plain spread.

    Where the labels are read from the change between frames (frame steps,
    ``S[f + 1] - S[f]``), a frame's render error reaches them through two
    frames: ``noise_gain`` says by how much (``sqrt(2)`` for frames whose noises
    do not correlate), and signal-relative errors are counted that many times.

    Args:
        parts: one array per part, each ``[1 or 2, frame >= 2, detector, row, col]``.
        noise_gain: what one frame's render error becomes where the signal is
            read (1: on the frames themselves).

    Raises:
        ValueError: no part, a part of another shape, or a gain not > 0.
    """

    parts: tuple[np.ndarray, ...]
    noise_gain: float = 1.0

    def __post_init__(self) -> None:
        if not self.parts:
            raise ValueError("LabelSignal.parts is empty: give at least one part")
        if not (math.isfinite(self.noise_gain) and self.noise_gain > 0):
            raise ValueError(
                f"LabelSignal.noise_gain = {self.noise_gain!r}: allowed a finite number > 0"
            )
        for i, part in enumerate(self.parts):
            if part.ndim != 5 or part.shape[0] not in (1, 2) or part.shape[1] < 2:
                raise ValueError(
                    f"LabelSignal.parts[{i}] has shape {part.shape}: expected "
                    "[1 or 2 estimates, >= 2 frames, detector, row, col]"
                )

    def rms(self, measure: Callable[[np.ndarray], np.ndarray]) -> float:
        """The weakest part's RMS over frames of its measurements about their mean (W).

        0 where the two estimates do not co-vary over frames (no signal, or one
        below their noise).

        Args:
            measure: ``T[frame, detector, row, col] -> P[frame, ...]`` (the masks
                or box pixels the errors are measured with).
        """
        return min(_spread_rms(np.stack([measure(e) for e in part])) for part in self.parts)

    def error_scale_w(self, measure: Callable[[np.ndarray], np.ndarray]) -> float:
        """What one frame's render error is divided by on the signal scale (W).

        :meth:`rms` over :attr:`noise_gain`.

        Raises:
            UnmeasurableSignalError: the RMS is 0 (a relative error would be
                undefined, not 0).
        """
        signal_rms = self.rms(measure)
        if not signal_rms > 0:
            raise UnmeasurableSignalError(
                "the label signal is not measurable for these masks: its two estimates "
                "do not co-vary over frames (nothing the labels read changes in the "
                "signal's frames, or the change is below the estimates' render noise), "
                "so an error relative to it is undefined; check the family's "
                "label_signal source against what its labels read"
            )
        return signal_rms / self.noise_gain


def _spread_rms(p: np.ndarray) -> float:
    """RMS over frames (axis 1) about the mean, pooled; ``p[estimate, frame, ...]``."""
    dev = p - p.mean(axis=1, keepdims=True)
    power = np.mean(dev[0] * dev[-1])  # two estimates: their noises do not correlate
    return float(np.sqrt(max(power, 0.0)))


def printable_masks(
    num: int, shape: tuple[int, ...], transmittance_range: tuple[float, float], seed: int
) -> np.ndarray:
    """Random printable masks ``M[mask, *shape]``: half i.i.d. uniform, half binary.

    The binary half is at the printable minimum or maximum with 10 % of texels
    open: they select few texels, the harder case for rounding and noise.
    """
    lo, hi = transmittance_range
    rng = np.random.default_rng(seed)
    half = num // 2
    uniform = rng.uniform(lo, hi, size=(num - half, *shape))
    binary = np.where(rng.random((half, *shape)) < 0.1, hi, lo)
    return np.concatenate([uniform, binary])


def smooth_masks(
    num: int, shape: tuple[int, int, int], transmittance_range: tuple[float, float], seed: int
) -> np.ndarray:
    """Trained-like masks ``M[mask, detector, row, col]``: smooth random fields in range.

    White noise low-pass filtered in the Fourier domain (cut-off a quarter of the
    mask's width), standardised, and squashed by a logistic function into the
    printable range, so masks have blobs of open and dark regions like trained ones.
    """
    k, rows, cols = shape
    lo, hi = transmittance_range
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((num, k, rows, cols))
    fy = np.fft.fftfreq(rows)[:, None]
    fx = np.fft.fftfreq(cols)[None, :]
    cutoff = 4.0 / max(rows, cols)  # about four blobs across the mask
    filt = np.exp(-0.5 * (fx**2 + fy**2) / cutoff**2)
    field = np.fft.ifft2(np.fft.fft2(noise) * filt).real
    field = (field - field.mean(axis=(-2, -1), keepdims=True)) / (
        field.std(axis=(-2, -1), keepdims=True) + 1e-12
    )
    return lo + (hi - lo) / (1.0 + np.exp(-2.0 * field))


def box_measurements(transport_w: np.ndarray, box_texels: int) -> np.ndarray:
    """Box pixels' measurements ``P[frame, detector, row, col]`` (W): sums of texel blocks.

    A box pixel of ``box_texels`` x ``box_texels`` texels is the pixel of a
    conventional camera (open block, the rest dark); 1 is a single texel, the
    finest pixel the rendered texels allow.

    Raises:
        ValueError: ``box_texels`` does not divide the rows and columns.
    """
    t = np.asarray(transport_w, dtype=np.float64)
    n, k, rows, cols = t.shape
    b = int(box_texels)
    if b < 1 or rows % b or cols % b:
        raise ValueError(f"box_texels = {box_texels!r}: allowed a divisor of {rows} and {cols}")
    return t.reshape(n, k, rows // b, b, cols // b, b).sum(axis=(3, 5))


def frame_scales(transport_w: np.ndarray) -> np.ndarray:
    """Per-frame power-of-two scales ``2^ceil(log2(max |T|))`` (float64, shape [N]).

    Dividing by a power of two is exact, so only the float16 rounding remains;
    stored values lie in [-1, 1]. Frames that are all zero get scale 1.
    """
    t = np.asarray(transport_w)
    peak = np.abs(t.reshape(t.shape[0], -1)).max(axis=1).astype(np.float64)
    scales = np.ones_like(peak)
    pos = peak > 0
    scales[pos] = np.exp2(np.ceil(np.log2(peak[pos])))
    return scales


def encode_transport(
    transport_w: np.ndarray, dtype: StorageDtype | str
) -> tuple[np.ndarray, np.ndarray]:
    """Stored array and per-frame scales for ``T[frame, detector, row, col]`` (W).

    Args:
        transport_w: float32 transport images, finite.
        dtype: :class:`StorageDtype` (or its value): ``FLOAT16`` (scaled per
            frame) or ``FLOAT32`` (scale 1).

    Returns:
        ``(stored, scales)``: little-endian array of ``dtype`` and float64 scales [N].

    Raises:
        ValueError: unknown dtype or non-finite values.
    """
    dtype = storage_dtype(dtype)
    t = np.asarray(transport_w, dtype=np.float32)
    if not np.all(np.isfinite(t)):
        raise ValueError("transport images contain NaN or infinity; refusing to store them")
    if dtype is StorageDtype.FLOAT32:
        return t.astype("<f4"), np.ones(t.shape[0])
    scales = frame_scales(t)
    shape = (-1,) + (1,) * (t.ndim - 1)
    stored = (t / scales.reshape(shape).astype(np.float32)).astype("<f2")
    return stored, scales


def decode_transport(stored: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """Inverse of :func:`encode_transport`: float32 watts."""
    shape = (-1,) + (1,) * (stored.ndim - 1)
    return np.asarray(stored, dtype=np.float32) * np.asarray(scales, np.float32).reshape(shape)


def measurement_relative_error(
    transport_w: np.ndarray,
    reference_w: np.ndarray,
    transmittance_range: tuple[float, float],
    *,
    num_masks: int = 16,
    seed: int = 0,
    scale: ErrorScale | str = ErrorScale.FRAME,
    signal: LabelSignal | None = None,
    box_texels: int | None = None,
) -> dict[str, float]:
    r"""Relative error of measurements ``P = sum_uv T M`` for random printable masks.

    The masks are :func:`printable_masks`, or with ``box_texels`` the box pixels
    of that size (:func:`box_measurements`).

    ``scale="frame"`` divides each error by its own frame's ``|P_ref|`` (frames
    without light are left out); ``scale="mean"`` divides it by the mean of
    ``|P_ref|`` over the frames (per detector and mask), so a frame ten times
    dimmer than the others weighs by its absolute error, not ten times more;
    ``scale="signal"`` divides every error by the label signal's RMS for the
    same masks (:meth:`LabelSignal.rms`, pooled over detectors and masks) and
    counts it ``g = signal.noise_gain`` times (frame steps: sqrt(2);
    :meth:`LabelSignal.error_scale_w`).

    .. math::

        e_\text{signal} = g \, \frac{\sqrt{\langle (P - P_\text{ref})^2 \rangle}}
            {\sqrt{\langle (S - \bar S)^2 \rangle}}

    with ``S`` a measurement of the label signal and ``\bar S`` its mean over frames.

    Args:
        transport_w: ``T[frame, detector, row, col]`` under test (W).
        reference_w: the reference, same shape (W).
        transmittance_range: printable ``(lo, hi)``.
        num_masks: masks per detector.
        seed: seed of the masks.
        scale: an :class:`ErrorScale` (or its value).
        signal: the label signal; required with ``scale="signal"``.
        box_texels: measure box pixels of this many texels per side instead.

    Returns:
        ``{"rms": ..., "max": ...}``: RMS over frames, detectors and masks of
        the relative error, and its maximum.

    Raises:
        ValueError: shapes differ or are not 4-D; unknown ``scale``; ``"signal"``
            without a signal; a box size that does not divide the texels.
        UnmeasurableSignalError: ``"signal"`` with a signal whose RMS is 0 for
            these masks (:meth:`LabelSignal.error_scale_w`).
    """
    t = np.asarray(transport_w, dtype=np.float64)
    ref = np.asarray(reference_w, dtype=np.float64)
    if t.shape != ref.shape or t.ndim != 4:
        raise ValueError(f"shapes {t.shape} and {ref.shape}: expected equal [N, K, R, C]")
    if scale not in ERROR_SCALES:
        raise ValueError(f"scale = {scale!r}: allowed {', '.join(ERROR_SCALES)}")
    scale = ErrorScale(scale)
    if scale is ErrorScale.SIGNAL and signal is None:
        raise ValueError("scale = 'signal' needs the label signal (signal=LabelSignal)")
    measure = measurements_of(
        t.shape[1:], transmittance_range, num_masks=num_masks, seed=seed, box_texels=box_texels
    )
    p, p_ref = measure(t), measure(ref)
    denom = np.abs(p_ref)
    if scale is ErrorScale.MEAN:
        denom = np.broadcast_to(denom.mean(axis=0), denom.shape)
    elif scale is ErrorScale.SIGNAL:
        assert signal is not None  # checked above
        denom = np.full(p.shape, signal.error_scale_w(measure))
    ok = denom > 0
    if not np.any(ok):
        return {"rms": 0.0, "max": 0.0}
    rel = np.abs(p - p_ref)[ok] / denom[ok]
    return {"rms": float(np.sqrt(np.mean(rel**2))), "max": float(rel.max())}


def measurements_of(
    shape: tuple[int, ...],
    transmittance_range: tuple[float, float],
    *,
    num_masks: int = 16,
    seed: int = 0,
    box_texels: int | None = None,
) -> Callable[[np.ndarray], np.ndarray]:
    """``T[frame, detector, row, col] -> P[frame, ...]`` (W) of the errors' masks.

    Args:
        shape: ``(detector, row, col)`` of the transport images.
        transmittance_range: printable ``(lo, hi)``.
        num_masks: random printable masks per detector (:func:`printable_masks`).
        seed: their seed.
        box_texels: box pixels of this size (:func:`box_measurements`) instead.
    """
    if box_texels is not None:
        return lambda t: box_measurements(t, box_texels)
    masks = printable_masks(num_masks, shape, transmittance_range, seed)
    return lambda t: np.einsum("nkrc,mkrc->nmk", np.asarray(t, np.float64), masks)
