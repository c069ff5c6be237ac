"""Robust training: a built camera per batch, reproducible and resumable."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from support import linear_task

from mincam_render.learn import train as tr
from mincam_render.learn.step import batch_draw
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
    assert [x.shift_mm.tolist() for x in a] == [x.shift_mm.tolist() for x in b]  # type: ignore[union-attr]
    assert not np.array_equal(a[0].shift_mm, a[1].shift_mm)  # type: ignore[union-attr]
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
    run, _ = tr.load_run(tmp_path / "run")
    assert run["config"]["perturbation"]["mask_shift_mm"] == pytest.approx(0.3)
    loaded = tr.load_mincam(tmp_path / "run", test)
    assert tr.evaluate(loaded, test)["error"] == pytest.approx(metrics["test"]["error"])


def test_train_config_refuses_a_perturbation_of_another_type():
    with pytest.raises(ValueError, match="TrainConfig.perturbation"):
        tr.TrainConfig(perturbation={"mask_shift_mm": 0.3})  # type: ignore[arg-type]


def test_a_baseline_camera_refuses_a_draw():
    data = linear_task(20)
    model = tr.build_baseline(data, (2, 2))
    draw = PerturbationModel().draw(1, np.random.default_rng(0))
    with pytest.raises(ValueError, match="baseline"):
        model.measure(torch.from_numpy(data.transport), draw=draw)
