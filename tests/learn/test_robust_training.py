"""Robust training: a built camera per batch, reproducible and resumable."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from support import linear_task

from mincam_render.learn import train as tr
from mincam_render.learn.evaluation import mean_loss_under
from mincam_render.learn.models import InputNorm
from mincam_render.learn.step import batch_draw, validation_draws
from mincam_render.optics.perturbation import PerturbationModel

CFG = tr.TrainConfig(
    max_steps=20, batch_size=16, eval_every=5, patience=100, perturbation=PerturbationModel()
)


def test_every_batch_gets_its_own_draw_reproducibly():
    model = tr.build_mincam(linear_task(40, k=3), 3)
    g1, g2 = torch.Generator().manual_seed(4), torch.Generator().manual_seed(4)
    a = [batch_draw(model, PerturbationModel(), g1) for _ in range(3)]
    b = [batch_draw(model, PerturbationModel(), g2) for _ in range(3)]
    assert all(x is not None for x in a + b)
    assert [x.shift_m.tolist() for x in a] == [x.shift_m.tolist() for x in b]  # type: ignore[union-attr]
    assert not np.array_equal(a[0].shift_m, a[1].shift_m)  # type: ignore[union-attr]
    assert batch_draw(model, None, g1) is None


def test_robust_training_resumes_like_continuing(variant, tmp_path):
    train, val, _ = linear_task(120).split((0.7, 0.15, 0.15))
    full = tr.build_mincam(train, 2, seed=3)
    tr.train_model(full, train, val, CFG, out_dir=tmp_path / "full")
    first = tr.build_mincam(train, 2, seed=3)
    tr.train_model(first, train, val, CFG, out_dir=tmp_path / "killed", stop_after_steps=12)
    again = tr.build_mincam(train, 2, seed=3)
    tr.train_model(again, train, val, CFG, out_dir=tmp_path / "killed")
    torch.testing.assert_close(full.logits, again.logits, rtol=1e-5, atol=1e-7)


def test_robust_training_differs_from_nominal_and_is_recorded(variant, tmp_path):
    train, val, test = linear_task(120).split((0.7, 0.15, 0.15))
    nominal = tr.build_mincam(train, 2, seed=3)
    tr.train_model(nominal, train, val, tr.TrainConfig(**{**CFG.__dict__, "perturbation": None}))
    robust = tr.build_mincam(train, 2, seed=3)
    tr.train_model(robust, train, val, CFG)
    assert not torch.allclose(nominal.logits, robust.logits)
    metrics = tr.train_run(train, val, test, tmp_path / "run", config=CFG)
    run = tr.open_run(tmp_path / "run")
    assert run.record["config"]["perturbation"]["mask_shift_mm"] == pytest.approx(0.3)
    loaded = tr.restore_model(run, test)
    assert tr.evaluate(loaded, test).error == pytest.approx(metrics.test.error)


def test_train_config_refuses_a_perturbation_of_another_type():
    with pytest.raises(ValueError, match="TrainConfig.perturbation"):
        tr.TrainConfig(perturbation={"mask_shift_mm": 0.3})  # type: ignore[arg-type]


def test_a_baseline_camera_refuses_a_draw():
    data = linear_task(20)
    model = tr.build_baseline(data, (2, 2))
    draw = PerturbationModel().draw(1, np.random.default_rng(0))
    with pytest.raises(ValueError, match="baseline"):
        model.measure(torch.from_numpy(data.transport), draw=draw)


# ---- robust validation: a fixed set of built cameras decides early stopping ----------

VAL_CFG = dataclasses.replace(CFG, robust_validation_draws=4)


def test_validation_draws_are_fixed_by_the_seed_and_absent_when_validating_the_design():
    model = tr.build_mincam(linear_task(40, k=3), 3)
    a, b = validation_draws(model, VAL_CFG), validation_draws(model, VAL_CFG)
    assert len(a) == 4 and [d.shift_m.tolist() for d in a] == [d.shift_m.tolist() for d in b]
    assert not np.array_equal(a[0].shift_m, a[1].shift_m)
    other = validation_draws(model, dataclasses.replace(VAL_CFG, seed=1))
    assert not np.array_equal(a[0].shift_m, other[0].shift_m)
    assert validation_draws(model, dataclasses.replace(VAL_CFG, robust_validation_draws=0)) == []
    assert validation_draws(model, dataclasses.replace(VAL_CFG, perturbation=None)) == []


def test_robust_validation_resumes_with_the_same_draws(variant, tmp_path):
    train, val, _ = linear_task(120).split((0.7, 0.15, 0.15))
    full = tr.build_mincam(train, 2, seed=3)
    res = tr.train_model(full, train, val, VAL_CFG, out_dir=tmp_path / "full")
    first = tr.build_mincam(train, 2, seed=3)
    tr.train_model(first, train, val, VAL_CFG, out_dir=tmp_path / "killed", stop_after_steps=12)
    again = tr.build_mincam(train, 2, seed=3)
    resumed = tr.train_model(again, train, val, VAL_CFG, out_dir=tmp_path / "killed")
    # the evaluations after the resume (steps 15, 20) saw the same built cameras
    assert [h["val_loss"] for h in resumed.history] == [h["val_loss"] for h in res.history]
    assert all(h["val_loss"] != h["val_loss_nominal"] for h in res.history)


def test_zero_validation_draws_validate_the_design_exactly(variant):
    train, val, _ = linear_task(120).split((0.7, 0.15, 0.15))
    cfg = dataclasses.replace(VAL_CFG, robust_validation_draws=0, max_steps=10)
    model = tr.build_mincam(train, 2, seed=3)
    res = tr.train_model(model, train, val, cfg)
    _, _, nominal = tr.predict(model, val, limit=cfg.max_eval_samples)
    # the model holds its best state: bit for bit the loss of the camera as designed
    assert res.best_val_loss == nominal
    assert "val_loss_nominal" not in res.history[-1]
    # a nominal run ignores the draws: the same run whatever their number
    runs = []
    for n in (0, 8):
        m = tr.build_mincam(train, 2, seed=3)
        c = dataclasses.replace(cfg, perturbation=None, robust_validation_draws=n)
        runs.append((tr.train_model(m, train, val, c).history, m.logits.detach().clone()))
    assert [h["val_loss"] for h in runs[0][0]] == [h["val_loss"] for h in runs[1][0]]
    assert torch.equal(runs[0][1], runs[1][1])


def test_validation_under_draws_differs_from_the_design_unless_the_ranges_are_zero(variant):
    data = linear_task(60)
    model = tr.build_mincam(data, 2, seed=3)
    # a trained design (its head reads the pixels) with masks far from uniform
    tr.train_model(model, data, data, dataclasses.replace(CFG, perturbation=None, max_steps=40))
    with torch.no_grad():
        model.logits.add_(torch.from_numpy(np.random.default_rng(2).normal(0, 2, (2, 8, 8))))
    _, _, nominal = tr.predict(model, data)
    perturbed = mean_loss_under(model, data, validation_draws(model, VAL_CFG))
    assert abs(perturbed / nominal - 1) > 0.01
    zero = dataclasses.replace(VAL_CFG, perturbation=PerturbationModel.zero())
    assert mean_loss_under(model, data, validation_draws(model, zero)) == pytest.approx(
        nominal, rel=1e-12
    )
    with pytest.raises(ValueError, match="at least one draw"):
        mean_loss_under(model, data, [])


@pytest.mark.parametrize("bad", [-1, 1.5, True])
def test_train_config_refuses_bad_validation_draws(bad):
    with pytest.raises(ValueError, match="TrainConfig.robust_validation_draws"):
        tr.TrainConfig(robust_validation_draws=bad)


def test_the_loss_under_one_draw_is_predicts_loss_with_that_draw(variant):
    data = linear_task(50)
    model = tr.build_mincam(data, 2, seed=3)
    draw = validation_draws(model, VAL_CFG)[1]
    expected = tr.predict(model, data, draw=draw, batch_size=16, limit=40)[2]
    assert mean_loss_under(model, data, [draw], batch_size=16, limit=40) == expected


def test_input_norm_in_running_mode_keeps_a_cameras_gain_error_that_batch_statistics_remove():
    g = torch.Generator().manual_seed(0)
    first = torch.rand(64, 4, generator=g) + 1.0
    second = torch.rand(64, 4, generator=g) + 1.0
    gain_error = torch.tensor([1.1, 1.0, 1.0, 1.0])  # one built camera's pixel 0 reads 10 % high
    plain = InputNorm(4).train()
    torch.testing.assert_close(plain(second * gain_error), plain(second), atol=1e-3, rtol=0)  # free
    norm = InputNorm(4).train()
    norm.running_in_training = True
    out1 = norm(first)  # the first batch sets the statistics
    m1, v1 = first.mean(0), first.var(0)
    torch.testing.assert_close(out1, (first - m1) / torch.sqrt(v1 + norm.eps))
    x = (second * gain_error).requires_grad_()
    out2 = norm(x)  # normalised by the statistics before this batch, then they move
    torch.testing.assert_close(out2, (x - m1) / torch.sqrt(v1 + norm.eps))
    m2, v2 = x.detach().mean(0), x.detach().var(0)
    torch.testing.assert_close(norm.running_mean, 0.9 * m1 + 0.1 * m2)
    torch.testing.assert_close(norm.running_var, 0.9 * v1 + 0.1 * v2)
    out2.sum().backward()  # the statistics are constants of the gradient
    torch.testing.assert_close(x.grad, (1 / torch.sqrt(v1 + norm.eps)).expand(64, 4))
    assert int(norm.num_batches_tracked) == 2
    norm.eval()
    torch.testing.assert_close(
        norm(first), (first - norm.running_mean) / torch.sqrt(norm.running_var + norm.eps)
    )


def test_only_robust_training_normalises_by_running_statistics(variant):
    train, val, _ = linear_task(120).split((0.7, 0.15, 0.15))
    nominal = tr.build_mincam(train, 2, seed=3)
    tr.train_model(nominal, train, val, dataclasses.replace(CFG, perturbation=None))
    robust = tr.build_mincam(train, 2, seed=3)
    tr.train_model(robust, train, val, CFG)
    assert robust.head.input_norm.running_in_training
    assert not nominal.head.input_norm.running_in_training
