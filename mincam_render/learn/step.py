"""One optimisation step: the Adam optimiser of a camera, its fused kernel, the step itself.

The step is plain torch when the transport is a torch tensor (every dataset on
disk): one ``index_select`` of the batch's frames, the mask plane as one
batched matrix product, the electronics as a handful of fused ops, fused Adam.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from mincam_render.core.seeds import stream_seed
from mincam_render.learn.batches import DatasetBatches, RenderedBatches
from mincam_render.learn.builders import learning_rate_for
from mincam_render.learn.models import MincamCamera, Model, task_loss, temporal_features
from mincam_render.learn.train_config import TrainConfig
from mincam_render.learn.training_data import Batch
from mincam_render.optics.perturbation import PerturbationDraw, PerturbationModel


def build_optimizer(model: Model, config: TrainConfig) -> torch.optim.Adam:
    """Adam over the head (``config.lr`` or :func:`learning_rate_for`) and the mask logits.

    The default rate follows the fan-in of the head's first layer: every input
    for the paper's MLP, ``pixels x kernel`` for the temporal convolution head.
    """
    lr = config.lr if config.lr is not None else learning_rate_for(model.head.fan_in)
    groups = [{"params": [p for p in model.head.parameters() if p.requires_grad], "lr": lr}]
    if isinstance(model, MincamCamera) and model.logits.requires_grad:
        groups.append({"params": [model.logits], "lr": config.mask_lr})
    adversary = getattr(model, "adversary", None)
    if adversary is not None:  # its own objective; the head's rate for its fan-in
        groups.append({"params": list(adversary.parameters()), "lr": learning_rate_for(128)})
    try:
        # one kernel for all parameters: 0.08 ms per step against 0.22 ms (8 px head)
        return torch.optim.Adam(groups, fused=True)
    except (RuntimeError, ValueError):  # a device or dtype without the fused kernel
        return torch.optim.Adam(groups)


def adam_step(opt: torch.optim.Optimizer) -> None:
    """``opt.step()``; for a plain fused Adam, its fused kernel called directly.

    ``Optimizer.step`` and the functional ``torch.optim.adam.adam`` spend
    ~0.1 ms of Python per call (hooks, profiler record, lazy state checks,
    grouping by device) around one fused kernel per parameter group (measured
    in a step at 1 px, 32x32, batch 64: 0.16 ms through ``adam``, 0.09 ms
    direct, of a 1.2 ms step). Here the step counters are advanced and
    ``torch._fused_adam_`` -- the op ``torch.optim.Adam(fused=True)`` itself
    calls -- runs on the optimiser's own state tensors: bit-identical, state
    and ``state_dict`` unchanged. Anything else -- other optimisers or
    options, a torch without the op, parameters of mixed device or dtype, a
    parameter without a gradient or without state yet (the first step) --
    goes through ``opt.step()``. Step hooks are not called.
    """
    groups = opt.param_groups
    fused = getattr(torch, "_fused_adam_", None)
    if fused is None or type(opt) is not torch.optim.Adam or not all(map(_plain_fused, groups)):
        opt.step()
        return
    state = opt.state
    if any(p.grad is None or p not in state for g in groups for p in g["params"]):
        opt.step()
        return
    with torch.no_grad():
        for g in groups:
            params = g["params"]
            st = [state[p] for p in params]
            steps = [s["step"] for s in st]
            beta1, beta2 = g["betas"]
            torch._foreach_add_(steps, 1)
            fused(
                params, [p.grad for p in params], [s["exp_avg"] for s in st],
                [s["exp_avg_sq"] for s in st], [], steps, amsgrad=False, lr=g["lr"],
                beta1=beta1, beta2=beta2, weight_decay=0.0, eps=g["eps"], maximize=False,
            )  # fmt: skip


def _plain_fused(group: Mapping[str, Any]) -> bool:
    """A fused Adam group on one device and dtype, without amsgrad, weight decay, etc."""
    params = group["params"]
    return (
        bool(group["fused"])
        and not (
            group["amsgrad"] or group["weight_decay"] or group["maximize"]
            or group["capturable"] or group["differentiable"]
            or group["decoupled_weight_decay"] or isinstance(group["lr"], torch.Tensor)
        )
        and len({(p.device, p.dtype) for p in params}) == 1
    )  # fmt: skip


def train_step(
    model: Model,
    source: DatasetBatches | RenderedBatches,
    opt: torch.optim.Optimizer,
    generator: torch.Generator,
    gain_range: tuple[float, float],
    perturbation: PerturbationModel | None = None,
    privacy_weight: float = 0.0,
    *,
    transport_noise: float = 0.0,
    mask_tv_weight: float = 0.0,
    mask_logit_decay: float = 0.0,
) -> torch.Tensor:
    """One optimisation step of :func:`train_model` (Adam); the task loss, detached.

    A batch, a random global gain per sample (augmentation), with ``perturbation``
    a built camera drawn for the batch (robust training; the head's input norm
    then uses running statistics, :class:`~mincam_render.learn.models.InputNorm`),
    the camera with sensor noise, the loss, backward, the optimiser, and the projection of the
    mask logits (a saturated mask must be able to move back). A camera with a
    privacy adversary (``model.adversary``) adds
    :func:`~mincam_render.learn.privacy_term.privacy_objective` with ``privacy_weight``.
    ``transport_noise``: relative Gaussian noise on every texel of the batch's
    transport (augmentation, :class:`TrainConfig`); ``mask_tv_weight`` and
    ``mask_logit_decay``: priors on a minimalist camera's masks
    (:meth:`~mincam_render.learn.models.MincamCamera.mask_penalty`), added to
    the optimised objective, not to the returned task loss.
    """
    batch = source.next(generator)
    if transport_noise:
        batch = noisy_transport(batch, transport_noise, generator)
    gain = torch.empty(len(batch)).uniform_(*gain_range, generator=generator)
    draw = batch_draw(model, perturbation, generator)
    if isinstance(model, MincamCamera):
        # one built camera per batch: its own statistics would calibrate it (InputNorm)
        model.head.normalise_by_running_statistics(draw is not None)
    adversary = getattr(model, "adversary", None)
    if adversary is None:  # any model with a forward (sim2real's measured heads too)
        out = model(**batch.inputs(), gain=gain, noise=True, generator=generator, draw=draw)
        loss, _ = task_loss(model.head, out, batch.labels)
        total = loss
    else:
        from mincam_render.learn.privacy_term import privacy_objective

        v = model.measure(**batch.inputs(), gain=gain, noise=True, generator=generator, draw=draw)
        loss, _ = task_loss(model.head, model.head(temporal_features(v)), batch.labels)
        frames = batch.transport if batch.windows is None else batch.transport[batch.windows[:, -1]]
        total = loss + privacy_objective(adversary, v[:, -1], frames, privacy_weight)
    if isinstance(model, MincamCamera) and (mask_tv_weight or mask_logit_decay):
        total = total + model.mask_penalty(mask_tv_weight, mask_logit_decay)
    for group in opt.param_groups:  # zero_grad(set_to_none=True) without its overhead
        for p in group["params"]:
            p.grad = None
    total.backward()
    adam_step(opt)
    if isinstance(model, MincamCamera):
        model.project_logits_()
    return loss.detach()


def noisy_transport(batch: Batch, relative_std: float, generator: torch.Generator) -> Batch:
    """``batch`` with every texel's transport times ``1 + relative_std * N(0, 1)`` (torch).

    A new tensor (the batch's own may be a view of the stored frames).
    """
    t = batch.transport
    noise = torch.randn(t.shape, generator=generator, dtype=t.dtype, device=t.device)
    return dataclasses.replace(batch, transport=t * (1.0 + relative_std * noise))


def batch_draw(
    model: Model, perturbation: PerturbationModel | None, generator: torch.Generator
) -> PerturbationDraw | None:
    """A built camera for one batch, from ``generator`` (so a resumed run draws the same).

    None without a perturbation model or for a baseline camera (no masks, no diodes).
    """
    if perturbation is None or not isinstance(model, MincamCamera):
        return None
    n = perturbation.uniforms_needed(model.num_pixels)
    u = torch.rand(n, generator=generator, dtype=torch.float64).numpy()
    return perturbation.draw_from(u, model.num_pixels)


def validation_draws(model: Model, config: TrainConfig) -> list[PerturbationDraw]:
    """The built cameras robust validation measures with (empty: validate the design).

    ``config.robust_validation_draws`` cameras of ``config.perturbation``, drawn
    from a stream of ``config.seed`` of their own (not the batches' generator):
    the same cameras at every evaluation, and a resumed run draws them again.
    Empty without a perturbation model, for a baseline camera, or with 0 draws.
    """
    n = config.robust_validation_draws
    if config.perturbation is None or not isinstance(model, MincamCamera) or n == 0:
        return []
    rng = np.random.default_rng(stream_seed(config.seed, "train/validation_draws"))
    return [config.perturbation.draw(model.num_pixels, rng) for _ in range(n)]
