"""Comparison statistics: pooled errors, bootstrap intervals, verdicts, convergence, seeds."""

import numpy as np
import pytest

from mincam_render.analysis.statistics import (
    EpisodeErrors,
    Interval,
    Pooling,
    bootstrap_interval,
    converged,
    paired_difference,
    paired_statement,
    verdict,
)
from mincam_render.core.seeds import stream_seed


def test_pooled_rmse_is_the_root_of_the_frame_weighted_mean_square():
    # seed 0: episodes of RMSE 1 (10 frames) and 3 (30 frames); seed 1: 2 and 2
    e = EpisodeErrors(
        error=np.array([[1.0, 3.0], [2.0, 2.0]]), frames=np.array([10, 30]), pooling="rms"
    )
    seed0 = np.sqrt((10 * 1 + 30 * 9) / 40)
    assert e.point() == pytest.approx((seed0 + 2.0) / 2)
    assert e.pooled(np.array([0]), np.array([1, 1])) == pytest.approx(3.0)


def test_pooled_error_rate_is_the_frame_weighted_mean():
    e = EpisodeErrors(error=np.array([[0.1, 0.4]]), frames=np.array([30, 10]), pooling="mean")
    assert e.point() == pytest.approx((30 * 0.1 + 10 * 0.4) / 40)


def test_interval_brackets_the_point_and_narrows_with_more_episodes():
    rng = np.random.default_rng(0)
    few = EpisodeErrors(
        error=1 + 0.2 * rng.standard_normal((3, 4)), frames=np.full(4, 100), pooling="rms"
    )
    many = EpisodeErrors(
        error=1 + 0.2 * rng.standard_normal((3, 64)), frames=np.full(64, 100), pooling="rms"
    )
    a, b = bootstrap_interval(few), bootstrap_interval(many)
    for iv in (a, b):
        assert iv.low <= iv.mean <= iv.high
    assert (b.high - b.low) < (a.high - a.low)
    # the episode spread of 0.2 / sqrt(64 * 3) ~ 0.014: a 95 % interval is a few of those
    assert 0.02 < b.high - b.low < 0.15


def test_identical_errors_give_a_zero_width_interval_and_one_seed_is_not_resampled():
    same = EpisodeErrors(error=np.full((3, 3), 0.7), frames=np.full(3, 50), pooling="rms")
    iv = bootstrap_interval(same)
    assert (iv.low, iv.mean, iv.high) == pytest.approx((0.7, 0.7, 0.7))
    lone = EpisodeErrors(error=np.array([[0.5, 1.5, 1.0]]), frames=np.full(3, 10), pooling="mean")
    iv = bootstrap_interval(lone)
    assert iv.mean == pytest.approx(1.0)
    assert 0.5 <= iv.low < iv.mean < iv.high <= 1.5
    single = bootstrap_interval(EpisodeErrors(np.array([[2.0]]), np.array([5]), "rms"))
    assert single == Interval(2.0, 2.0, 2.0)


def test_verdict_only_where_intervals_separate():
    assert verdict("a", Interval(1, 0.9, 1.1), "b", Interval(2, 1.8, 2.2)).startswith("a beats b")
    assert verdict("a", Interval(2, 1.8, 2.2), "b", Interval(1, 0.9, 1.1)).startswith("b beats a")
    assert verdict("a", Interval(1, 0.9, 1.5), "b", Interval(1.4, 1.2, 1.6)).startswith(
        "no verdict"
    )


def test_paired_difference_removes_the_episode_difficulty_the_separate_intervals_keep():
    # episodes of very different difficulty shared by both cameras; b is 0.1 worse everywhere
    difficulty = np.array([0.5, 1.5, 3.0, 1.0])
    seed_noise = np.array([[0.0], [0.01], [-0.01]])
    a = EpisodeErrors(difficulty + seed_noise, np.full(4, 100), "mean")
    b = EpisodeErrors(difficulty + 0.1 + seed_noise[::-1], np.full(4, 100), "mean")
    assert verdict("a", bootstrap_interval(a), "b", bootstrap_interval(b)).startswith("no verdict")
    diff = paired_difference(a, b)
    assert diff.mean == pytest.approx(-0.1)  # means of the error rates: closed form
    assert -0.1 - 0.02 <= diff.low <= diff.mean <= diff.high <= -0.1 + 0.02
    assert "a lower on the same episodes" in paired_statement("a", "b", diff)
    flipped = paired_difference(b, a)
    assert flipped.mean == pytest.approx(0.1)
    assert "a lower on the same episodes" in paired_statement("b", "a", flipped)


