"""The adversarial privacy term: its sign, its gradients, and training runs that carry it."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
import torch
from support import linear_task

from mincam_render.learn import train as tr
from mincam_render.learn.privacy_term import PrivacyAdversary, privacy_objective
from mincam_render.learn.runs import attach_adversary

CFG = tr.TrainConfig(max_steps=60, batch_size=32, eval_every=20, patience=100)


def _camera_and_batch(pixels: int = 2):
    data = linear_task(64, k=2, res=8)
    model = tr.build_mincam(data, pixels, sensor_model=False)
    attach_adversary(model, seed=3)
    frames = torch.from_numpy(data.transport[:64])
    return model, frames


def test_the_privacy_term_makes_the_masks_fool_a_fixed_adversary():
    # sign test: a gradient step of the masks on the privacy term alone raises the
    # (frozen) adversary's reconstruction loss
    model, frames = _camera_and_batch()
    adv = model.adversary
    adv.eval()  # fixed normalisation statistics, so only the masks change the loss

    def adversary_loss() -> float:
        with torch.no_grad():
            v = model.measure(frames, noise=False)[:, -1]
            return float(adv.loss(v, adv.target(frames), frozen=True))

    before = adversary_loss()
    v = model.measure(frames, noise=False)[:, -1]
    privacy_objective(adv, v, frames, weight=1.0).backward()
    with torch.no_grad():
        model.logits -= 0.5 * model.logits.grad / model.logits.grad.abs().max()
    after = adversary_loss()
    assert after > before, (before, after)


def test_the_adversary_learns_its_own_loss_and_the_camera_its_negative():
    model, frames = _camera_and_batch()
    adv = model.adversary
    v = model.measure(frames, noise=False)[:, -1]
    target = adv.target(frames)
    weight = 0.7
    params = list(adv.parameters())
    grads = torch.autograd.grad(
        privacy_objective(adv, v, frames, weight), [*params, model.logits], retain_graph=True
    )
    own = torch.autograd.grad(adv.loss(v.detach(), target, frozen=False), params)
    for g, o in zip(grads[:-1], own, strict=True):
        torch.testing.assert_close(g, o)
    fooled = torch.autograd.grad(adv.loss(v, target, frozen=True), model.logits)[0]
    torch.testing.assert_close(grads[-1], -weight * fooled)


def test_adversary_target_is_the_first_detector_with_mean_one():
    adv = PrivacyAdversary(2, grid=2)
    frames = torch.zeros(1, 2, 4, 4)
    frames[0, 0, :2, :2] = 3.0  # one bright quarter: [4, 0, 0, 0] after normalising
    frames[0, 1] = 100.0  # other detectors are ignored
    torch.testing.assert_close(adv.target(frames), torch.tensor([[4.0, 0.0, 0.0, 0.0]]))
    torch.testing.assert_close(adv.target(torch.zeros(1, 1, 4, 4)), torch.zeros(1, 4))


def test_a_privacy_run_trains_records_its_weight_and_loads(variant, tmp_path):
    train, val, test = linear_task(200).split((0.7, 0.15, 0.15))
    cfg = replace(CFG, privacy_weight=2.0)
    metrics = tr.train_run(train, val, test, tmp_path, pixels=2, config=cfg)
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["config"]["privacy_weight"] == 2.0
    assert metrics.test.error < float(test.labels["count"].std()) * 1.5
    trained = tr.open_run(tmp_path)
    assert any(k.startswith("adversary.") for k in trained.state)
    model = tr.restore_model(trained, test)  # the measured camera has no adversary
    assert not hasattr(model, "adversary")
    # a run without the term keeps run.json's recipe as before (no privacy_weight key)
    plain = tmp_path / "plain"
    tr.train_run(train, val, None, plain, pixels=2, config=CFG)
    assert "privacy_weight" not in json.loads((plain / "run.json").read_text())["config"]


def test_privacy_weight_bad_input(tmp_path):
    with pytest.raises(ValueError, match="privacy_weight"):
        tr.TrainConfig(privacy_weight=-1.0)
    with pytest.raises(ValueError, match="privacy_weight"):
        tr.TrainConfig(privacy_weight=float("nan"))
    train, val, _ = linear_task(100).split((0.7, 0.15, 0.15))
    with pytest.raises(ValueError, match="baseline camera has none"):
        tr.train_run(train, val, None, tmp_path, baseline_grid=(2, 2),
                     config=replace(CFG, privacy_weight=1.0))  # fmt: skip
