"""Privacy audit: image metrics against closed forms, re-identification, attackers, verdicts."""

from __future__ import annotations

import json

import numpy as np
import pytest
from support import linear_task

from mincam_render.learn import train as tr
from mincam_render.studies.privacy import attacks, decoders
from mincam_render.studies.privacy.config import (
    ROSTER_OVERRIDES,
    AttackConfig,
    default_comparison,
)
from mincam_render.studies.privacy.curve import corner_verdicts
from mincam_render.studies.privacy.metrics import (
    display,
    foreground_mask,
    foreground_quality,
    prior_scores,
    reconstruction_quality,
    reid_top1,
    white_level,
)
from mincam_render.studies.privacy.study import (
    IMAGE_FIGURES,
    Episode,
    prior_attack,
    score_reconstruction,
    trivial_attack,
)


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


def _people(rng, frames: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(true, background, block mask)``: a 6 x 5 person of +0.3 on a noisy background,
    a one-pixel speck of +0.3 and a change of 0.01 (below the threshold) everywhere."""
    background = rng.uniform(0.2, 0.6, (frames, 16, 16))
    block = np.zeros(background.shape, bool)
    block[:, 4:10, 3:8] = True
    true = background + 0.01 + 0.3 * block
    true[:, 13, 13] += 0.3  # an isolated Monte Carlo speck
    return true, background, block


def test_foreground_is_what_changes_by_more_than_the_threshold_without_specks(rng):
    true, background, block = _people(rng)
    np.testing.assert_array_equal(foreground_mask(true, background), block)
    with_specks = foreground_mask(true, background, speck_px=0)
    assert with_specks.sum() == block.sum() + len(block) and with_specks[:, 13, 13].all()
    # a lower threshold takes the faint change too: every pixel
    assert foreground_mask(true, background, threshold=0.005, speck_px=0).all()


@pytest.mark.parametrize("delta", [0.1, 0.02])
def test_foreground_psnr_is_the_closed_form_on_the_mask_only(rng, delta):
    true, background, block = _people(rng)
    pred = true + delta * block + rng.uniform(-0.2, 0.2, true.shape) * ~block
    q = foreground_quality(true, pred, block)
    # MSE on the mask = delta^2 (data range 1): errors off the mask do not count
    assert q["fg_psnr_db"] == pytest.approx(-20 * np.log10(delta), rel=1e-9)
    assert q["fg_frames"] == 3 and q["fg_fraction"] == pytest.approx(30 / 256)
    exact = foreground_quality(true, true.copy(), block)
    assert exact["fg_psnr_db"] == np.inf and exact["fg_ssim"] == pytest.approx(1.0)
    # the whole view's PSNR does count them
    assert reconstruction_quality(true, pred)["psnr_db"] < q["fg_psnr_db"]


def test_frames_without_a_foreground_are_skipped(rng):
    true, background, block = _people(rng)
    block[1] = False
    q = foreground_quality(true, true + 0.1 * block, block)
    assert q["fg_frames"] == 2 and q["fg_psnr_db"] == pytest.approx(20.0)
    empty = foreground_quality(true, true, np.zeros_like(block))
    assert np.isnan(empty["fg_psnr_db"]) and np.isnan(empty["fg_ssim"]) and empty["fg_frames"] == 0


def test_foreground_bad_input(rng):
    true, background, block = _people(rng)
    with pytest.raises(ValueError, match="threshold"):
        foreground_mask(true, background, threshold=1.5)
    with pytest.raises(ValueError, match="speck_px"):
        foreground_mask(true, background, speck_px=-1)
    with pytest.raises(ValueError, match="equal"):
        foreground_mask(true, background[:, :8])
    with pytest.raises(ValueError, match="mask"):
        foreground_quality(true, true, block[:2])


def _episode(name: str, rng, frames: int = 20) -> Episode:
    """Synthetic display views: a background and one person-sized block of varying brightness."""
    background = rng.uniform(0.2, 0.6, (1, 8, 8)).repeat(frames, axis=0).astype(np.float32)
    views = background.copy()
    views[:, 2:6, 3:5] += rng.uniform(-0.2, 0.3, (frames, 1, 1)).astype(np.float32)
    present = (rng.random((frames, 3)) < 0.5).astype(np.float32)
    return Episode(name, name, views, background, present, foreground_mask(views, background))


def test_a_decoder_that_sees_no_one_scores_exactly_the_trivial_attacker(rng):
    import torch

    episodes = {n: _episode(n, rng) for n in ("train-0", "val-0", "test-0", "test-1")}
    trivial = trivial_attack(episodes)
    x = rng.standard_normal((20, 4)).astype(np.float32)
    model = decoders.ConvDecoder(x, 8, hidden=8, channels=8)
    with torch.no_grad():  # a decoder whose last layer outputs no difference
        for p in model.upsample[-1].parameters():
            p.zero_()
    nobody = attacks.Fitted(model, [], 0)
    for name in ("test-0", "test-1"):
        ep = episodes[name]
        recon = decoders.reconstruct(nobody, x, ep.background)
        np.testing.assert_array_equal(recon, ep.background)
        scored = score_reconstruction(ep, recon)
        assert scored == {k: trivial[name][k] for k in IMAGE_FIGURES}
        assert 0 < trivial[name]["fg_fraction"] < 1 and np.isfinite(scored["fg_psnr_db"])


def test_the_prior_knows_where_people_usually_are_not_where_they_are_now(rng):
    background = rng.uniform(0.2, 0.6, (10, 8, 8))
    usual = np.zeros((8, 8))
    usual[2:6, 3:5] = 0.2  # in every training frame, one person at the same place

    def episode(name: str, diff: np.ndarray) -> Episode:
        views = background + diff
        return Episode(name, name, views, background, np.ones((10, 1)),
                       foreground_mask(views, background))  # fmt: skip

    moved = np.roll(usual, 3, axis=1)  # the person elsewhere
    episodes = {"train-0": episode("train-0", usual), "test-0": episode("test-0", usual),
                "test-1": episode("test-1", moved)}  # fmt: skip
    prior, trivial = prior_attack(episodes), trivial_attack(episodes)
    assert prior["test-0"]["fg_psnr_db"] > 100  # the usual place: right (float32 rounding)
    assert trivial["test-0"]["fg_psnr_db"] == pytest.approx(-20 * np.log10(0.2))
    # elsewhere, the prior paints a person where none is: no better on the people's pixels,
    # worse on the whole view
    assert prior["test-1"]["fg_psnr_db"] <= trivial["test-1"]["fg_psnr_db"] + 1e-9
    assert prior["test-1"]["psnr_db"] < trivial["test-1"]["psnr_db"]


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


@pytest.mark.parametrize(("kind", "width"), [("mlp", 8), ("conv", 16), ("ridge", 8)])
def test_decoders_recover_a_difference_that_the_readout_determines(rng, kind, width):
    # the people's difference is a fixed mix of 3 patterns weighted by the read-out
    patterns = rng.uniform(-0.5, 0.5, (3, width, width))
    x = rng.uniform(0, 1, (600, 3)).astype(np.float32)
    diff = (np.einsum("nk,krc->nrc", x, patterns) / 3).astype(np.float32)
    background = np.full((100, width, width), 0.5, np.float32)
    fit = decoders.train_decoder(kind, (x[:400], diff[:400]), (x[400:500], diff[400:500]), FAST, 0)
    recon = decoders.reconstruct(fit, x[500:], background)
    assert recon.shape == (100, width, width) and recon.dtype == np.float32
    views = background + diff[500:]
    learned = reconstruction_quality(views, recon)
    nobody = reconstruction_quality(views, background)  # the trivial attacker
    assert learned["psnr_db"] > nobody["psnr_db"] + 6, (learned, nobody)


def test_decoder_kinds_are_an_enum_whose_values_are_the_json_keys():
    assert decoders.DECODERS == tuple(decoders.DecoderKind)
    assert [str(k) for k in decoders.DECODERS] == ["mlp", "conv", "ridge"]  # privacy.json's order
    kinds = decoders.DecoderKind
    assert json.dumps({kinds.RIDGE: kinds.CONV}) == '{"ridge": "conv"}'


def test_decoder_bad_input(rng):
    x, d = rng.uniform(0, 1, (20, 2)), rng.uniform(0, 1, (20, 4, 4))
    with pytest.raises(ValueError, match="decoder 'unet': allowed mlp, conv, ridge"):
        decoders.train_decoder("unet", (x, d), (x, d), FAST, 0)
    with pytest.raises(ValueError, match="rows == cols"):
        decoders.train_decoder("conv", (x, d[:, :, :3]), (x, d[:, :, :3]), FAST, 0)


@pytest.mark.parametrize(("width", "grid"), [(64, (8, 3)), (48, (12, 2)), (16, (8, 1)),
                                             (8, (8, 0)), (15, (15, 0))])  # fmt: skip
def test_the_conv_decoders_coarse_grid_doubles_up_to_the_view(width, grid):
    side, doublings = decoders.coarse_grid(width)
    assert (side, doublings) == grid and side * 2**doublings == width


@pytest.mark.parametrize("width", [64, 12])
def test_conv_decoder_maps_readouts_to_images_with_exact_gradients(rng, width):
    import torch

    x = rng.standard_normal((30, 5)).astype(np.float32)
    torch.manual_seed(0)  # a tiny net: some initial weights leave every ReLU dead
    model = decoders.ConvDecoder(x, width, hidden=8, channels=8)
    out = model(torch.from_numpy(x[:4]))
    assert out.shape == (4, width, width)
    out.square().mean().backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in model.parameters())
    # float64 against central differences (random projections of the 2 x 16 x 16 outputs)
    small = decoders.ConvDecoder(x, 16, hidden=4, channels=4).double()
    xin = torch.from_numpy(x[:2].astype(np.float64)).requires_grad_()
    assert torch.autograd.gradcheck(small, (xin,), eps=1e-6, atol=1e-6, fast_mode=True)


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


#: Test episodes of the synthetic audits: hard, middling, easy for every attacker.
_EPISODE_OFFSETS = (-1.0, 0.0, 1.0)


def _per_seed(psnr: float, reid: float) -> list[dict]:
    """3 attacker seeds x 3 test episodes around the means; episodes move every design alike."""
    return [
        {f"test-{e}": {"fg_psnr_db": psnr + 2.0 * o + 0.01 * s, "reid_top1": reid + 0.1 * o}
         for e, o in enumerate(_EPISODE_OFFSETS)}
        for s in range(3)
    ]  # fmt: skip


def _design(task: float, task_half: float, psnr: float, reid: float, view: float) -> dict:
    # the whole view's PSNR (psnr_db) is the other way round: the corner ignores it
    return {"task_error": _iv(task, task_half), "fg_psnr_db": _iv(psnr, 0.5),
            "psnr_db": _iv(view, 0.5), "reid_top1": _iv(reid, 0.05),
            "per_seed": _per_seed(psnr, reid)}  # fmt: skip


def _result(mincam_psnr: float, mincam_reid: float) -> dict:
    return {
        "designs": {
            "mincam-2px": _design(1.0, 0.1, mincam_psnr, mincam_reid, 40.0),
            "baseline-2x2": _design(1.5, 0.1, 15.0, 0.6, 10.0),
            "baseline-8x8": _design(1.0, 0.1, 18.0, 0.8, 10.0),
            "baseline-32x32": _design(0.5, 0.1, 22.0, 0.9, 10.0),
        },
        "episodes": {f"test-{e}": {"samples": 200} for e in range(3)},
        "config": {"comparison": {"seed": 0, "designs": [  # kinds come from here, not names
            {"pixels": 2, "grid": None}, *({"pixels": None, "grid": [g, g]} for g in (2, 8, 32))]}},
    }  # fmt: skip


def test_corner_needs_a_task_match_and_separated_attack_intervals():
    corner = corner_verdicts(_result(13.0, 0.4))["mincam-2px"]
    # 32x32 is better at the task: no match; 2x2 and 8x8 are no better
    assert corner["task_matched"] == ["baseline-2x2", "baseline-8x8"]
    assert corner["in_corner_against"] == ["baseline-2x2", "baseline-8x8"]
    # less re-identifiable than both, but its PSNR is not below either: not in the corner
    close = corner_verdicts(_result(17.8, 0.4))["mincam-2px"]
    assert close["more_private_than"] == {
        "fg_psnr_db": [], "reid_top1": ["baseline-2x2", "baseline-8x8"]}  # fmt: skip
    assert close["in_corner_against"] == []
    none = corner_verdicts(_result(20.0, 0.85))["mincam-2px"]
    assert none["in_corner_against"] == [] and "not in the corner" in none["verdict"]
    assert none["paired_more_private_than"] == []
    json.dumps(none)  # JSON-ready


def test_corner_reports_the_paired_reading_beside_the_interval_verdict():
    # 0.4 dB and 0.05 below 8x8 on every episode: the intervals (episode spread) overlap,
    # the paired differences (the episodes drop out) do not
    corner = corner_verdicts(_result(17.6, 0.75))["mincam-2px"]
    assert corner["in_corner_against"] == []
    assert corner["paired_more_private_than"] == ["baseline-8x8"]
    paired = corner["paired"]["baseline-8x8"]
    assert paired["fg_psnr_db"]["mean"] == pytest.approx(17.6 - 18.0)
    assert paired["reid_top1"]["mean"] == pytest.approx(0.75 - 0.8)
    assert paired["fg_psnr_db"]["ci95"][1] < 0 and paired["reid_top1"]["ci95"][1] < 0
    assert corner["verdict"].startswith("mincam-2px: not in the corner")
    assert corner["verdict"].endswith("lower on both attacks than: baseline-8x8")
    # more re-identifiable than 2x2 on the same episodes: not paired-private against it
    assert corner["paired"]["baseline-2x2"]["reid_top1"]["ci95"][0] > 0


def test_ridge_decoder_recovers_a_linear_view_and_picks_its_penalty(rng):
    patterns = rng.uniform(0, 1, (4, 8, 8))
    x = rng.uniform(0, 1, (300, 4))
    views = np.einsum("nk,krc->nrc", x, patterns) / 4
    ridge = decoders.fit_ridge((x[:200], views[:200]), (x[200:250], views[200:250]))
    assert ridge.penalty == min(decoders.RIDGE_PENALTIES)  # noiseless: the least penalty
    q = reconstruction_quality(views[250:], np.clip(ridge.predict(x[250:]), 0, 1))
    assert q["psnr_db"] > 40 and q["ssim"] > 0.99


def test_every_attacker_seed_scores_every_decoder_and_the_gains_are_paired(variant, tmp_path, rng):
    from mincam_render.studies.privacy.config import PrivacyConfig
    from mincam_render.studies.privacy.study import FIGURES, attack_design

    names = ("train-0", "val-0", "test-0", "test-1")
    data = {n: linear_task(40, seed=i) for i, n in enumerate(names)}
    cfg = tr.TrainConfig(max_steps=20, eval_every=10)
    tr.train_run(data["train-0"], data["val-0"], None, tmp_path, config=cfg, pixels=2)
    episodes = {n: _episode(n, rng, frames=40) for n in names}
    attack = AttackConfig(seeds=3, max_steps=20, eval_every=10, hidden=8, conv_channels=8,
                          view_width=8)  # fmt: skip
    trivial, prior = trivial_attack(episodes), prior_attack(episodes)
    result, examples = attack_design(
        [str(tmp_path)], data, episodes, PrivacyConfig(attack=attack), "mincam-2px",
        {"trivial": trivial, "prior": prior},
    )  # fmt: skip
    for f in FIGURES:
        assert result[f]["ci95"][0] <= result[f]["mean"] <= result[f]["ci95"][1]
    assert len(result["per_seed"]) == 3 and set(result["per_seed"][0]) == {"test-0", "test-1"}
    assert set(result["by_decoder"]) == set(decoders.DECODERS)
    for kept in result["decoders"]:  # each seed keeps its best decoder on validation
        errors = kept["decoder_val_mse"]
        assert kept["decoder"] == min(errors, key=errors.__getitem__)
    # paired on the same test episodes (equal frames): the point is the difference of means
    nobody = np.mean([trivial[e]["fg_psnr_db"] for e in ("test-0", "test-1")])
    gain = result["fg_psnr_gain_db"]
    assert gain["mean"] == pytest.approx(result["fg_psnr_db"]["mean"] - nobody, rel=1e-9)
    usual = np.mean([prior[e]["fg_psnr_db"] for e in ("test-0", "test-1")])
    over = result["fg_psnr_over_prior_db"]["mean"]
    assert over == pytest.approx(result["fg_psnr_db"]["mean"] - usual, rel=1e-9)
    assert examples["test-0"].shape == (40, 8, 8)
    json.dumps(result)  # JSON-ready


def test_examples_round_trip_with_backgrounds_and_masks(rng, tmp_path):
    from mincam_render.studies.privacy.study import _write_examples

    ep = _episode("test-0", rng)
    recon = {"mincam-2px": ep.views + 0.1, "baseline-2x2": ep.background}
    _write_examples(tmp_path / "examples.npz", ep, recon, 3)
    with np.load(tmp_path / "examples.npz") as saved:
        frames = saved["frames"]
        assert len(frames) == 3 and ep.present[frames].any(axis=1).all()  # occupied frames
        np.testing.assert_array_equal(saved["true"], ep.views[frames])
        np.testing.assert_array_equal(saved["background"], ep.background[frames])
        np.testing.assert_array_equal(saved["mask"], ep.mask[frames])
        assert saved["designs"].tolist() == ["mincam-2px", "baseline-2x2"]
        np.testing.assert_array_equal(saved["recon"][1], ep.background[frames])


def test_audit_designs_follow_the_render_size():
    default = default_comparison()
    # the kept audit's episodes and designs: unchanged by the size options
    assert default.overrides == ROSTER_OVERRIDES and default.mask_res is None
    assert [d.name for d in default.designs] == [
        "mincam-1px", "mincam-2px", "mincam-4px", "mincam-8px", "mincam-8px-private1",
        "baseline-2x2", "baseline-4x4", "baseline-8x8", "baseline-16x16", "baseline-32x32",
    ]  # fmt: skip
    large = default_comparison(16, 64)
    names = [d.name for d in large.designs]
    assert {"mincam-16px", "baseline-64x64", "mincam-8px-private1"} <= set(names)
    assert large.mask_res == 64 and large.overrides["camera"] == {"detectors": 16}
    assert large.overrides["people"] == ROSTER_OVERRIDES["people"]


@pytest.mark.parametrize(
    ("size", "message"),
    [
        ({"detectors": 12}, "detectors = 12: allowed 8, 16"),
        ({"texels": 48}, "texels = 48: allowed 32, 64"),
    ],
)
def test_audit_sizes_other_than_the_two_rendered_are_refused(size, message):
    with pytest.raises(ValueError, match=message):
        default_comparison(**size)
