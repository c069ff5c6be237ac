r"""The adversarial privacy term: masks that carry the task and hide the scene (torch).

An adversary (a small decoder, part of the camera so it is checkpointed with
it) learns to reconstruct a coarse image of the scene from the pixel outputs;
the masks and head learn to minimise the task loss minus ``weight`` times the
adversary's loss. Both updates come from one backward pass:

.. math::

    L = L_{task}(\theta) - w \, L_{adv}(\theta, \bar\phi) + L_{adv}(\bar\theta, \phi)

where a bar stops the gradient: the camera parameters :math:`\theta` see only
the first two terms, the adversary's :math:`\phi` only the last (its own
reconstruction loss on the detached pixel outputs), as in alternating
adversarial training with simultaneous steps.

The adversary's target is the scene as the first detector sees it with an open
mask: its transport box-summed to ``grid x grid`` pixels and divided by the
frame's mean (the layout of light, not the overall brightness, which any light
meter reveals). It is a proxy of the privacy audit's attacker
(:mod:`mincam_render.studies.privacy`), which reconstructs a rendered
perspective view instead; the audit measures whether the proxy helps.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn
from torch.func import functional_call

from mincam_render.learn.models import box_pixels

#: Pixels per side of the adversary's target image.
ADVERSARY_GRID = 16
#: Units of each of the adversary's two hidden layers.
ADVERSARY_HIDDEN = 128


class PrivacyAdversary(nn.Module):
    """Decoder from pixel outputs ``[batch, pixel]`` to a ``grid x grid`` image (mean 1).

    Args:
        inputs: pixel outputs per sample.
        grid: pixels per side of the target image (at most the mask resolution).
        hidden: units of each hidden layer.
        seed: seed of the initial weights.
    """

    def __init__(
        self, inputs: int, *, grid: int = ADVERSARY_GRID, hidden: int = ADVERSARY_HIDDEN,
        seed: int = 0,
    ) -> None:  # fmt: skip
        super().__init__()
        if inputs < 1 or grid < 1 or hidden < 1:
            raise ValueError(f"inputs = {inputs}, grid = {grid}, hidden = {hidden}: need >= 1")
        self.grid = int(grid)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(int(seed))
            # the pixel outputs are volts of any scale: standardised per batch
            self.norm = nn.BatchNorm1d(inputs, affine=False)
            self.net = nn.Sequential(
                nn.Linear(inputs, hidden),
                nn.ReLU(),
                nn.Linear(hidden, hidden),
                nn.ReLU(),
                nn.Linear(hidden, grid * grid),
            )

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """Reconstructed image ``[batch, grid * grid]`` of pixel outputs ``[batch, pixel]``."""
        return self.net(self.norm(features))

    def target(self, frames: torch.Tensor) -> torch.Tensor:
        """``[batch, grid * grid]``: detector 0's transport, box-summed, over its mean.

        ``frames`` is ``T[batch, detector, row, col]``; a frame without light gives zeros.
        """
        img = box_pixels(frames[:, 0].float(), (self.grid, self.grid)).reshape(len(frames), -1)
        mean = img.mean(dim=1, keepdim=True)
        return img / torch.where(mean > 0, mean, torch.ones_like(mean))

    def loss(self, features: torch.Tensor, target: torch.Tensor, *, frozen: bool) -> torch.Tensor:
        """Mean squared reconstruction error; ``frozen``: no gradient to the adversary."""
        if not frozen:
            return F.mse_loss(self(features), target)
        params = {k: v.detach() for k, v in self.named_parameters()}
        return F.mse_loss(functional_call(self, params, (features,)), target)


def privacy_objective(
    adversary: PrivacyAdversary, features: torch.Tensor, frames: torch.Tensor, weight: float
) -> torch.Tensor:
    """The two privacy terms to add to the task loss (module docstring): one scalar.

    Args:
        adversary: the decoder.
        features: pixel outputs ``[batch, pixel]`` (with their graph to the masks).
        frames: ``T[batch, detector, row, col]`` of the samples (any scale per frame).
        weight: ``w`` >= 0.
    """
    target = adversary.target(frames)
    fooled = adversary.loss(features, target, frozen=True)
    learned = adversary.loss(features.detach(), target, frozen=False)
    return learned - weight * fooled
