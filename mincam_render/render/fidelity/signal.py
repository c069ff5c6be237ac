"""The label signal of a family's frames, and how render noise repeats over frames (numpy, W).

Render error matters against what the camera must read: the *label signal*,
the part of each measurement that the state the labels are computed from
changes (:class:`~mincam_render.render.precision.LabelSignal`). A family says
where that state lives (:class:`SignalSource`); :func:`render_label_signal`
renders it on frames spread over an episode, two estimates with independent
seeds so that its spread over frames is measured without their noise.

:func:`noise_autocorrelation` measures how render noise repeats from frame to
frame: noise that a head sees again in the next frame (or for a whole
background window) is a pattern it can learn, unlike noise that is new in
every frame.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np

from mincam_render.render.differential import background_family
from mincam_render.render.precision import LabelSignal

if TYPE_CHECKING:
    import mitsuba as mi

    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.render.differential import BackgroundFamily, EstimatorFamily
    from mincam_render.render.precision import ErrorScale

    # A structural type (``render`` sits below ``scenes`` in the layers); here,
    # beside the SignalSource it names, so that probes imports signal, not back.
    class ProbedFamily(EstimatorFamily, Protocol):
        """What the planner needs of a scene family (``SceneFamily`` has it)."""

        num_frames: int

        @property
        def planning_error_scale(self) -> ErrorScale:
            """What the planning target is relative to (a class variable of the family)."""

        @property
        def signal_target_error(self) -> float | None:
            """The target relative to the label signal, chosen by the task-level check."""

        @property
        def total_error_scale(self) -> ErrorScale:
            """What errors relative to the total are relative to: frame or mean."""

        @property
        def label_signal(self) -> SignalSource:
            """Where the family's labels live in its frames."""

        @property
        def name(self) -> str:
            """The family's name."""

        def build_scene(self) -> mi.Scene:
            """The family's Mitsuba scene."""

        def set_frame(self, scene: mi.Scene, index: int) -> dict[str, np.ndarray]:
            """Set ``scene`` to frame ``index``; return its labels."""


class SignalSource(enum.StrEnum):
    """Where a family's labels live in its frames: what the label signal is."""

    #: What movers and doors change: ``X - C`` of differential rendering (the
    #: frame against its static background, same samples), e.g. people counting.
    MOVERS = "movers"
    #: What each switched light of the static background changes (its converged
    #: component times its on/off state); the weakest light sets the signal.
    LIGHTS = "lights"
    #: The frames themselves: their static background is their mean over frames
    #: (families without a separated background: patches).
    FRAMES = "frames"
    #: What changes from one frame to the next, ``S[f + 1] - S[f]``: a temporal
    #: task that reads its label from motion (traffic's speed, from the head's
    #: frame history), where the frames' light cancels and render noise that is
    #: new in every frame does not. For families without a separated background
    #: whose frames each have their own seed: a frame's error counts sqrt(2)
    #: times on a step (``LabelSignal.noise_gain``).
    FRAME_STEPS = "frame-steps"


#: A render of the family's scene as it is set: ``seed -> T[detector, row, col]`` (W).
FrameRender = Callable[[int], np.ndarray]


def render_label_signal(
    family: ProbedFamily,
    scene: mi.Scene,
    camera: FreeformCamera,
    frames: Sequence[int],
    *,
    source: SignalSource,
    spp: int,
    seeds: Callable[[int, int], int],
    interval_s: float,
    max_depth: int | None = None,
) -> LabelSignal:
    """The label signal of ``frames``: two estimates per part with independent seeds.

    FRAME_STEPS renders each frame with the next (the last with the one
    before), both with one seed per estimate so that what the step leaves
    unchanged cancels with its noise.

    Args:
        family: the scene family (a ``SceneFamily``; MOVERS and LIGHTS need its
            static background).
        scene: its built Mitsuba scene (left at the last state rendered).
        camera: the camera (every detector is rendered).
        frames: frame indices, at least 2, spread over the episode.
        source: where the labels live (:class:`SignalSource`).
        spp: samples per texel of each estimate.
        seeds: ``(frame, estimate) -> render seed`` (estimate 0 or 1).
        interval_s: background window (s) of MOVERS and LIGHTS.
        max_depth: path depth (None: the scene's integrator).

    Raises:
        ValueError: fewer than 2 frames (FRAME_STEPS: fewer than 2 distinct
            frame pairs, e.g. a 2-frame episode); a source the family cannot give.
    """
    if len(frames) < 2:
        raise ValueError(f"frames = {list(frames)}: the signal's spread needs at least 2")

    def render(seed: int) -> np.ndarray:
        return family.render_transport(scene, camera, spp=spp, seed=seed, max_depth=max_depth)

    if source is SignalSource.FRAME_STEPS:
        return _steps_signal(family, scene, render, frames, seeds)
    # MOVERS and LIGHTS need the static background: checked where every renderer checks it
    background = None if source is SignalSource.FRAMES else background_family(family)
    if source is SignalSource.LIGHTS and background is not None:
        return _lights_signal(background, scene, render, frames, seeds, interval_s)
    estimates = []
    for e in (0, 1):
        per_frame = []
        for i in frames:
            if background is not None:  # MOVERS
                x, c = difference_pair(background, scene, render, i, seeds(i, e), interval_s)
                per_frame.append(x - c)
            else:
                family.set_frame(scene, i)
                per_frame.append(render(seeds(i, e)))
        estimates.append(np.stack(per_frame))
    return LabelSignal(parts=(np.stack(estimates),))


