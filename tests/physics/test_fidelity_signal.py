"""Render error against the label signal, and the autocorrelation of render noise (numpy)."""

from __future__ import annotations

import numpy as np
import pytest

from mincam_render.render.fidelity.signal import (
    SignalSource,
    noise_autocorrelation,
    render_label_signal,
)
from mincam_render.render.precision import (
    ErrorScale,
    LabelSignal,
    UnmeasurableSignalError,
    box_measurements,
    measurement_relative_error,
)

LO_HI = (0.01, 0.67)


def _scene(rng, frames=40, shape=(2, 8, 8)):
    """A static background ``B``, a mover's image ``D`` and its amplitude ``a[frame]``."""
    background = rng.uniform(1.0, 2.0, size=shape)
    mover = rng.uniform(0.0, 0.05, size=shape)
    amplitude = rng.integers(0, 5, size=frames).astype(np.float64)
    reference = background[None] + amplitude[:, None, None, None] * mover[None]
    return background, mover, amplitude, reference


@pytest.mark.parametrize("box_texels", [None, 1, 4])
def test_error_along_the_signal_is_its_amplitude_over_the_signals_spread(rng, box_texels):
    # an error eps * D against a signal a_f * D: pooled over the measurements,
    # the masks cancel and the signal-relative RMS error is eps / std_f(a)
    # exactly (random masks and box pixels)
    _, mover, amplitude, reference = _scene(rng)
    eps = 0.3
    signal = LabelSignal(parts=(np.stack([amplitude[:, None, None, None] * mover[None]] * 2),))
    err = measurement_relative_error(
        reference + eps * mover[None],
        reference,
        LO_HI,
        scale=ErrorScale.SIGNAL,
        signal=signal,
        box_texels=box_texels,
    )
    expected = eps / amplitude.std()
    np.testing.assert_allclose(err["rms"], expected, rtol=1e-12)
    assert err["max"] > err["rms"]


def test_signal_relative_error_is_the_total_relative_one_times_total_over_signal(rng):
    # a constant error eps * B: relative to the total it is about eps; relative
    # to a signal a few per cent of the total it is tens of times larger
    background, mover, amplitude, reference = _scene(rng)
    signal = LabelSignal(parts=(np.stack([amplitude[:, None, None, None] * mover[None]] * 2),))
    test = reference + 0.01 * background[None]
    total = measurement_relative_error(test, reference, LO_HI)["rms"]
    relative = measurement_relative_error(test, reference, LO_HI, scale="signal", signal=signal)[
        "rms"
    ]
    assert 0.009 < total < 0.01
    assert relative > 10 * total


def test_two_independent_estimates_measure_the_signal_without_their_noise(rng):
    # the covariance of two noisy estimates is the signal's power; one
    # estimate's spread holds its noise too (here as large as the signal)
    _, mover, amplitude, _ = _scene(rng, frames=4000)
    clean = amplitude[:, None, None, None] * mover[None]

    def measure(t):
        return box_measurements(t, 8)

    truth = float(np.sqrt(np.mean((measure(clean) - measure(clean).mean(0)) ** 2)))
    noisy = [clean + rng.normal(0, 1.0, clean.shape) * truth / 8 for _ in range(2)]
    two = LabelSignal(parts=(np.stack(noisy),)).rms(measure)
    one = LabelSignal(parts=(np.stack(noisy[:1]),)).rms(measure)
    np.testing.assert_allclose(two, truth, rtol=0.03)
    np.testing.assert_allclose(one, truth * np.sqrt(2.0), rtol=0.03)


def test_the_weakest_part_sets_the_signal(rng):
    _, mover, amplitude, _ = _scene(rng)
    part = np.stack([amplitude[:, None, None, None] * mover[None]] * 2)
    signal = LabelSignal(parts=(part, 0.1 * part))

    def measure(t):
        return box_measurements(t, 8)

    np.testing.assert_allclose(
        signal.rms(measure), 0.1 * LabelSignal(parts=(part,)).rms(measure), rtol=1e-12
    )


