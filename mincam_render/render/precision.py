"""Storage precision of transport images and the measurement error it causes (numpy).

Stored values are ``T / scale`` with a per-frame power-of-two ``scale`` (exact in
binary floating point), so float16 keeps its 11-bit precision for scenes from
moonlight to sun. The fidelity planner picks the storage dtype from
:func:`measurement_relative_error`; datasets store with :func:`encode_transport`
and read with :func:`decode_transport`.
"""

from __future__ import annotations

import numpy as np

#: Storage dtypes of transport images.
DTYPES = ("float16", "float32")
#: What a measurement error is relative to (:func:`measurement_relative_error`):
#: each frame's own measurement, or the mean measurement over the frames.
ERROR_SCALES = ("frame", "mean")


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


def encode_transport(transport_w: np.ndarray, dtype: str) -> tuple[np.ndarray, np.ndarray]:
    """Stored array and per-frame scales for ``T[frame, detector, row, col]`` (W).

    Args:
        transport_w: float32 transport images, finite.
        dtype: ``"float16"`` (scaled per frame) or ``"float32"`` (scale 1).

    Returns:
        ``(stored, scales)``: little-endian array of ``dtype`` and float64 scales [N].

    Raises:
        ValueError: unknown dtype or non-finite values.
    """
    if dtype not in DTYPES:
        raise ValueError(f"dtype = {dtype!r}: allowed {', '.join(DTYPES)}")
    t = np.asarray(transport_w, dtype=np.float32)
    if not np.all(np.isfinite(t)):
        raise ValueError("transport images contain NaN or infinity; refusing to store them")
    if dtype == "float32":
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
    scale: str = "frame",
) -> dict[str, float]:
    """Relative error of measurements ``P = sum_uv T M`` for random printable masks.

    Half of the masks have i.i.d. uniform transmittance in the printable range,
    half are binary (printable minimum or maximum, 10 % open), which selects few
    texels and so is the harder case for rounding and noise.

    ``scale="frame"`` divides each error by its own frame's ``|P_ref|`` (frames
    without light are left out); ``scale="mean"`` divides it by the mean of
    ``|P_ref|`` over the frames (per detector and mask), so a frame ten times
    dimmer than the others weighs by its absolute error, not ten times more.

    Args:
        transport_w: ``T[frame, detector, row, col]`` under test (W).
        reference_w: the reference, same shape (W).
        transmittance_range: printable ``(lo, hi)``.
        num_masks: masks per detector.
        seed: seed of the masks.
        scale: ``"frame"`` or ``"mean"`` (:data:`ERROR_SCALES`).

    Returns:
        ``{"rms": ..., "max": ...}``: RMS over frames, detectors and masks of
        ``|P - P_ref| / |P_ref|`` (``|P_ref|`` per frame or its mean over frames),
        and the maximum.

    Raises:
        ValueError: shapes differ or are not 4-D; unknown ``scale``.
    """
    t = np.asarray(transport_w, dtype=np.float64)
    ref = np.asarray(reference_w, dtype=np.float64)
    if t.shape != ref.shape or t.ndim != 4:
        raise ValueError(f"shapes {t.shape} and {ref.shape}: expected equal [N, K, R, C]")
    if scale not in ERROR_SCALES:
        raise ValueError(f"scale = {scale!r}: allowed {', '.join(ERROR_SCALES)}")
    lo, hi = transmittance_range
    rng = np.random.default_rng(seed)
    _, k, rows, cols = t.shape
    half = num_masks // 2
    uniform = rng.uniform(lo, hi, size=(num_masks - half, k, rows, cols))
    binary = np.where(rng.random((half, k, rows, cols)) < 0.1, hi, lo)
    masks = np.concatenate([uniform, binary])
    p = np.einsum("nkrc,mkrc->nmk", t, masks)
    p_ref = np.einsum("nkrc,mkrc->nmk", ref, masks)
    denom = np.abs(p_ref)
    if scale == "mean":
        denom = np.broadcast_to(denom.mean(axis=0), denom.shape)
    ok = denom > 0
    if not np.any(ok):
        return {"rms": 0.0, "max": 0.0}
    rel = np.abs(p - p_ref)[ok] / denom[ok]
    return {"rms": float(np.sqrt(np.mean(rel**2))), "max": float(rel.max())}