def _steps_signal(
    family: ProbedFamily,
    scene: mi.Scene,
    render: FrameRender,
    frames: Sequence[int],
    seeds: Callable[[int, int], int],
) -> LabelSignal:
    """The steps ``T[f + 1] - T[f]`` at ``frames``, each pair under one seed per estimate."""
    firsts = sorted({min(int(i), family.num_frames - 2) for i in frames})
    if len(firsts) < 2 or firsts[0] < 0:
        raise ValueError(
            f"frames {list(frames)} of a {family.num_frames}-frame episode: the steps' "
            "spread needs at least 2 distinct frame pairs"
        )
    estimates = []
    for e in (0, 1):
        steps = []
        for first in firsts:
            pair = []
            for index in (first, first + 1):
                family.set_frame(scene, index)
                pair.append(render(seeds(first, e)))
            steps.append(pair[1] - pair[0])
        estimates.append(np.stack(steps))
    return LabelSignal(parts=(np.stack(estimates),), noise_gain=float(np.sqrt(2.0)))


def difference_pair(
    family: BackgroundFamily,
    scene: mi.Scene,
    render: FrameRender,
    index: int,
    seed: int,
    interval_s: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``(X, C)`` of frame ``index`` with one seed (common random numbers, W).

    ``X`` is the frame lit by its window's slow light, ``C`` its static
    background at the window's start: paths that miss every mover cancel in
    ``X - C``, which is what the movers change.
    """
    family.set_frame_in_window(scene, index, interval_s)
    x = render(seed)
    family.set_background(scene, index, interval_s)
    return x, render(seed)


def _lights_signal(
    family: BackgroundFamily,
    scene: mi.Scene,
    render: FrameRender,
    frames: Sequence[int],
    seeds: Callable[[int, int], int],
    interval_s: float,
) -> LabelSignal:
    """One part per switched component: its render times its weight in each frame.

    A component is switched when its weight changes over ``frames`` (a light
    turned on or off); components of constant weight are background.
    """
    weights = [family.background_components(i, interval_s) for i in frames]
    keys = sorted({k for w in weights for k in w})
    parts = []
    for key in keys:
        w = np.array([frame.get(key, 0.0) for frame in weights])
        if np.all(w == w[0]):
            continue
        family.set_background_component(scene, key)
        estimates = [render(seeds(frames[0], e)) for e in (0, 1)]
        parts.append(np.stack([w[:, None, None, None] * r[None] for r in estimates]))
    if not parts:
        raise ValueError(
            f"no light switches within frames {list(frames)}: the lights' signal is unmeasured"
        )
    return LabelSignal(parts=tuple(parts))


def noise_autocorrelation(noise: np.ndarray, lags: Sequence[int]) -> dict[int, float]:
    r"""Autocorrelation over frames of render noise, pooled over measurements.

    .. math::

        \rho(L) = \frac{\sum_{f,m} n_{f,m}\, n_{f+L,m}}{\sum_{f,m} n_{f,m}^2}
            \cdot \frac{F}{F - L},
        \qquad n_{f,m} = e_{f,m} - \bar e_{m}

    with ``e[frame, measurement]`` the error of each measurement against a
    reference and its mean over frames removed (a constant offset is not noise
    that moves). Independent noise gives 0 at every lag; noise shared by every
    frame of a window of ``W`` frames gives ``(W - L) / W``.

    Args:
        noise: ``e[frame, ...]`` (any trailing axes are measurements), >= 2 frames.
        lags: lags in frames, each in [1, frames - 1].

    Returns:
        ``{lag: rho}``.

    Raises:
        ValueError: fewer than 2 frames, a lag out of range, or noise of zero power.
    """
    e = np.asarray(noise, dtype=np.float64)
    frames = e.shape[0] if e.ndim else 0
    if frames < 2:
        raise ValueError(f"noise has {frames} frame(s): need at least 2")
    n = e.reshape(frames, -1)
    n = n - n.mean(axis=0)
    power = float(np.mean(n * n))
    if power <= 0.0:
        raise ValueError("noise is constant over frames: its autocorrelation is undefined")
    out = {}
    for lag in lags:
        if not 1 <= int(lag) < frames:
            raise ValueError(f"lag = {lag!r}: allowed an integer in [1, {frames - 1}]")
        out[int(lag)] = float(np.mean(n[:-lag] * n[lag:]) / power)
    return out