def test_frame_steps_count_independent_noise_as_the_task_check_measures_it(rng):
    # frames a_f D plus noise new in every frame: the planner's figure (the
    # frame error over the steps' signal, counted sqrt(2) times) is what the
    # task check measures directly, the error's steps over the signal's steps
    _, mover, _, _ = _scene(rng)
    amplitude = np.cumsum(rng.normal(0.0, 1.0, 3000))  # a slow walk: small steps
    clean = amplitude[:, None, None, None] * mover[None]
    noisy = clean + rng.normal(0.0, 0.01, clean.shape)
    steps = np.diff(clean, axis=0)
    signal = LabelSignal(parts=(np.stack([steps] * 2),), noise_gain=np.sqrt(2.0))
    planned = measurement_relative_error(
        noisy, clean, LO_HI, scale=ErrorScale.SIGNAL, signal=signal, box_texels=4
    )["rms"]

    def measure(t):
        return box_measurements(t, 4)

    error_steps = np.diff(measure(noisy) - measure(clean), axis=0)
    signal_steps = np.diff(measure(clean), axis=0)
    direct = np.sqrt(np.mean(error_steps**2) / np.var(signal_steps, axis=0).mean())
    np.testing.assert_allclose(planned, direct, rtol=0.03)
    frames_only = LabelSignal(parts=(np.stack([steps] * 2),))
    np.testing.assert_allclose(
        measurement_relative_error(
            noisy, clean, LO_HI, scale=ErrorScale.SIGNAL, signal=frames_only, box_texels=4
        )["rms"],
        planned / np.sqrt(2.0),
        rtol=1e-12,
    )


class _Strip:
    """A numpy stand-in for a family: frame ``f`` renders ``B + a[f] D`` plus noise of its seed."""

    def __init__(self, rng, frames=12, shape=(2, 4, 4)):
        self.num_frames = frames
        self.background = rng.uniform(1.0, 2.0, size=shape)
        self.mover = rng.uniform(0.0, 0.05, size=shape)
        self.amplitude = rng.normal(0.0, 1.0, size=frames)
        self.noise = {}  # seed -> its noise image: one pattern per seed
        self.rng, self.shape, self.frame = rng, shape, 0

    def set_frame(self, scene, index):
        self.frame = index
        return {}

    def render_transport(self, scene, camera, *, spp, seed, max_depth):
        noise = self.noise.setdefault(seed, self.rng.normal(0.0, 0.1, size=self.shape))
        return self.background + self.amplitude[self.frame] * self.mover + noise


def _steps(family, frames):
    return render_label_signal(
        family,
        None,
        None,
        frames,
        source=SignalSource.FRAME_STEPS,
        spp=1,
        seeds=lambda i, e: 1000 * e + i,
        interval_s=1.0,
    )


def test_frame_step_signal_renders_each_pair_under_one_seed(rng):
    # the background and each seed's noise cancel in a step: what is left is
    # exactly the mover's change; the last frame pairs with the one before
    family = _Strip(rng)
    signal = _steps(family, [0, 5, 11])
    a, d = family.amplitude, family.mover
    expected = np.stack([(a[f + 1] - a[f]) * d for f in (0, 5, 10)])
    assert len(signal.parts) == 1 and signal.parts[0].shape == (2, 3, *family.shape)
    for estimate in signal.parts[0]:
        np.testing.assert_allclose(estimate, expected, atol=1e-12)
    assert signal.noise_gain == pytest.approx(np.sqrt(2.0))
    assert len(family.noise) == 6  # 3 pairs x 2 estimates, each its own seed


@pytest.mark.parametrize("frames", [[10, 11], [3, 3]])
def test_frame_steps_need_two_distinct_pairs(rng, frames):
    with pytest.raises(ValueError, match="2 distinct frame pairs"):
        _steps(_Strip(rng), frames)


@pytest.mark.parametrize("gain", [0.0, -1.0, float("nan"), float("inf")])
def test_label_signal_refuses_a_gain_that_is_not_positive(gain):
    with pytest.raises(ValueError, match="noise_gain"):
        LabelSignal(parts=(np.zeros((2, 2, 1, 4, 4)),), noise_gain=gain)


