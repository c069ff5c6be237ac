"""Privacy audit: image metrics against closed forms, re-identification, attackers, verdicts."""

from __future__ import annotations

import json

import numpy as np
import pytest
from support import linear_task

from mincam_render.analysis.privacy import attacks
from mincam_render.analysis.privacy.config import AttackConfig
from mincam_render.analysis.privacy.curve import corner_verdicts
from mincam_render.analysis.privacy.metrics import (
    display,
    prior_scores,
    reconstruction_quality,
    reid_top1,
    white_level,
)
from mincam_render.learn import train as tr


def test_identical_images_have_infinite_psnr_and_ssim_one(rng):
    img = rng.uniform(0, 1, (3, 16, 16))
    q = reconstruction_quality(img, img.copy())
    assert q["psnr_db"] == np.inf and q["ssim"] == pytest.approx(1.0)


@pytest.mark.parametrize("offset", [0.1, 0.01])
def test_constant_offset_gives_the_closed_form_psnr(rng, offset):
    img = rng.uniform(0.2, 0.7, (2, 16, 16))
    q = reconstruction_quality(img, img + offset)
    # MSE = offset^2 on a data range of 1: PSNR = -20 log10(offset)
    assert q["psnr_db"] == pytest.approx(-20 * np.log10(offset), rel=1e-9)
    assert q["ssim"] < 1.0


def test_reconstruction_quality_bad_input():
    with pytest.raises(ValueError, match="equal"):
        reconstruction_quality(np.zeros((2, 4, 4)), np.zeros((2, 4, 5)))


def test_display_maps_the_white_level_to_one_with_gamma():
    views = np.array([[[0.0, 1.0], [4.0, 8.0]]], np.float32)
    out = display(views, 4.0)
    np.testing.assert_allclose(out, [[[0.0, 0.25 ** (1 / 2.2)], [1.0, 1.0]]], rtol=1e-6)
    assert white_level(np.arange(101, dtype=np.float32)) == pytest.approx(99.0)
    with pytest.raises(ValueError, match="dark"):
        white_level(np.zeros(5))


def test_trivial_reidentification_accuracy_is_the_class_prior(rng):
    # person 1 is in the room in 60 % of frames, person 0 in 30 %, person 2 in 20 %
    n = 1000
    present = np.stack(
        [rng.random(n) < 0.3, rng.random(n) < 0.6, rng.random(n) < 0.2], axis=1
    ).astype(np.float32)
    scores = prior_scores(present, n)
    occupied = present.any(axis=1)
    assert reid_top1(scores, present) == pytest.approx(present[occupied, 1].mean())
    # an oracle that scores who is present is always right
    assert reid_top1(present + 0.01 * rng.random(present.shape), present) == 1.0
    assert np.isnan(reid_top1(np.zeros((3, 2)), np.zeros((3, 2))))
    with pytest.raises(ValueError, match="equal"):
        reid_top1(np.zeros((3, 2)), np.zeros((3, 3)))


FAST = AttackConfig(max_steps=300, eval_every=50, hidden=64, batch_size=64)


def test_decoder_recovers_a_view_that_the_readout_determines(rng):
    # views are a fixed mix of 3 patterns weighted by the read-out: a decodable scene
    patterns = rng.uniform(0, 1, (3, 8, 8))
    x = rng.uniform(0, 1, (600, 3)).astype(np.float32)
    views = (np.einsum("nk,krc->nrc", x, patterns) / 3).astype(np.float32)
    fit = attacks.train_decoder((x[:400], views[:400]), (x[400:500], views[400:500]), FAST, 0)
    recon = attacks.decode(fit, x[500:], (8, 8))
    learned = reconstruction_quality(views[500:], recon)
    mean = reconstruction_quality(views[500:], np.broadcast_to(views[:400].mean(0), recon.shape))
    assert learned["psnr_db"] > mean["psnr_db"] + 6, (learned, mean)
    assert fit.history and fit.best_step > 0


