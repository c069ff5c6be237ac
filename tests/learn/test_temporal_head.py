"""The temporal convolution head: shapes, causality, gradients, and that it learns history."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from support import temporal_task

from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.learn import train as tr
from mincam_render.learn.runs import config_record
from mincam_render.learn.temporal_head import TemporalConvHead, tcn_dilations

SPECS = (
    LabelSpec(name="speed", kind=LabelKind.REGRESSION, size=2, unit="mph"),
    LabelSpec(name="lights", kind=LabelKind.BINARY, size=3),
)


@pytest.mark.parametrize(("steps", "dilations"), [(1, (1,)), (3, (1,)), (29, (1, 2, 4, 8))])
def test_receptive_field_covers_the_window(steps, dilations):
    assert tcn_dilations(steps) == dilations
    assert 1 + 2 * sum(dilations) >= steps


def test_shapes_and_refused_inputs():
    head = TemporalConvHead(4, 29, SPECS)
    assert head.in_features == 4 * 29
    x = torch.randn(5, 4 * 29)
    out = head(x)
    assert out["speed"].shape == (5, 2) and out["lights"].shape == (5, 3)
    assert head.sequence(x).shape == (5, 32, 29)
    assert head.input_running_mean().shape == (4 * 29,)
    assert head.fan_in == 4 * 3  # the first convolution's inputs per unit
    with pytest.raises(ValueError, match="29 steps x 4 pixels"):
        head(torch.randn(5, 4 * 28))
    with pytest.raises(ValueError, match="pixels"):
        TemporalConvHead(0, 29, SPECS)


@pytest.mark.parametrize("step", [0, 7, 19])
def test_features_at_a_step_do_not_depend_on_later_steps(step):
    torch.manual_seed(0)
    head = TemporalConvHead(3, 20, SPECS).eval()  # running statistics: no batch coupling
    x = torch.randn(2, 20, 3)
    y = x.clone()
    y[:, step] += 1.0
    with torch.no_grad():
        a, b = (head.sequence(v.reshape(2, -1)) for v in (x, y))
    torch.testing.assert_close(a[:, :, :step], b[:, :, :step], rtol=0, atol=0)
    assert (a[:, :, step] - b[:, :, step]).abs().max() > 1e-4


@pytest.mark.parametrize("training", [True, False])
def test_gradients_match_finite_differences_in_float64(training):
    torch.manual_seed(1)
    head = TemporalConvHead(2, 5, SPECS, channels=3, hidden=4).double().train(training)
    x = torch.randn(4, 10, dtype=torch.float64, requires_grad=True)

    def outputs(inp: torch.Tensor) -> torch.Tensor:
        return torch.cat(list(head(inp).values()), dim=1)

    assert torch.autograd.gradcheck(outputs, (x,), eps=1e-6, atol=1e-6)


def test_tcn_learns_a_change_over_time_far_better_than_the_trivial_predictor():
    data = temporal_task(n=600, seed=0)
    train, val = data.subset(0, 450, "train"), data.subset(450, 600, "val")
    cfg = tr.TrainConfig(
        max_steps=400, batch_size=32, eval_every=50, patience=20, seed=0, head=tr.HeadKind.TCN
    )
    model = tr.build_mincam(train, 1, seed=0, head=cfg.head)
    assert isinstance(model.head, TemporalConvHead)
    tr.train_model(model, train, val, cfg)
    _, lab, loss = tr.predict(model, val)
    y = train.labels["change"]
    mean, std = float(np.mean(y)), float(np.std(y))
    trivial = float(np.mean(((lab["change"] - mean) / std) ** 2))
    assert loss < 0.25 * trivial, (loss, trivial)


def test_the_head_is_a_choice_of_the_recipe_recorded_in_the_model():
    data = temporal_task(n=80, seed=1)
    mlp = tr.build_mincam(data, 2)
    tcn = tr.build_mincam(data, 2, head=tr.HeadKind.TCN)
    base = tr.build_baseline(data, (2, 2), head=tr.HeadKind.TCN)
    assert "head" not in tr.describe_model(mlp)  # the paper's models: descriptions unchanged
    assert tr.describe_model(tcn)["head"] == tr.describe_model(base)["head"] == "tcn"
    assert tr.TrainConfig(head="tcn").head is tr.HeadKind.TCN
    with pytest.raises(ValueError, match="TrainConfig.head"):
        tr.TrainConfig(head="lstm")


def test_train_run_records_the_head_and_resumes_runs_written_before_the_choice(tmp_path):
    data = temporal_task(n=120, seed=2)
    train, val = data.subset(0, 80, "train"), data.subset(80, 120, "val")
    cfg = tr.TrainConfig(max_steps=4, eval_every=2, batch_size=8, head="tcn")
    metrics = tr.train_run(train, val, None, tmp_path / "tcn", pixels=1, config=cfg)
    run = json.loads((tmp_path / "tcn" / "run.json").read_text())
    assert run["config"]["head"] == "tcn" and metrics.model["head"] == "tcn"
    # the paper's MLP: run.json's recipe as before the head was a choice
    assert "head" not in config_record(tr.TrainConfig())
    assert "perturbation" not in config_record(tr.TrainConfig())


def test_the_default_learning_rate_follows_the_first_layers_fan_in():
    data = temporal_task(n=80, seed=3)  # history 12: 11 differenced steps
    cfg = tr.TrainConfig()
    mlp = tr.build_optimizer(tr.build_mincam(data, 2), cfg).param_groups[0]["lr"]
    tcn = tr.build_optimizer(tr.build_mincam(data, 2, head="tcn"), cfg).param_groups[0]["lr"]
    assert mlp == pytest.approx(tr.learning_rate_for(2 * 11))
    assert tcn == pytest.approx(tr.learning_rate_for(2 * 3))


def test_a_bottleneck_is_refused_for_the_convolution_head():
    from mincam_render.learn.builders import build_head

    data = temporal_task(40)
    steps = data.history - 1
    with pytest.raises(ValueError, match="bottleneck = 2: the temporal convolution head"):
        build_head(data, 2 * steps, kind=tr.HeadKind.TCN, bottleneck=2)
    assert build_head(data, 2 * steps, kind=tr.HeadKind.MLP, bottleneck=2).bottleneck == 2
