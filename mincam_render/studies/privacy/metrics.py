"""How well an attack succeeds: image quality of reconstructions, re-identification accuracy.

PSNR and SSIM come from scikit-image (``skimage.metrics``) on display images in
[0, 1], over the whole view and over its *foreground*: the pixels where the
view differs from the frame's background (the same frame with its people
removed, :mod:`mincam_render.data.views`) by more than
:data:`FOREGROUND_THRESHOLD`, specks of at most :data:`FOREGROUND_SPECK_PX`
pixels dropped. The whole view is dominated by the room, which an attacker
knows anyway; the foreground is what the people add. Re-identification is
scored as top-1 accuracy against the chance of the trivial attacker that
always names the most often present person.
"""

from __future__ import annotations

import numpy as np

from mincam_render.core.checks import check_int, check_number

#: Display gamma of the views the attacker reconstructs (sRGB-like).
DISPLAY_GAMMA = 2.2
#: Percentile of the training views' radiance mapped to white.
WHITE_PERCENTILE = 99.0
#: Change of a display pixel (of [0, 1]; 0.05 ~ 13 of 255 grey levels) that makes
#: it foreground. The view and its background share the sampler seed, so pixels
#: the people do not touch are equal; light paths that only graze a person (a
#: bounce off them onto the wall) leave 4-spp Monte Carlo specks whose median
#: change is ~0.03, while the people and their shadows mostly change by > 0.1.
FOREGROUND_THRESHOLD = 0.05
#: Connected (8-neighbour) foreground specks of at most this many pixels are
#: dropped: isolated Monte Carlo specks, not a person (one spans tens of pixels
#: at 64 x 64).
FOREGROUND_SPECK_PX = 3


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

    The whole-view figures of :func:`foreground_quality` (``skimage.metrics``,
    data range 1, SSIM's default 7 x 7 window); identical frames give an
    infinite PSNR and SSIM 1.

    Raises:
        ValueError: shapes differ or are not ``[frame, row, col]``.
    """
    t, p = _frames(true, pred, "pred")
    quality = foreground_quality(t, p, np.zeros(t.shape, bool))
    return {"psnr_db": quality["psnr_db"], "ssim": quality["ssim"]}


def foreground_mask(
    true: np.ndarray,
    background: np.ndarray,
    *,
    threshold: float = FOREGROUND_THRESHOLD,
    speck_px: int = FOREGROUND_SPECK_PX,
) -> np.ndarray:
    """``mask[frame, row, col]`` (bool): where the view differs from its background.

    Args:
        true: display views ``[frame, row, col]`` in [0, 1].
        background: the same frames without their people (display, same shape).
        threshold: a pixel is foreground when ``|true - background| > threshold``.
        speck_px: connected (8-neighbour) components of at most this many pixels
            are dropped (``skimage.morphology.remove_small_objects``); 0 keeps all.

    Raises:
        ValueError: shapes differ or are not ``[frame, row, col]``; threshold
            not in [0, 1); speck_px negative.
    """
    from skimage.morphology import remove_small_objects

    t, b = _frames(true, background, "background")
    check_number("threshold", threshold, 0, 1, hi_open=True, unit="(display units)", numpy=True)
    check_int("speck_px", speck_px, 0, unit="px")
    mask = np.abs(t - b) > threshold
    if speck_px:
        mask = np.stack([remove_small_objects(m, max_size=speck_px, connectivity=2) for m in mask])
    return mask


def foreground_quality(true: np.ndarray, pred: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """PSNR (dB) and SSIM of ``pred`` on the foreground ``mask`` and on the whole view.

    Per frame, from one ``skimage.metrics.structural_similarity`` call (its
    default 7 x 7 window; data range 1): the whole view's SSIM (skimage's mean)
    and the mean of its SSIM map over the frame's foreground; PSNR
    (``peak_signal_noise_ratio``) of the whole frame and of its foreground
    pixels. Averaged over frames; frames without a foreground are skipped for
    the foreground figures (NaN when no frame has one). ``fg_fraction``: the
    mean share of foreground pixels per frame; ``fg_frames``: frames with one.

    Returns:
        ``{"fg_psnr_db", "fg_ssim", "psnr_db", "ssim", "fg_fraction", "fg_frames"}``.

    Raises:
        ValueError: shapes differ or are not ``[frame, row, col]``.
    """
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    t, p = _frames(true, pred, "pred")
    m = np.asarray(mask, bool)
    if m.shape != t.shape:
        raise ValueError(f"mask {m.shape}: need the views' shape {t.shape}")
    fg_psnr, fg_ssim, psnr, ssim = [], [], [], []
    with np.errstate(divide="ignore"):
        for a, b, where in zip(t, p, m, strict=True):
            mean_ssim, ssim_map = structural_similarity(a, b, data_range=1.0, full=True)
            psnr.append(peak_signal_noise_ratio(a, b, data_range=1.0))
            ssim.append(mean_ssim)
            if where.any():
                fg_psnr.append(peak_signal_noise_ratio(a[where], b[where], data_range=1.0))
                fg_ssim.append(ssim_map[where].mean())
    nan = float("nan")
    return {
        "fg_psnr_db": float(np.mean(fg_psnr)) if fg_psnr else nan,
        "fg_ssim": float(np.mean(fg_ssim)) if fg_ssim else nan,
        "psnr_db": float(np.mean(psnr)),
        "ssim": float(np.mean(ssim)),
        "fg_fraction": float(m.mean()),
        "fg_frames": len(fg_psnr),
    }


def _frames(true: np.ndarray, other: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Both as float64 ``[frame, row, col]`` of one shape, or ValueError."""
    t, o = np.asarray(true, np.float64), np.asarray(other, np.float64)
    if t.shape != o.shape or t.ndim != 3 or len(t) == 0:
        raise ValueError(f"true {t.shape} and {name} {o.shape}: need equal [frame, row, col]")
    return t, o


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