def test_paired_difference_of_a_noisy_tie_contains_zero_and_needs_the_same_episodes():
    rng = np.random.default_rng(1)
    a = EpisodeErrors(1 + 0.2 * rng.standard_normal((3, 5)), np.full(5, 60), "rms")
    b = EpisodeErrors(1 + 0.2 * rng.standard_normal((3, 5)), np.full(5, 60), "rms")
    diff = paired_difference(a, b)
    assert diff.low < 0 < diff.high
    assert "contains 0" in paired_statement("a", "b", diff)
    other = EpisodeErrors(np.ones((3, 4)), np.full(4, 60), "rms")
    with pytest.raises(ValueError, match="same test episodes"):
        paired_difference(a, other)


def test_episode_errors_round_trip_through_json():
    import json

    e = EpisodeErrors(np.array([[1.0, 2.5], [0.5, 3.0]]), np.array([10, 40]), "rms")
    back = EpisodeErrors.from_dict(json.loads(json.dumps(e.as_dict())))
    assert np.array_equal(back.error, e.error) and np.array_equal(back.frames, e.frames)
    assert back.pooling is Pooling.RMS and back.point() == pytest.approx(e.point())
    assert json.dumps(e.as_dict()) == json.dumps(back.as_dict())  # the value, as before
    assert e.as_dict()["pooling"] == "rms" and type(e.as_dict()["pooling"]) is str


@pytest.mark.parametrize(
    ("losses", "expected"),
    [([1.0, 0.5, 0.495, 0.494], True), ([1.0, 0.5, 0.4, 0.3], False), ([1.0], False)],
)
def test_converged_compares_the_best_loss_at_half_and_all_steps(losses, expected):
    hist = [{"step": 100 * (i + 1), "val_loss": v} for i, v in enumerate(losses)]
    c = converged(hist)
    assert c["converged"] is expected
    if len(losses) > 1:
        assert c["improvement"] == pytest.approx((0.5 - min(losses)) / 0.5)
    else:  # nothing to compare: null with its reason (strict JSON has no NaN)
        assert c["improvement"] is None and "no evaluation" in c["improvement_null_reason"]


def test_bad_episode_errors_are_refused():
    with pytest.raises(ValueError, match="expected"):
        EpisodeErrors(error=np.ones(3), frames=np.ones(3), pooling="rms")
    with pytest.raises(ValueError, match="finite"):
        EpisodeErrors(error=np.array([[np.nan]]), frames=np.ones(1), pooling="rms")
    with pytest.raises(ValueError, match="pooling = 'median': allowed 'rms', 'mean'"):
        EpisodeErrors(error=np.ones((1, 1)), frames=np.ones(1), pooling="median")
    with pytest.raises(ValueError, match="allowed 'rms', 'mean'"):
        EpisodeErrors.from_dict({"error": [[1.0]], "frames": [1], "pooling": "RMS"})


def test_stream_seeds_are_stable_distinct_and_refuse_negatives():
    seeds = {
        stream_seed(r, p, i)
        for r in (0, 1)
        for p in ("episode/train", "episode/test")
        for i in range(3)
    }
    assert len(seeds) == 12 and all(0 <= s < 2**63 for s in seeds)
    assert stream_seed(0, "episode/test", 1) == stream_seed(0, "episode/test", 1)
    # pinned: datasets and runs are reproduced from these seeds
    assert stream_seed(0, "episode/test", 0) == 5309830758224222565
    with pytest.raises(ValueError, match=">= 0"):
        stream_seed(-1, "x")