def test_box_measurements_are_block_sums(rng):
    t = rng.uniform(size=(3, 2, 8, 8))
    boxes = box_measurements(t, 4)
    assert boxes.shape == (3, 2, 2, 2)
    np.testing.assert_allclose(boxes[1, 0, 1, 0], t[1, 0, 4:, :4].sum(), rtol=1e-12)
    np.testing.assert_allclose(box_measurements(t, 1), t, rtol=0)


@pytest.mark.parametrize("box_texels", [0, 3])
def test_box_size_that_does_not_divide_the_texels_is_refused(rng, box_texels):
    with pytest.raises(ValueError, match="box_texels"):
        box_measurements(rng.uniform(size=(1, 1, 8, 8)), box_texels)


def test_signal_scale_without_a_signal_is_refused(rng):
    t = rng.uniform(size=(2, 1, 4, 4))
    with pytest.raises(ValueError, match="label signal"):
        measurement_relative_error(t, t, LO_HI, scale="signal")


@pytest.mark.parametrize(("shape", "match"), [((2, 1, 1, 4, 4), "frames"), ((3, 2, 1, 4), "shape")])
def test_label_signal_of_the_wrong_shape_is_refused(shape, match):
    with pytest.raises(ValueError, match=match):
        LabelSignal(parts=(np.zeros(shape),))


def test_autocorrelation_of_ar1_noise_is_rho_to_the_lag(rng):
    # n_f = rho n_{f-1} + sqrt(1 - rho^2) w_f, 400 independent series of 2,000
    # frames: the estimate's standard error is about 1 / sqrt(800,000) ~ 0.001
    rho, frames = 0.6, 2000
    w = rng.normal(size=(frames, 400))
    n = np.empty_like(w)
    n[0] = w[0]
    for f in range(1, frames):
        n[f] = rho * n[f - 1] + np.sqrt(1 - rho**2) * w[f]
    acf = noise_autocorrelation(n, [1, 2, 5])
    for lag, value in acf.items():
        np.testing.assert_allclose(value, rho**lag, atol=0.01)


def test_noise_shared_by_a_window_correlates_as_the_windows_overlap(rng):
    # one draw per window of W frames: rho(L) = (W - L) / W, 0 beyond a window
    window, windows = 20, 200
    n = np.repeat(rng.normal(size=(windows, 300)), window, axis=0)
    acf = noise_autocorrelation(n, [1, 10, window])
    np.testing.assert_allclose(acf[1], (window - 1) / window, atol=0.01)
    np.testing.assert_allclose(acf[10], 0.5, atol=0.01)
    np.testing.assert_allclose(acf[window], 0.0, atol=0.01)


@pytest.mark.parametrize(
    ("noise", "lags", "match"),
    [
        (np.ones((5, 3)), [1], "constant"),
        (np.arange(10.0), [10], "lag"),
        (np.arange(10.0), [0], "lag"),
        (np.zeros((1, 3)), [1], "frame"),
    ],
)
def test_autocorrelation_refuses_what_it_cannot_measure(noise, lags, match):
    with pytest.raises(ValueError, match=match):
        noise_autocorrelation(noise, lags)


def _anticorrelated_estimates(rng, frames=6):
    # the second estimate's deviations are the first's negated: no common signal
    first = rng.normal(size=(frames, 1, 4, 4))
    return np.stack([first, 2 * first.mean(axis=0) - first])


@pytest.mark.parametrize("part", ["zeros", "anticorrelated"])
def test_an_error_against_a_signal_that_is_not_measurable_is_refused(rng, part):
    estimates = np.zeros((2, 6, 1, 4, 4)) if part == "zeros" else _anticorrelated_estimates(rng)
    moving = np.stack([rng.normal(size=(6, 1, 4, 4))] * 2)
    signal = LabelSignal(parts=(moving, estimates))
    t = rng.uniform(size=(6, 1, 4, 4))
    with pytest.raises(UnmeasurableSignalError, match="not measurable"):
        measurement_relative_error(t, 1.01 * t, LO_HI, scale="signal", signal=signal)
