"""Errors of a count split by the true count: bias, RMSE, shares and their intervals."""

from __future__ import annotations

import numpy as np
import pytest

from mincam_render.analysis.errors_by_count import errors_by_count


def _episodes(n_episodes: int = 8, frames: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """True counts cycling 0-4 in every episode and the episode of each frame."""
    true = np.tile(np.arange(frames) % 5, n_episodes).astype(float)
    return true, np.repeat(np.arange(n_episodes), frames)


def test_a_shrinking_predictor_has_the_bias_of_its_shrinkage() -> None:
    true, episode = _episodes()
    mean = 2.0
    # regression toward the mean by a half, plus noise of +-0.3 that alternates over
    # a count's frames in an episode (its mean there is exactly 0), per seed
    sign = np.where((np.arange(true.size) // 5) % 2 == 0, 1.0, -1.0)
    pred = np.stack([mean + 0.5 * (true - mean) + k * 0.3 * sign for k in (1, -1, 1)])
    bins = errors_by_count(pred, true, episode)
    assert [b.count for b in bins] == [0, 1, 2, 3, 4]
    for b in bins:
        expected = -0.5 * (b.count - mean)
        # every resample of seeds and episodes sees the same bias
        assert (b.bias.low, b.bias.mean, b.bias.high) == pytest.approx((expected,) * 3)
        assert b.rmse == pytest.approx(np.hypot(expected, 0.3))
        assert b.share == pytest.approx(0.2)
        assert b.frames == 8 * 40


def test_an_exact_predictor_has_no_bias_and_a_point_interval() -> None:
    true, episode = _episodes(n_episodes=4, frames=50)
    bins = errors_by_count(np.stack([true, true]), true, episode)
    assert all(b.bias.mean == b.bias.low == b.bias.high == 0.0 and b.rmse == 0.0 for b in bins)
    assert sum(b.share for b in bins) == pytest.approx(1.0)


def test_a_count_one_episode_gets_wrong_is_uncertain_and_rare_counts_are_left_out() -> None:
    # count 3 appears in two episodes: right in one, 2 too high in the other
    true = np.array([0, 0, 3, 3, 0, 0, 3, 3, 5], float)
    episode = np.array([0, 0, 0, 0, 1, 1, 1, 1, 1])
    pred = np.array([[0, 0, 3, 3, 0, 0, 5, 5, 5]], float)
    bins = errors_by_count(pred, true, episode, min_frames=2)
    assert [b.count for b in bins] == [0, 3]
    three = bins[1]
    assert three.bias.mean == pytest.approx(1.0)
    assert three.bias.low == pytest.approx(0.0) and three.bias.high == pytest.approx(2.0)
    assert three.as_json()["bias"] == {"mean": 1.0, "ci95": [three.bias.low, three.bias.high]}


@pytest.mark.parametrize(
    ("pred", "true", "episode", "message"),
    [
        (np.zeros(3), np.zeros(3), np.zeros(3), "expected"),
        (np.zeros((1, 3)), np.zeros(4), np.zeros(4), "expected"),
        (np.zeros((1, 3)), np.zeros(3), np.zeros(2), "one index per frame"),
        (np.full((1, 2), np.nan), np.zeros(2), np.zeros(2), "finite"),
        (np.zeros((1, 2)), np.array([0.5, 1.0]), np.zeros(2), "whole numbers"),
        (np.zeros((1, 2)), np.array([-1.0, 1.0]), np.zeros(2), "whole numbers"),
    ],
)
def test_bad_input_is_named(pred, true, episode, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        errors_by_count(pred, true, episode)


def test_min_frames_below_one_is_refused() -> None:
    with pytest.raises(ValueError, match="min_frames"):
        errors_by_count(np.zeros((1, 2)), np.zeros(2), np.zeros(2), min_frames=0)
