"""The training recipe as data (no PyTorch import: commands show its defaults at once)."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TypedDict

from mincam_render.core.checks import check_int, check_number
from mincam_render.optics.perturbation import PerturbationModel


class CountLoss(enum.Enum):
    """How a COUNT label is learned.

    * ``MSE``: regression of the standardised count (paper, supplement C: people count).
    * ``CROSS_ENTROPY``: classification into counts ``0 .. n-1`` (paper Sec. 5: patches);
      predicts the expected count under the softmax.
    """

    MSE = "mse"
    CROSS_ENTROPY = "cross_entropy"


class ModelKind(enum.StrEnum):
    """The kind of camera a run trained (``run.json``'s and a study's ``model.kind``)."""

    MINCAM = "mincam"
    BASELINE = "baseline"


#: Width of the head's two hidden layers (paper Sec. 5).
HIDDEN_UNITS = 128


class HeadKind(enum.Enum):
    """The inference network behind the pixels.

    * ``MLP``: the paper's head: the (forward-differenced) history of every
      pixel stacked into one vector, two hidden layers of 128 units.
    * ``TCN``: a temporal convolution head: causal 1-D convolutions over the
      history of the pixels (forward-differenced), then the same two hidden
      layers on the last time step's features. For a static task (history 1)
      it is a per-frame network like the MLP.
    """

    MLP = "mlp"
    TCN = "tcn"


#: The gain augmentation of the recipe before the design protocol (a random +-20 %
#: gain per sample); the benchmarks measured with it pin it. The protocol's recipe
#: table found no augmentation or prior lower than none on the validation
#: episodes (``docs/design_protocol.md``).
GAIN_AUGMENTATION_20 = (0.8, 1.2)


class MaskReference(enum.Enum):
    """Reference masks a learned design must beat (:mod:`mincam_render.learn.reference_masks`).

    * ``PCA``: the first principal components of the training views.
    * ``PLS``: partial least squares of the views on the task's labels.
    * ``DISTILLED``: a full-resolution network's first layer distilled into masks.
    """

    PCA = "pca"
    PLS = "pls"
    DISTILLED = "distilled"


class HeadOptions(TypedDict):
    """The builders' keywords a recipe sets (:meth:`TrainConfig.head_options`)."""

    count_loss: CountLoss | None
    seed: int
    head: HeadKind
    head_hidden: int
    head_bottleneck: int


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """Training recipe (the paper's, with the choices documented in the module).

    Args:
        max_steps: optimisation steps at most (early stopping ends most runs sooner:
            3,000-4,500 steps on the workspace episodes of the design protocol).
        batch_size: samples per step.
        lr: head learning rate; None = :func:`learning_rate_for` the input count.
        mask_lr: Adam learning rate of the mask logits (logit units per step).
        eval_every: steps between validation evaluations (and checkpoints).
        patience: evaluations without improvement before the learning rate decays
            (or, after ``lr_decays`` decays, before stopping).
        lr_decays: plateaus answered by multiplying every learning rate by
            ``lr_decay`` and going on (0: the first plateau stops the run). With a
            constant rate Adam's steps keep the parameters jittering about the
            optimum, so the validation loss stalls above what a smaller rate reaches.
        lr_decay: factor applied to every learning rate at each decay, in (0, 1).
        gain_range: random global gain per sample (augmentation), (lo, hi); (1, 1),
            the default, turns it off (the design protocol's recipe table:
            :data:`GAIN_AUGMENTATION_20` was not lower on validation episodes).
        max_eval_samples: validation samples used per evaluation (evenly spaced).
        count_loss: how COUNT labels are learned; None = the paper's choice for the
            data's scene family (:data:`PAPER_COUNT_LOSS`). Used where this module
            builds the models (:func:`sweep`, :func:`train_run`).
        head: the inference network (:class:`HeadKind`); the paper's is ``MLP``.
        head_hidden: units of each of the head's two hidden layers (the
            paper's :data:`HIDDEN_UNITS`; the design protocol's ``head-512``
            recipe tries a wider head).
        head_bottleneck: the head's hidden layers read this many learned,
            unconstrained linear combinations of the camera's pixels
            (:class:`~mincam_render.learn.models.Head`); 0, the paper's head:
            the pixels themselves. A diagnostic: a box camera so trained is that
            many linear measurements of its pixels with no printability limit
            (the design protocol's ``linear-8`` recipe).
        seed: seed of batches, noise and initialisation.
        torch_threads: intra-op threads while training (restored afterwards). The
            head is tiny, and torch's spinning worker threads next to Dr.Jit's pool
            oversubscribe a small machine: on 2 shared cores one thread measured
            7x faster per step than two.
        perturbation: robust training (domain randomisation): every batch is
            measured through a new built camera drawn from this model (mask
            shift, rotation, print tone, printable range, blur, gain mismatch, dark
            offset; :mod:`mincam_render.optics.perturbation`); None trains the
            design as drawn (nominal). A minimalist camera's option only.
        robust_validation_draws: with ``perturbation``, the validation loss (which
            decays the learning rate and stops the run) is the mean loss over this
            many built cameras, drawn once from ``seed`` (the same cameras at every
            evaluation and after a resume; the nominal camera is not among them);
            0 validates the camera as designed. Ignored without ``perturbation``.
        privacy_weight: weight ``w`` of the adversarial privacy term
            (:mod:`mincam_render.learn.privacy_term`): the masks minimise the task
            loss minus ``w`` times the loss of a decoder trained alongside to
            reconstruct the scene from the pixels; 0 trains for the task alone.
            A static minimalist camera's option only.
        mask_tv_weight: weight of the masks' total variation per texel
            (:func:`~mincam_render.optics.maskplane.total_variation_per_texel`,
            transmittance units) added to the loss; 0: no smoothness prior.
        mask_logit_decay: weight of the mean squared mask logit added to the loss
            (weight decay on the logits: pulls texels away from the printable
            limits); 0: none.
        mask_block: the masks are parameterised in blocks of ``mask_block`` x
            ``mask_block`` texels (a coarser mask, printed at the full texel grid);
            1: every texel free. Must divide the mask resolution.
        transport_noise: relative standard deviation of Gaussian noise multiplying
            every texel of every training sample's transport, ``T (1 + s e)``
            (like render noise, new at every step; both camera kinds); 0: none.
        signed_pixels: every freeform pixel is signed: a pair of photodiodes
            behind two masks, the first's reading minus the second's
            (:class:`~mincam_render.learn.models.MincamCamera`), so a design of
            ``K`` pixels has ``2 K`` photodiodes and ``K`` outputs. A minimalist
            camera's option (the design protocol's ``signed`` diagnostic).

    """

    max_steps: int = 10000
    batch_size: int = 64
    lr: float | None = None
    mask_lr: float = 0.05
    eval_every: int = 100
    patience: int = 8
    lr_decays: int = 2
    lr_decay: float = 0.2
    gain_range: tuple[float, float] = (1.0, 1.0)
    max_eval_samples: int = 2048
    count_loss: CountLoss | None = None
    head: HeadKind = HeadKind.MLP
    head_hidden: int = HIDDEN_UNITS
    head_bottleneck: int = 0
    seed: int = 0
    torch_threads: int | None = 1
    perturbation: PerturbationModel | None = None
    robust_validation_draws: int = 8
    privacy_weight: float = 0.0
    mask_tv_weight: float = 0.0
    mask_logit_decay: float = 0.0
    mask_block: int = 1
    transport_noise: float = 0.0
    signed_pixels: bool = False

    def __post_init__(self) -> None:
        for name, lo in (
            ("max_steps", 1),
            ("batch_size", 2),
            ("eval_every", 1),
            ("patience", 1),
            ("lr_decays", 0),
            ("max_eval_samples", 2),
            ("robust_validation_draws", 0),
            ("mask_block", 1),
        ):
            check_int(f"TrainConfig.{name}", getattr(self, name), lo)
        check_int("TrainConfig.head_hidden", self.head_hidden, 1, 4096)
        check_int("TrainConfig.head_bottleneck", self.head_bottleneck, 0, 4096)
        for name in ("lr_decay", "lr"):  # lr None: learning_rate_for the input count
            if getattr(self, name) is not None:
                check_number(
                    f"TrainConfig.{name}",
                    getattr(self, name),
                    0,
                    1,
                    lo_open=True,
                    hi_open=True,
                    numpy=True,
                )
        check_number("TrainConfig.mask_lr", self.mask_lr, 0, 10, hi_open=True, numpy=True)
        if self.count_loss is not None and not isinstance(self.count_loss, CountLoss):
            allowed = [c.value for c in CountLoss]
            try:
                object.__setattr__(self, "count_loss", CountLoss(self.count_loss))
            except ValueError:
                raise ValueError(
                    f"TrainConfig.count_loss = {self.count_loss!r}: allowed {allowed} or None"
                ) from None
        if not isinstance(self.head, HeadKind):
            try:
                object.__setattr__(self, "head", HeadKind(self.head))
            except ValueError:
                raise ValueError(
                    f"TrainConfig.head = {self.head!r}: allowed {[h.value for h in HeadKind]}"
                ) from None
        if self.perturbation is not None and not isinstance(self.perturbation, PerturbationModel):
            raise ValueError(
                f"TrainConfig.perturbation = {self.perturbation!r}: allowed a PerturbationModel "
                "or None"
            )
        check_number("TrainConfig.privacy_weight", self.privacy_weight, 0, 1e3)
        for name in ("mask_tv_weight", "mask_logit_decay"):
            check_number(f"TrainConfig.{name}", getattr(self, name), 0, 1e3, numpy=True)
        check_number("TrainConfig.transport_noise", self.transport_noise, 0, 1, numpy=True)
        if not isinstance(self.signed_pixels, bool):
            raise ValueError(f"TrainConfig.signed_pixels = {self.signed_pixels!r}: true or false")
        g0, g1 = self.gain_range
        if not 0 < g0 <= g1:
            raise ValueError(f"TrainConfig.gain_range = {self.gain_range!r}: need 0 < lo <= hi")

    def head_options(self) -> HeadOptions:
        """The keywords of ``learn.builders.build_mincam`` and ``build_baseline`` it sets.

        How counts are learned, the seed, and the head's kind, width and
        bottleneck (the recipe's).
        """
        return {
            "count_loss": self.count_loss,
            "seed": self.seed,
            "head": self.head,
            "head_hidden": self.head_hidden,
            "head_bottleneck": self.head_bottleneck,
        }
