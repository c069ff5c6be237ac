"""Task metrics of a recording: heads trained on simulation and/or real data, tested on real.

Trained on simulation / tested on real; the sim-trained head retrained on real,
as the paper did; trained and tested on real. Arrays are numpy unless a docstring
says torch; voltages in volts.
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING, cast

import numpy as np

from mincam_render.studies.sim2real.recording import Recording
from mincam_render.studies.sim2real.result import TaskMetrics

if TYPE_CHECKING:
    import torch

    from mincam_render.learn.models import Model
    from mincam_render.learn.training_data import TrainingData

#: Fraction of the recording in the train/val/test segments (contiguous).
SPLITS = (0.6, 0.2, 0.2)


def _measurement_model(
    num_inputs: int, data: TrainingData, read_noise_v: float, seed: int
) -> Model:
    """A torch module: measured voltages ``[b, time, P, 1, 1]`` -> :class:`Head` outputs."""
    import torch
    from torch import nn

    from mincam_render.learn.models import _per_window, temporal_features
    from mincam_render.learn.train import build_head

    class MeasurementHead(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.head = build_head(data, num_inputs, seed=seed)

        def forward(
            self,
            transport: torch.Tensor,
            *,
            windows: torch.Tensor | None = None,
            frame_scales: torch.Tensor | None = None,
            gain: torch.Tensor | None = None,
            noise: bool = True,
            generator: torch.Generator | None = None,
            draw: object = None,
        ) -> dict[str, torch.Tensor]:
            # the arguments of CameraModel.forward; frames [frame, P, 1, 1] -> [b, time, P, 1, 1]
            if draw is not None:
                raise ValueError("measured voltages have no masks or diodes to perturb")
            t = _per_window(transport, windows, frame_scales) if transport.ndim == 4 else transport
            v = t.reshape(t.shape[0], -1, t.shape[-3])
            if gain is not None:
                v = v * gain.reshape(-1, 1, 1)
            if noise and read_noise_v > 0:
                v = v + read_noise_v * torch.randn(v.shape, generator=generator, dtype=v.dtype)
            return self.head(temporal_features(v))

    # duck-types CameraModel (same forward and .head), which the training loop and
    # evaluation accept; the cast is for mypy only
    return cast("Model", MeasurementHead())


def task_metrics(rec: Recording, sim_volts: np.ndarray, *, steps: int, seed: int) -> TaskMetrics:
    """Task errors on the real test segment for heads trained on simulation and/or real data."""
    from mincam_render.learn.train import TrainConfig, TrainingData, evaluate, train_model
    from mincam_render.learn.train_config import GAIN_AUGMENTATION_20

    history = 30 if rec.meta.get("needs_history") else 1
    fps = float(rec.meta["fps"])

    def data(v: np.ndarray) -> TrainingData:
        return TrainingData(
            transport=v.astype(np.float32)[:, :, None, None],
            labels=rec.labels,
            label_specs=rec.label_specs,
            camera=rec.camera,
            fps=fps,
            history=history,
        )

    sim_tr, sim_va, sim_te = data(sim_volts).split(SPLITS)
    real_tr, real_va, real_te = data(rec.volts).split(SPLITS)
    n_in = rec.volts.shape[1] * max(history - 1, 1)
    noise = rec.camera.electronics.read_noise_v
    cfg = TrainConfig(  # the recipe sim2real_surrogate.json was measured with
        max_steps=steps, eval_every=max(10, steps // 20), patience=6, seed=seed, batch_size=64,
        gain_range=GAIN_AUGMENTATION_20,
    )  # fmt: skip
    # evaluated in this order (the heads' training and evaluation share torch's state)
    sim_model = _measurement_model(n_in, sim_tr, noise, seed)
    train_model(sim_model, sim_tr, sim_va, cfg)
    sim_on_sim = evaluate(sim_model, sim_te, noise=False)
    sim_on_real = evaluate(sim_model, real_te, noise=False)
    retrained = copy.deepcopy(sim_model)
    train_model(retrained, real_tr, real_va, cfg)
    retrained_on_real = evaluate(retrained, real_te, noise=False)
    real_model = _measurement_model(n_in, real_tr, noise, seed)
    train_model(real_model, real_tr, real_va, cfg)
    return TaskMetrics(
        sim_on_sim=sim_on_sim,
        sim_on_real=sim_on_real,
        sim_head_retrained_on_real=retrained_on_real,
        real_on_real=evaluate(real_model, real_te, noise=False),
    )
