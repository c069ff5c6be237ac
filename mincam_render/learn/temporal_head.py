"""A temporal convolution head: causal 1-D convolutions over a pixel history, then the MLP.

An alternative to the paper's stacked-history head for temporal tasks
(traffic): instead of one dense layer over every (time step, pixel) input,
a few causal convolutions with doubling dilation slide over the
forward-differenced history of the ``K`` pixels, sharing weights across time,
and the features of the last time step feed the paper's two hidden layers and
the same output groups (:class:`~mincam_render.learn.models.Head`). Its
receptive field covers the whole window. Causal: the features at step ``t``
depend on steps ``<= t`` only (in evaluation mode; in training mode the input
batch norm's statistics are taken over the batch and every step, as the
MLP's are over the batch). Tensors are torch.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import cast

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from mincam_render.core.labels import LabelSpec
from mincam_render.learn.models import LEAKY_SLOPE, Head, InputNorm
from mincam_render.learn.train_config import HIDDEN_UNITS

#: Channels of every convolution and its kernel length (time steps).
TCN_CHANNELS = 32
TCN_KERNEL = 3


def tcn_dilations(steps: int, kernel: int = TCN_KERNEL) -> tuple[int, ...]:
    """Dilations 1, 2, 4, ... until the receptive field ``1 + (kernel-1)*sum`` covers ``steps``."""
    if steps < 1 or kernel < 2:
        raise ValueError(f"steps = {steps}, kernel = {kernel}: need steps >= 1 and kernel >= 2")
    dilations = [1]
    while 1 + (kernel - 1) * sum(dilations) < steps:
        dilations.append(2 * dilations[-1])
    return tuple(dilations)


class CausalConv1d(nn.Conv1d):
    """A 1-D convolution over ``x[batch, channel, time]`` that sees only the past (left padding)."""

    def __init__(self, in_channels: int, out_channels: int, kernel: int, dilation: int) -> None:
        super().__init__(in_channels, out_channels, kernel, dilation=dilation)
        self.left_pad = (kernel - 1) * dilation

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``y[batch, out_channels, time]``; ``y[..., t]`` uses ``x[..., :t+1]`` only."""
        return super().forward(F.pad(x, (self.left_pad, 0)))


class TemporalConvHead(Head):
    """Causal temporal convolutions over ``steps`` x ``pixels`` inputs, then the paper's MLP.

    Args:
        pixels: measurements per time step (``K``).
        steps: time steps of the (forward-differenced) history (29 for traffic).
        label_specs: the task's labels (output groups as :class:`Head`).
        target_mean: as :class:`Head`.
        target_std: as :class:`Head`.
        count_classes: as :class:`Head`.
        channels: channels of every convolution.
        kernel: kernel length of every convolution (time steps, >= 2).
        hidden: width of the two hidden layers.

    Inputs are the flattened history ``x[batch, steps * pixels]``, time-major
    (what :func:`~mincam_render.learn.models.temporal_features` gives).

    Raises:
        ValueError: fewer than one pixel or step, a kernel below 2, or what
            :class:`Head` refuses.

    """

    def __init__(
        self,
        pixels: int,
        steps: int,
        label_specs: Sequence[LabelSpec],
        *,
        target_mean: Mapping[str, np.ndarray] | None = None,
        target_std: Mapping[str, np.ndarray] | None = None,
        count_classes: Mapping[str, int] | None = None,
        channels: int = TCN_CHANNELS,
        kernel: int = TCN_KERNEL,
        hidden: int = HIDDEN_UNITS,
    ) -> None:
        if pixels < 1:
            raise ValueError(f"pixels = {pixels}: need at least 1")
        dilations = tcn_dilations(steps, kernel)
        super().__init__(
            channels,
            label_specs,
            target_mean=target_mean,
            target_std=target_std,
            count_classes=count_classes,
            hidden=hidden,
        )
        self.pixels, self.steps = int(pixels), int(steps)
        # per pixel, shared over time: the differenced signals are stationary in time
        self.input_norm = InputNorm(self.pixels)
        layers: list[nn.Module] = []
        for i, d in enumerate(dilations):
            layers += [
                CausalConv1d(self.pixels if i == 0 else channels, channels, kernel, d),
                nn.LeakyReLU(LEAKY_SLOPE),
            ]
        self.temporal = nn.Sequential(*layers)

    @property
    def in_features(self) -> int:
        """Number of inputs: ``steps * pixels``."""
        return self.steps * self.pixels

    @property
    def fan_in(self) -> int:
        """Inputs of one unit of the first convolution: ``pixels * kernel``."""
        first = cast(CausalConv1d, self.temporal[0])
        return self.pixels * first.kernel_size[0]

    def sequence(self, x: torch.Tensor) -> torch.Tensor:
        """Convolution features ``[batch, channels, steps]`` of ``x[batch, steps * pixels]``."""
        if x.ndim != 2 or x.shape[1] != self.in_features:
            raise ValueError(
                f"inputs have shape {tuple(x.shape)}: expected (batch, {self.in_features}) "
                f"= {self.steps} steps x {self.pixels} pixels"
            )
        z = x.reshape(len(x), self.steps, self.pixels).transpose(1, 2)
        return self.temporal(self.input_norm(z))

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """Hidden features ``[batch, hidden]``: the MLP on the last step's convolution features."""
        return self.body(self.sequence(x)[:, :, -1])

    def input_running_mean(self) -> torch.Tensor:
        """``[steps * pixels]`` running mean of every input (each pixel's, at every step)."""
        return super().input_running_mean().repeat(self.steps)
