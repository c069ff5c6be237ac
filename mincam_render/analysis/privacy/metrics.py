"""How well an attack succeeds: image quality of reconstructions, re-identification accuracy.

PSNR and SSIM come from scikit-image (``skimage.metrics``) on display images in
[0, 1]; re-identification is scored as top-1 accuracy against the chance of
the trivial attacker that always names the most often present person.
"""

from __future__ import annotations

import numpy as np

#: Display gamma of the views the attacker reconstructs (sRGB-like).
DISPLAY_GAMMA = 2.2
#: Percentile of the training views' radiance mapped to white.
WHITE_PERCENTILE = 99.0


def white_level(views: np.ndarray) -> float:
    """Radiance (W/(m^2 sr)) shown as white: the :data:`WHITE_PERCENTILE` of ``views``."""
    level = float(np.percentile(np.asarray(views, np.float32), WHITE_PERCENTILE))
    if not level > 0:
        raise ValueError("views are all dark: no white level")
    return level


def display(views: np.ndarray, white: float) -> np.ndarray:
    """Display images in [0, 1]: ``(view / white)`` clipped, to the power 1 / gamma (float32)."""
    x = np.clip(np.asarray(views, np.float32) / np.float32(white), 0.0, 1.0)
    return x ** np.float32(1.0 / DISPLAY_GAMMA)


def reconstruction_quality(true: np.ndarray, pred: np.ndarray) -> dict[str, float]:
    """Mean PSNR (dB) and SSIM over frames of display images ``[frame, row, col]`` in [0, 1].

    Per frame with ``skimage.metrics`` (data range 1; SSIM's default 7 x 7
    window); identical frames give an infinite PSNR and SSIM 1.

    Raises:
        ValueError: shapes differ or are not ``[frame, row, col]``.
    """
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    t, p = np.asarray(true, np.float64), np.asarray(pred, np.float64)
    if t.shape != p.shape or t.ndim != 3 or len(t) == 0:
        raise ValueError(f"true {t.shape} and pred {p.shape}: need equal [frame, row, col]")
    with np.errstate(divide="ignore"):
        psnr = [peak_signal_noise_ratio(a, b, data_range=1.0) for a, b in zip(t, p, strict=True)]
    ssim = [structural_similarity(a, b, data_range=1.0) for a, b in zip(t, p, strict=True)]
    return {"psnr_db": float(np.mean(psnr)), "ssim": float(np.mean(ssim))}


def reid_top1(scores: np.ndarray, present: np.ndarray) -> float:
    """Top-1 re-identification accuracy: the highest-scored person is in the room.

    Args:
        scores: ``[frame, identity]`` the attacker's scores (any monotone scale).
        present: ``[frame, identity]`` 0/1 who is inside.

    Returns:
        The fraction of occupied frames (someone inside) whose top-scored
        identity is present; NaN without occupied frames.
    """
    s, p = np.asarray(scores), np.asarray(present) > 0.5
    if s.shape != p.shape or s.ndim != 2:
        raise ValueError(f"scores {s.shape} and present {p.shape}: need equal [frame, identity]")
    occupied = p.any(axis=1)
    if not occupied.any():
        return float("nan")
    top = s[occupied].argmax(axis=1)
    return float(p[occupied][np.arange(len(top)), top].mean())


def prior_scores(train_present: np.ndarray, frames: int) -> np.ndarray:
    """The trivial attacker's scores ``[frames, identity]``: how often each person is present."""
    freq = np.asarray(train_present, np.float64).mean(axis=0)
    return np.broadcast_to(freq, (frames, len(freq))).copy()