def test_reidentifier_beats_the_prior_when_the_readout_carries_identity(rng):
    present = (rng.random((600, 3)) < 0.4).astype(np.float32)
    x = present + 0.1 * rng.standard_normal(present.shape).astype(np.float32)
    fit = attacks.train_reid((x[:400], present[:400]), (x[400:500], present[400:500]), FAST, 1)
    acc = reid_top1(fit.predict(x[500:]), present[500:])
    prior = reid_top1(prior_scores(present[:400], 100), present[500:])
    assert acc > prior + 0.2, (acc, prior)


@pytest.mark.parametrize("baseline", [False, True])
def test_the_attacker_reads_the_trained_design(variant, tmp_path, baseline):
    train, val, _ = linear_task(120).split((0.7, 0.15, 0.15))
    cfg = tr.TrainConfig(max_steps=20, eval_every=10)
    kind = {"baseline_grid": (2, 2)} if baseline else {"pixels": 2}
    tr.train_run(train, val, None, tmp_path, config=cfg, **kind)
    camera = attacks.design_camera(tmp_path, train)
    x = attacks.measurements(camera, train, seed=5)
    assert x.shape == (len(train), 4 if baseline else 2)
    np.testing.assert_array_equal(x, attacks.measurements(camera, train, seed=5))
    assert not np.array_equal(x, attacks.measurements(camera, train, seed=6))  # sensor noise


def test_attack_config_bad_input():
    with pytest.raises(ValueError, match="seeds"):
        AttackConfig(seeds=0)
    with pytest.raises(ValueError, match="lr"):
        AttackConfig(lr=2.0)


def _iv(mean: float, half: float) -> dict:
    return {"mean": mean, "ci95": [mean - half, mean + half]}


def _result(mincam_psnr: float, mincam_reid: float) -> dict:
    return {
        "designs": {
            "mincam-2px": {"task_error": _iv(1.0, 0.1), "psnr_db": _iv(mincam_psnr, 0.5),
                           "reid_top1": _iv(mincam_reid, 0.05)},
            "baseline-2x2": {"task_error": _iv(1.5, 0.1), "psnr_db": _iv(15.0, 0.5),
                             "reid_top1": _iv(0.6, 0.05)},
            "baseline-8x8": {"task_error": _iv(1.0, 0.1), "psnr_db": _iv(18.0, 0.5),
                             "reid_top1": _iv(0.8, 0.05)},
            "baseline-32x32": {"task_error": _iv(0.5, 0.1), "psnr_db": _iv(22.0, 0.5),
                               "reid_top1": _iv(0.9, 0.05)},
        }
    }  # fmt: skip


def test_corner_needs_a_task_match_and_separated_attack_intervals():
    corner = corner_verdicts(_result(13.0, 0.4))["mincam-2px"]
    # 32x32 is better at the task: no match; 2x2 and 8x8 are no better
    assert corner["task_matched"] == ["baseline-2x2", "baseline-8x8"]
    assert corner["in_corner_against"] == ["baseline-2x2", "baseline-8x8"]
    # less re-identifiable than both, but its PSNR is not below either: not in the corner
    close = corner_verdicts(_result(17.8, 0.4))["mincam-2px"]
    assert close["more_private_than"] == {
        "psnr_db": [], "reid_top1": ["baseline-2x2", "baseline-8x8"]}  # fmt: skip
    assert close["in_corner_against"] == []
    none = corner_verdicts(_result(20.0, 0.85))["mincam-2px"]
    assert none["in_corner_against"] == [] and "not in the corner" in none["verdict"]
    json.dumps(none)  # JSON-ready


def test_ridge_decoder_recovers_a_linear_view_and_picks_its_penalty(rng):
    patterns = rng.uniform(0, 1, (4, 8, 8))
    x = rng.uniform(0, 1, (300, 4))
    views = np.einsum("nk,krc->nrc", x, patterns) / 4
    ridge = attacks.fit_ridge((x[:200], views[:200]), (x[200:250], views[200:250]))
    assert ridge.penalty == min(attacks.RIDGE_PENALTIES)  # noiseless: the least penalty
    q = reconstruction_quality(views[250:], ridge.decode(x[250:], (8, 8)))
    assert q["psnr_db"] > 40 and q["ssim"] > 0.99
