"""The recipe's priors and augmentations, and validation pooled over several episodes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from support import linear_task

from mincam_render.learn import train as tr
from mincam_render.learn.evaluation import episode_limits, metrics, pooled_validation, predict
from mincam_render.learn.models import block_mean
from mincam_render.learn.runs import config_record, describe_run
from mincam_render.learn.step import noisy_transport
from mincam_render.optics.maskplane import total_variation_per_texel


def test_total_variation_per_texel_closed_forms():
    uniform = torch.full((2, 4, 4), 0.3)
    assert float(total_variation_per_texel(uniform)) == 0.0
    # vertical stripes 0/1: every row has 3 jumps of 1, 4 rows; no jumps down the columns
    stripes = torch.tensor([0.0, 1.0, 0.0, 1.0]).repeat(4, 1)[None]
    np.testing.assert_allclose(float(total_variation_per_texel(stripes)), 12 / 16, rtol=1e-7)
    # a checkerboard of lo/hi over R x C: 2 R (C - 1) jumps of (hi - lo) in all
    lo, hi, n = 0.01, 0.67, 8
    board = lo + (hi - lo) * ((np.add.outer(np.arange(n), np.arange(n)) % 2).astype(np.float64))
    tv = float(total_variation_per_texel(torch.from_numpy(board)[None]))
    np.testing.assert_allclose(tv, 2 * n * (n - 1) * (hi - lo) / n**2, rtol=1e-12)
    with pytest.raises(ValueError, match="pixel, row, col"):
        total_variation_per_texel(torch.zeros(4, 4))


def test_mask_penalty_gradient_matches_finite_differences():
    data = linear_task(20, k=2, res=4)
    model = tr.build_mincam(data, 2).double()
    lo, hi = model.camera.transmittance_range

    def penalty(z):  # written out: TV of the transmittance plus the mean squared logit
        t = lo + (hi - lo) * torch.sigmoid(z)
        return 0.7 * total_variation_per_texel(t) + 0.3 * z.square().mean()

    g = torch.Generator().manual_seed(0)
    x = 2 * torch.randn(model.logits.shape, dtype=torch.float64, generator=g)
    assert torch.autograd.gradcheck(penalty, (x.clone().requires_grad_(True),), eps=1e-6)
    with torch.no_grad():
        model.logits.copy_(x)
    value = model.mask_penalty(0.7, 0.3)
    value.backward()
    xr = x.clone().requires_grad_(True)
    expected = torch.autograd.grad(penalty(xr), xr)[0]
    np.testing.assert_allclose(value.item(), penalty(x).item(), rtol=1e-12)
    torch.testing.assert_close(model.logits.grad, expected, rtol=1e-10, atol=1e-12)
    assert float(model.mask_penalty(0.0, 0.0)) == 0.0


def test_block_mean_averages_each_tile():
    g = torch.arange(16.0).reshape(1, 4, 4)
    out = block_mean(g, block=2)
    expected = torch.tensor([[2.5, 2.5, 4.5, 4.5], [2.5, 2.5, 4.5, 4.5],
                             [10.5, 10.5, 12.5, 12.5], [10.5, 10.5, 12.5, 12.5]])  # fmt: skip
    torch.testing.assert_close(out[0], expected)


def test_block_masks_stay_blocks_through_training_and_get_block_mean_gradients():
    data = linear_task(120, k=2, res=8)
    free = tr.build_mincam(data, 2, seed=3)
    blocks = tr.build_mincam(data, 2, seed=3, mask_block=4)
    m = blocks.transmittance().detach()
    assert torch.equal(m, m[:, ::4, ::4].repeat_interleave(4, 1).repeat_interleave(4, 2))
    # the same logits: the block camera's gradient is the free camera's averaged per block
    with torch.no_grad():
        free.logits.copy_(blocks.logits)
    batch = data.sample(torch.arange(32))
    for model in (free, blocks):
        out = model(**batch.inputs(), noise=False)
        tr.task_loss(model.head, out, batch.labels)[0].backward()
    torch.testing.assert_close(blocks.logits.grad, block_mean(free.logits.grad, block=4))
    cfg = tr.TrainConfig(max_steps=60, batch_size=16, eval_every=20, mask_block=4)
    tr.train_model(blocks, data, data, cfg)
    m = blocks.transmittance().detach()
    assert torch.equal(m, m[:, ::4, ::4].repeat_interleave(4, 1).repeat_interleave(4, 2))
    assert not torch.equal(m, torch.full_like(m, float(m[0, 0, 0])))  # the masks moved
    with pytest.raises(ValueError, match="mask_block = 3 texels"):
        tr.build_mincam(data, 2, mask_block=3)


def test_noisy_transport_has_the_relative_spread_asked_for():
    data = linear_task(64, k=2, res=8, background_w=0.0)
    batch = data.sample(torch.arange(64))
    g = torch.Generator().manual_seed(0)
    noisy = noisy_transport(batch, 0.1, g).transport
    ratio = (noisy / batch.transport)[batch.transport > 0]
    # 8,192 draws: the mean of N(1, 0.1) within 5 standard errors, the spread within 3 %
    assert abs(float(ratio.mean()) - 1.0) < 5 * 0.1 / np.sqrt(ratio.numel())
    np.testing.assert_allclose(float(ratio.std()), 0.1, rtol=0.03)
    assert torch.equal(noisy_transport(batch, 0.1, g).labels["count"], batch.labels["count"])


def test_recipe_fields_are_validated():
    for field, bad in (
        ("mask_tv_weight", -1.0),
        ("mask_logit_decay", float("nan")),
        ("transport_noise", 2.0),
        ("mask_block", 0),
        ("signed_pixels", 1),
    ):
        with pytest.raises(ValueError, match=field):
            tr.TrainConfig(**{field: bad})


def test_default_recipe_leaves_run_records_unchanged():
    record = config_record(tr.TrainConfig())
    assert not {"mask_tv_weight", "mask_logit_decay", "transport_noise", "mask_block"} & set(record)
    assert config_record(tr.TrainConfig(mask_block=2))["mask_block"] == 2


def test_sweep_cameras_get_the_recipes_head_and_seed():
    from mincam_render.learn.builders import hidden_width
    from mincam_render.learn.sweep import _sweep_jobs

    data = linear_task(n=64)
    config = tr.TrainConfig(head_hidden=24, seed=3)
    jobs = dict(_sweep_jobs(data, [2], ["2x2"], config))
    assert sorted(jobs) == ["baseline_2x2", "mincam_2px"]
    for name, build in jobs.items():
        model = build()
        assert hidden_width(model.head) == 24, name
        again = dict(_sweep_jobs(data, [2], ["2x2"], config))[name]()
        other = dict(_sweep_jobs(data, [2], ["2x2"], replace(config, seed=4)))[name]()
        first = next(model.head.parameters())
        assert torch.equal(first, next(again.head.parameters())), name
        assert not torch.equal(first, next(other.head.parameters())), name


def test_signed_pixels_take_pairs_of_detectors_and_no_baseline(tmp_path):
    from mincam_render.learn.sweep import _sweep_jobs

    four = linear_task(n=64, k=4)
    assert tr.build_mincam(four, 2, signed=True).detectors.tolist() == [0, 1, 2, 3]
    assert tr.build_mincam(four, signed=True).num_outputs == 2  # every detector, in pairs
    with pytest.raises(ValueError, match="3 signed pixels need 6 photodiodes: the data has only 4"):
        tr.build_mincam(four, 3, signed=True)
    with pytest.raises(ValueError, match="pairs of detectors; the data has only one"):
        tr.build_mincam(linear_task(n=64, k=1), signed=True)
    jobs = dict(_sweep_jobs(four, None, [], tr.TrainConfig(signed_pixels=True)))
    assert sorted(jobs) == ["mincam_1px_signed", "mincam_2px_signed"]
    assert jobs["mincam_2px_signed"]().signed
    train, val = four.split((0.5, 0.5))
    with pytest.raises(ValueError, match="signed_pixels = True: an option of freeform pixels"):
        tr.train_run(train, val, None, tmp_path / "b", baseline_grid=(2, 2),
                     config=tr.TrainConfig(signed_pixels=True))  # fmt: skip


def test_pooled_validation_is_the_sample_weighted_pool_of_the_episodes():
    data = linear_task(300, k=2, res=8)
    model = tr.build_mincam(data, 2)
    a, b = data.subset(0, 100, "a"), data.subset(100, 300, "b")
    pooled = pooled_validation(model, [a, b])
    parts = []
    for ep in (a, b):
        pred, lab, loss = predict(model, ep)
        parts.append((loss, metrics(pred, lab, loss, ep).error, len(ep)))
    w = np.array([n for *_, n in parts], np.float64) / 300
    np.testing.assert_allclose(pooled["loss"], w @ [p[0] for p in parts], rtol=1e-12)
    rmse = np.sqrt(w @ np.square([p[1] for p in parts]))
    np.testing.assert_allclose(pooled["error"], rmse, rtol=1e-12)
    # one episode: exactly what the loop validated with before
    pred, lab, loss = predict(model, a, limit=50)
    assert pooled_validation(model, [a], limit=50)["loss"] == loss
    with pytest.raises(ValueError, match="at least one"):
        pooled_validation(model, [])


def test_episode_limits_share_the_budget_by_length():
    data = linear_task(300, k=1, res=2)
    eps = [data.subset(0, 100), data.subset(100, 300)]
    assert episode_limits(eps, None) == [None, None]
    assert episode_limits(eps, 400) == [None, None]
    assert episode_limits(eps, 30) == [10, 20]


def test_training_on_several_validation_episodes_records_the_pooled_error(tmp_path):
    data = linear_task(400, k=2, res=8)
    train, v1, v2 = data.subset(0, 200), data.subset(200, 300), data.subset(300, 400)
    cfg = tr.TrainConfig(max_steps=40, batch_size=16, eval_every=20)
    model = tr.build_mincam(train, 2)
    res = tr.train_model(model, train, [v1, v2], cfg, out_dir=tmp_path)
    assert all({"val_loss", "val_error"} <= set(h) for h in res.history)
    # the kept (best) state is the one whose pooled validation loss was recorded
    assert res.best_val_loss == pooled_validation(model, [v1, v2])["loss"]
    best = next(h for h in res.history if h["step"] == res.best_step)
    assert best["val_error"] == pooled_validation(model, [v1, v2])["error"]
    run = describe_run(model, train, [v1, v2], None, cfg, False)
    assert [v["range"] for v in run["data"]["val"]] == [[200, 300], [300, 400]]
    assert describe_run(model, train, v1, None, cfg, False)["data"]["val"] == v1.source


def test_a_static_part_is_replaced_frame_by_frame():
    data = linear_task(10, k=2, res=4)
    rng = np.random.default_rng(0)
    static = rng.uniform(0, 1e-9, data.transport.shape).astype(np.float32)
    fixed = np.full(data.transport.shape[1:], 5e-10, np.float32)
    out = data.with_static_part(static, fixed)
    np.testing.assert_array_equal(out.transport, data.transport - static + fixed)
    assert out.scales is None and out.labels is not None and out.source["static_part"]
    with pytest.raises(ValueError, match="static part has shape"):
        data.with_static_part(static[:3], fixed)
    with pytest.raises(ValueError, match="replacement has shape"):
        data.with_static_part(static, fixed[0])
