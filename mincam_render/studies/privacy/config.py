"""What a privacy audit renders, trains and attacks, as data (no torch or Mitsuba import)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from mincam_render.core.checks import check_int, check_number
from mincam_render.learn.train_config import GAIN_AUGMENTATION_20, TrainConfig
from mincam_render.studies.comparison.config import ComparisonConfig, Design, Protocol

#: The workspace with a roster of six people (max six present, so each has a look).
ROSTER_OVERRIDES = {"max_people": 6, "people": {"roster": 6}}
#: A cheap, fixed render (no fidelity planning): direct light and one bounce,
#: 4 samples per texel. Every design sees the same noisy transport, so the
#: comparison between designs stays fair; absolute task errors are not the
#: shipped studies'.
AUDIT_FIDELITY = {
    "spp": 4,
    "max_depth": 3,
    "shared_render": False,
    "dtype": "float16",
    "differential": False,
}


class DecoderKind(enum.StrEnum):
    """A decoder of the people (:mod:`.decoders`); the values are ``privacy.json``'s keys."""

    MLP = "mlp"
    CONV = "conv"
    RIDGE = "ridge"


#: The decoders an attacker trains, in ``privacy.json``'s order.
DECODERS = tuple(DecoderKind)

#: Weight of the privacy term of the audit's privacy-trained design (8 px).
AUDIT_PRIVACY_WEIGHT = 1.0
#: Detectors an audit may render (:func:`default_comparison`): the default, and the large one.
AUDIT_DETECTORS = (8, 16)
#: Mask texels per side an audit may render: the default, and the large one.
AUDIT_TEXELS = (32, 64)


def default_designs(detectors: int = 8, texels: int = 32) -> tuple[Design, ...]:
    """The audit's designs for a render of ``detectors`` at ``texels`` texels per side.

    Minimalist cameras of 1, 2, 4, ... ``detectors`` px, 8 px (or the largest, if
    fewer) also with the privacy term, and baselines 2x2, 4x4, ... ``texels`` x
    ``texels``.

    The default render (8 detectors at 32 x 32 texels) gives mincam 1-8 px and
    baselines up to 32 x 32; 16 detectors at 64 texels add 16 px and 64 x 64.
    """
    pixels = [2**i for i in range(detectors.bit_length()) if 2**i <= detectors]
    grids = [2**i for i in range(1, texels.bit_length()) if 2**i <= texels]
    return (
        *(Design(pixels=k) for k in pixels),
        Design(pixels=min(8, pixels[-1]), privacy_weight=AUDIT_PRIVACY_WEIGHT),
        *(Design(grid=(g, g)) for g in grids),
    )


def default_comparison(detectors: int = 8, texels: int = 32) -> ComparisonConfig:
    """The audit's episodes and task training: the workspace at 1 fps with a roster.

    Sized for a shared 2-core machine: 2 task seeds of at most 1,000 steps per
    design (the attacks have 3 seeds each).

    1 fps spreads 300 frames over 5 minutes of office activity (a few visits
    of each person per episode); the task is the workspace's (people count RMSE).
    ``detectors`` and ``texels`` (mask texels per side) size the render and so
    the designs (:func:`default_designs`); at 16 and 64 the render costs about
    8 times the default's.

    Raises:
        ValueError: ``detectors`` not one of :data:`AUDIT_DETECTORS`, or
            ``texels`` not one of :data:`AUDIT_TEXELS`.
    """
    for name, value, allowed in (
        ("detectors", detectors, AUDIT_DETECTORS),
        ("texels", texels, AUDIT_TEXELS),
    ):
        if value not in allowed:
            raise ValueError(f"{name} = {value!r}: allowed {', '.join(map(str, allowed))}")
    overrides = dict(ROSTER_OVERRIDES)
    if detectors != 8:
        overrides["camera"] = {"detectors": detectors}
    return ComparisonConfig(
        family="workspace",
        seed=0,
        fps=1.0,
        overrides=overrides,
        train_episodes=3,
        train_frames=300,
        val_frames=200,
        test_frames=200,
        test_episodes=3,
        seeds=2,
        designs=default_designs(detectors, texels),
        train=TrainConfig(max_steps=1000, gain_range=GAIN_AUGMENTATION_20),
        fidelity=AUDIT_FIDELITY,
        mask_res=None if texels == 32 else texels,
        # as audited (privacy.json, privacy_16det.json): one camera for every label,
        # early stopping on one validation episode, the +-20 % gain augmentation
        protocol=Protocol.JOINT,
        val_episodes=1,
    )


@dataclass(frozen=True, kw_only=True)
class AttackConfig:
    """How the attacker learns (the same for every design).

    Args:
        view_width: pixels per side of the full view the decoder reconstructs.
        view_spp: samples per pixel of the full views.
        seeds: attacker seeds (>= 3 for an interval).
        max_steps: Adam steps of each attacker at most.
        batch_size: samples per step.
        hidden: units of each hidden layer (the MLPs' two, the conv decoder's one).
        conv_channels: feature maps of the conv decoder's coarsest grid (halved
            at each doubling, at least 8).
        lr: Adam learning rate.
        eval_every: steps between validation checks (the best state is kept).
        examples: test frames shown in the report's reconstructions.
    """

    view_width: int = 64
    view_spp: int = 4
    seeds: int = 3
    max_steps: int = 600
    batch_size: int = 64
    hidden: int = 256
    conv_channels: int = 32
    lr: float = 1e-3
    eval_every: int = 100
    examples: int = 4

    def __post_init__(self) -> None:
        for name, lo in (
            ("view_width", 8),
            ("view_spp", 1),
            ("seeds", 1),
            ("max_steps", 1),
            ("batch_size", 2),
            ("hidden", 1),
            ("conv_channels", 1),
            ("eval_every", 1),
            ("examples", 0),
        ):
            check_int(f"AttackConfig.{name}", getattr(self, name), lo)
        check_number("AttackConfig.lr", self.lr, 0, 1, lo_open=True, hi_open=True, numpy=True)


@dataclass(frozen=True, kw_only=True)
class PrivacyConfig:
    """A privacy audit: the comparison's episodes and designs, and the attacker.

    Args:
        comparison: episodes, designs (a privacy-trained design is one with
            ``Design.privacy_weight``) and task training (:func:`default_comparison`).
        attack: the attacker (:class:`AttackConfig`).
    """

    comparison: ComparisonConfig = field(default_factory=default_comparison)
    attack: AttackConfig = field(default_factory=AttackConfig)

    @classmethod
    def sized(
        cls,
        *,
        train_frames: int,
        task_seeds: int,
        detectors: int = AUDIT_DETECTORS[0],
        texels: int = AUDIT_TEXELS[0],
        attack: AttackConfig | None = None,
    ) -> PrivacyConfig:
        """The default audit with ``train_frames`` per training episode and ``task_seeds``.

        Validation and test episodes are 2/3 of a training episode (rounded up).

        Raises:
            ValueError: sizes outside :func:`default_comparison`'s or
                :class:`ComparisonConfig`'s ranges.
        """
        import dataclasses

        other = -(-2 * train_frames // 3)
        comparison = dataclasses.replace(
            default_comparison(detectors, texels),
            train_frames=train_frames,
            val_frames=other,
            test_frames=other,
            seeds=task_seeds,
        )
        return cls(comparison=comparison, attack=attack or AttackConfig())
