"""Render noise of rendered episodes against the label signal, and how it repeats (numpy, W).

The same episode (same scene seed) rendered at two fidelities differs only by
render error: ``e = P_level - P_reference`` for every measurement ``P`` (random
printable masks, box pixels). Its power holds the reference's own noise too;
Monte Carlo noise power falls as 1/samples, so the level's share of it is
``(1/f) / (1/f + 1/f_ref)`` for sample factors ``f`` and ``f_ref``.

The label signal of a differential episode is what the movers change in each
frame, ``T - B`` (the frame less its converged background: ``X - C``); of a plain
episode, the frame itself (its static part is its mean over frames). Two
renders of the episode (the reference and a second level) give two estimates
whose covariance over frames is the signal's power without their noise
(:class:`~mincam_render.render.precision.LabelSignal`).

A temporal task reads its label from what changes between frames (traffic's
speed from the frames of the head's history), where the whole frame's light
cancels and noise that is new in every frame does not. So every figure is also
taken on *frame steps*, ``x[f + 1] - x[f]`` of the error and of each signal
estimate: noise independent from frame to frame has sqrt(2) times its frame RMS
there, a pattern held for a background window nearly none, and a signal that
changes slowly little. The level's share of the steps' error power is taken as
the frames' (both levels' noises repeat alike: the same seeding).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_render.render.fidelity.signal import noise_autocorrelation
from mincam_render.render.precision import LabelSignal, box_measurements, measurements_of

#: Box pixels (texels per side) measured beside the random masks: the single
#: texel (the 32x32 baseline's pixel at 32 texels) and 4x4 texels (8x8's).
BOX_TEXELS = (1, 4)


@dataclass(frozen=True)
class NoiseFigures:
    """A level's render error against the reference, beside the label signal.

    Every figure is keyed by measurement kind: ``random_masks``, ``box_1``
    (single texels), ``box_4``.

    Args:
        episodes: the episodes measured.
        reference: the level the errors are taken against.
        error_rms_w: RMS of ``P_level - P_reference`` (W), the reference's share out.
        noise_rms_w: the same about each measurement's mean over frames (W): the
            part that moves from frame to frame (a constant offset, like a
            missing bounce or a converged background's noise, is left out).
        signal_rms_w: the label signal's RMS over frames (W).
        step_error_rms_w: RMS of the error's frame steps ``e[f + 1] - e[f]`` (W),
            the reference's share out.
        step_signal_rms_w: the label signal's frame steps' RMS (W).
        autocorrelation: ``{kind: {"lag_1_frame", "lag_1_window"}}`` of the error;
            ``lag_1_window`` is None where no episode is longer than a window
            (the lighting room's 1,800-frame test episodes hold one 60 s window
            at 30 fps).
        window_frames: frames of one background window (the second lag).
    """

    episodes: tuple[str, ...]
    reference: str
    error_rms_w: Mapping[str, float]
    noise_rms_w: Mapping[str, float]
    signal_rms_w: Mapping[str, float]
    step_error_rms_w: Mapping[str, float]
    step_signal_rms_w: Mapping[str, float]
    autocorrelation: Mapping[str, Mapping[str, float | None]]
    window_frames: int

    def ratio(self, figure: str = "error_rms_w", signal: str = "signal_rms_w") -> dict[str, float]:
        """``figure`` over ``signal``, per measurement kind (dimensionless).

        On frame steps: ``ratio("step_error_rms_w", "step_signal_rms_w")``.
        """
        values, over = getattr(self, figure), getattr(self, signal)
        return {k: values[k] / over[k] for k in values}


def measurement_kinds(
    shape: tuple[int, ...], transmittance_range: tuple[float, float]
) -> dict[str, Callable[[np.ndarray], np.ndarray]]:
    """``{kind: T[frame, detector, row, col] -> P[frame, ...]}``: random masks and boxes."""
    kinds = {"random_masks": measurements_of(shape, transmittance_range)}
    for b in BOX_TEXELS:
        kinds[f"box_{b}"] = _boxes(b)
    return kinds


def _boxes(b: int) -> Callable[[np.ndarray], np.ndarray]:
    return lambda t: box_measurements(t, b)


def episode_transport(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``(T, S)`` of an episode: its frames and their label signal (W, ``[frame, k, r, c]``).

    ``S = T - B`` for a differential episode (``B`` each frame's converged
    background), else ``S = T``.
    """
    from mincam_render.data.dataset import open_dataset
    from mincam_render.data.render_job.backgrounds import load_backgrounds
    from mincam_render.render.differential import background_family
    from mincam_render.scenes.registry import load_family

    ds = open_dataset(path)
    t = ds.transport((0, ds.num_frames))
    job = ds.manifest["job"]
    settings = job["render"].get("background")
    if settings is None:
        return t, t
    family = background_family(
        load_family(
            job["family"]["source"],
            seed=job["seed"],
            num_frames=job["num_frames"],
            overrides=job["family"]["overrides"],
        )
    )
    interval = float(settings["interval_s"])
    keys = [family.background_key(i, interval) for i in range(ds.num_frames)]
    backgrounds = load_backgrounds(Path(path), ds.manifest, keys)
    s = np.empty_like(t)
    for i, key in enumerate(keys):
        converged = backgrounds[key].converged(family.background_components(i, interval))
        s[i] = t[i] - converged
    return t, s


def noise_figures(
    level: tuple[Sequence[Path], float],
    reference: tuple[Sequence[Path], float, str],
    second: Sequence[Path] | None,
    *,
    window_frames: int,
    load: Callable[[Path], tuple[np.ndarray, np.ndarray]] = episode_transport,
    transmittance_range: tuple[float, float] | None = None,
) -> NoiseFigures:
    """A level's error against the reference, per measurement kind, pooled over episodes.

    Args:
        level: ``(episode directories, sample factor)`` of the level measured.
        reference: ``(episode directories, sample factor, name)`` of the reference
            (the same episodes, in the same order).
        second: the same episodes at another level, the label signal's second
            estimate (None: the reference's alone, its noise included).
        window_frames: frames of one background window.
        load: an episode's ``(T, S)`` (:func:`episode_transport`).
        transmittance_range: the masks' printable range (None: the level's camera's).
    """
    paths, factor = level
    ref_paths, ref_factor, ref_name = reference
    share = (1.0 / factor) / (1.0 / factor + 1.0 / ref_factor)
    sums: dict[str, dict[str, list[float]]] = {}
    lo_hi = transmittance_range or _range(paths[0])
    for i, path in enumerate(paths):
        t, _ = load(path)
        t_ref, s_ref = load(ref_paths[i])
        estimates = np.stack([s_ref] if second is None else [s_ref, load(second[i])[1]])
        signal = LabelSignal(parts=(estimates,))
        steps = LabelSignal(parts=(np.diff(estimates, axis=1),))
        for kind, measure in measurement_kinds(t.shape[1:], lo_hi).items():
            error = measure(t) - measure(t_ref)
            _add(sums, kind, error, (signal.rms(measure), steps.rms(measure)), window_frames)
    pooled = {kind: _pooled(v, share) for kind, v in sums.items()}
    return NoiseFigures(
        episodes=tuple(Path(p).name for p in paths),
        reference=ref_name,
        error_rms_w={k: v.error for k, v in pooled.items()},
        noise_rms_w={k: v.noise for k, v in pooled.items()},
        signal_rms_w={k: v.signal for k, v in pooled.items()},
        step_error_rms_w={k: v.step_error for k, v in pooled.items()},
        step_signal_rms_w={k: v.step_signal for k, v in pooled.items()},
        autocorrelation={
            k: {"lag_1_frame": v.lag_1, "lag_1_window": v.lag_window} for k, v in pooled.items()
        },
        window_frames=window_frames,
    )


def _range(path: Path) -> tuple[float, float]:
    from mincam_render.data.dataset import open_dataset

    lo, hi = open_dataset(path).camera.transmittance_range
    return float(lo), float(hi)


def _add(
    sums: dict[str, dict[str, list[float]]],
    kind: str,
    error: np.ndarray,
    signal_rms: tuple[float, float],
    window_frames: int,
) -> None:
    """One episode's powers and autocorrelations, weighted by its frames.

    ``signal_rms`` is the label signal's RMS over frames and over frame steps (W).
    """
    frames = error.shape[0]
    flat = error.reshape(frames, -1)
    # a lag of one window needs an episode longer than a window; else not measured
    acf = noise_autocorrelation(flat, [1] + ([window_frames] if window_frames < frames else []))
    keys = ("w", "e2", "n2", "s2", "d2", "ds2", "r1", "rw")
    entry = sums.setdefault(kind, {k: [] for k in keys})
    entry["w"].append(frames)
    entry["e2"].append(float(np.mean(flat**2)))
    entry["n2"].append(float(np.mean((flat - flat.mean(axis=0)) ** 2)))
    entry["s2"].append(signal_rms[0] ** 2)
    entry["d2"].append(float(np.mean(np.diff(flat, axis=0) ** 2)))
    entry["ds2"].append(signal_rms[1] ** 2)
    entry["r1"].append(acf[1])
    entry["rw"].append(acf.get(window_frames, math.nan))


@dataclass(frozen=True)
class _Pooled:
    """One measurement kind's figures pooled over episodes (:func:`_pooled`; W, and lags)."""

    error: float
    noise: float
    signal: float
    step_error: float
    step_signal: float
    lag_1: float
    lag_window: float | None


def _pooled(entry: Mapping[str, list[float]], share: float) -> _Pooled:
    """Frame-weighted means over episodes; the powers' level share (square roots)."""
    w = np.asarray(entry["w"], dtype=np.float64)

    def mean(key: str) -> float:
        return float(np.sum(w * np.asarray(entry[key])) / np.sum(w))

    rw = np.asarray(entry["rw"], dtype=np.float64)
    measured = ~np.isnan(rw)  # the episodes longer than a window

    return _Pooled(
        error=float(np.sqrt(share * mean("e2"))),
        noise=float(np.sqrt(share * mean("n2"))),
        signal=float(np.sqrt(mean("s2"))),
        step_error=float(np.sqrt(share * mean("d2"))),
        step_signal=float(np.sqrt(mean("ds2"))),
        lag_1=mean("r1"),
        lag_window=float(np.sum(w[measured] * rw[measured]) / np.sum(w[measured]))
        if measured.any()
        else None,
    )
