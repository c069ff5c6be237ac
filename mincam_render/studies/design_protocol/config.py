"""What the design-protocol study runs, as data (no PyTorch or Mitsuba import)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

from mincam_render.core.checks import check_int, check_number
from mincam_render.learn.train_config import MaskReference, TrainConfig
from mincam_render.studies.comparison.config import ComparisonConfig, Design

#: The learning curves' designs: the paper's 2-pixel camera, 8 freeform pixels,
#: and the box cameras they are measured against.
LADDER_DESIGNS = (
    Design(pixels=2),
    Design(pixels=8),
    Design(grid=(2, 2)),
    Design(grid=(8, 8)),
    Design(grid=(32, 32)),
)


@dataclass(frozen=True, kw_only=True)
class Floor:
    """A figure a design must reach against a baseline (the issue's "done when").

    Met when ``design - baseline < margin`` on the same test episodes: the
    paired 95 % interval lies below ``margin`` (in the task's error units: RMSE,
    or error rate = 1 - accuracy).

    Args:
        design: the minimalist design (``mincam-2px``).
        baseline: the box camera it is held against (``baseline-8x8``).
        margin: how much higher the design's error may be (0: strictly lower;
            0.02: "within 2 points" of an error rate).
    """

    design: str
    baseline: str
    margin: float = 0.0

    def __post_init__(self) -> None:
        if not self.design or not self.baseline or self.design == self.baseline:
            raise ValueError(f"floor {self.design!r} against {self.baseline!r}: two designs")
        if not 0.0 <= self.margin < 1.0:
            raise ValueError(f"floor margin {self.margin}: must be in [0, 1) error units")


@dataclass(frozen=True, kw_only=True)
class RecipeVariant:
    """One recipe tried on the validation episodes: changes to the base recipe.

    Args:
        name: short name in tables (``gain-20``).
        changes: :class:`~mincam_render.learn.train_config.TrainConfig` fields
            replaced (JSON-ready values; tuples as lists are accepted).
        minimalist_only: the change acts on masks only (priors, block masks):
            tried on the minimalist designs alone.
        baselines_only: the change is for the box cameras (a linear
            bottleneck): tried on the baselines alone.
        diagnostic: a question asked of the designs, not a recipe: never
            chosen (it changes what a design is: its measurements' kind, its
            photodiodes).
    """

    name: str
    changes: Mapping[str, Any] = field(default_factory=dict)
    minimalist_only: bool = False
    baselines_only: bool = False
    diagnostic: bool = False

    def __post_init__(self) -> None:
        known = {f.name for f in fields(TrainConfig)}
        unknown = sorted(set(self.changes) - known)
        if unknown or not self.name:
            raise ValueError(f"recipe {self.name!r}: unknown TrainConfig fields {unknown}")
        if self.minimalist_only and self.baselines_only:
            raise ValueError(f"recipe {self.name!r}: minimalist_only or baselines_only, not both")
        self.apply(TrainConfig())  # validated now, not after hours of training

    def apply(self, base: TrainConfig) -> TrainConfig:
        """``base`` with this variant's changes (lists as tuples)."""
        from dataclasses import replace

        return replace(base, **{k: _field_value(v) for k, v in self.changes.items()})


def _field_value(value: Any) -> Any:
    """A recipe change as its field holds it (a TOML or JSON list as a tuple)."""
    return tuple(value) if isinstance(value, list) else value


def default_recipes() -> tuple[RecipeVariant, ...]:
    """The variants of the issue's step 3: gain augmentation, priors, a wider head, a budget.

    ``head-512`` (four times the paper's hidden width) was added after the
    learning curves flattened for the freeform cameras (the 8-pixel floor's
    limit, ``docs/design_protocol.md``): whether the head, not what the pixels
    read, stops them. ``steps-30k`` (three times the base's step budget; the
    issue's "longer training") was added after the patches box cameras ended
    budget-limited at 10,000 steps: whether the floors' baselines were cut short.
    ``linear-2`` and ``linear-8`` (the box cameras read through 2 or 8 learned
    signed linear combinations of their pixels, ``TrainConfig.head_bottleneck``)
    were added after the patches' 8-pixel floor was missed with the optimiser,
    head and budget ruled out: whether any 2 or 8 linear measurements of the
    view, printable or not, hold what the box pixels hold; ``linear-16`` after
    they did not, beside 16 freeform pixels. ``signed`` (every freeform pixel a
    pair of masks and photodiodes read as one difference,
    ``TrainConfig.signed_pixels``: twice the photodiodes) after 2 signed
    combinations of 32x32's pixels beat 2 and 4 printable masks on the narrow
    patches: whether the sign is what the masks lack. Diagnostics, not recipes:
    they are never chosen (``diagnostic``).
    """
    return (
        RecipeVariant(name="base"),
        RecipeVariant(name="gain-5", changes={"gain_range": (0.95, 1.05)}),
        RecipeVariant(name="gain-20", changes={"gain_range": (0.8, 1.2)}),
        RecipeVariant(name="tv-0.03", changes={"mask_tv_weight": 0.03}, minimalist_only=True),
        RecipeVariant(name="tv-0.3", changes={"mask_tv_weight": 0.3}, minimalist_only=True),
        RecipeVariant(name="block-4", changes={"mask_block": 4}, minimalist_only=True),
        RecipeVariant(name="block-8", changes={"mask_block": 8}, minimalist_only=True),
        RecipeVariant(name="noise-0.03", changes={"transport_noise": 0.03}),
        RecipeVariant(name="noise-0.1", changes={"transport_noise": 0.1}),
        RecipeVariant(name="decay-0.01", changes={"mask_logit_decay": 0.01}, minimalist_only=True),
        RecipeVariant(name="head-512", changes={"head_hidden": 512}),
        RecipeVariant(name="steps-30k", changes={"max_steps": 30000}),
        *(
            RecipeVariant(
                name=f"linear-{k}",
                changes={"head_bottleneck": k},
                baselines_only=True,
                diagnostic=True,
            )
            for k in (2, 8, 16)
        ),
        RecipeVariant(
            name="signed",
            changes={"signed_pixels": True},
            minimalist_only=True,
            diagnostic=True,
        ),
    )


def recipes_named(names: Sequence[str]) -> tuple[RecipeVariant, ...]:
    """The base recipe and the variants of :func:`default_recipes` called ``names``, in order.

    Raises:
        ValueError: a name that is not a default variant's, or one given twice.
    """
    known = {r.name: r for r in default_recipes()}
    unknown = [n for n in names if n not in known]
    if unknown or len(set(names)) != len(names):
        raise ValueError(f"recipes {list(names)}: give each of {sorted(known)} at most once")
    base = default_recipes()[0]
    return (base, *(known[n] for n in names if n != base.name))


@dataclass(frozen=True, kw_only=True)
class DesignProtocolConfig:
    """The design protocol's sections (``docs/design_protocol.md``).

    Args:
        episodes: the shared episodes and base recipe: family, frame rate,
            frames per episode, validation and test episodes, training seeds,
            ``train`` (the base recipe) and fidelity. Its ``train_episodes`` and
            ``designs`` are replaced per section.
        task: the task of the learning curves, recipes and references (one of
            the family's :func:`~mincam_render.core.labels.label_tasks`).
        ladder: training-episode counts of the learning curves.
        ladder_designs: the designs of the learning curves.
        recipe_episodes: training episodes the recipes are compared on.
        recipes: the variants (the first is the base, the others are compared with it).
        reference_episodes: training episodes the references are compared on.
        reference_pixels: pixel counts at which end-to-end masks meet the references.
        references: the reference masks (each also tuned end to end from it).
        reference_recipe: the recipe every design of the references section
            trains with (one of :func:`default_recipes`, e.g. the one the
            recipes section chose for the task's freeform pixels); None: the
            base. The reference masks themselves are fitted at full resolution
            whatever the recipe (a block recipe moves only the tuned ones, in
            blocks).
        protocol_episodes: training episodes of the per-task against joint table.
        protocol_pixels: per-task pixel budgets of that table; each meets a joint
            camera of the same pixels and one of the per-task cameras' total.
        restarts: runs per kept camera in the restarts section (the best on
            validation is kept).
        floors: what the learning curves' largest training set is held to
            (both designs among ``ladder_designs``).
        floor_test_factors: the floors are also read on the test episodes
            rendered again at each of these multiples of the plan's samples, at
            full path depth (the task-fidelity check's level of that factor), by
            the same runs: with factors above the episodes' own
            (:attr:`episodes_factor`), the figures with less render noise in the
            test data, nearer what a deployed camera reads. Empty: on the
            episodes' own tests alone.
    """

    episodes: ComparisonConfig = field(
        default_factory=lambda: ComparisonConfig(val_episodes=4, test_episodes=6)
    )
    task: str = "people_count"
    ladder: tuple[int, ...] = (1, 2, 4, 8, 16, 32)
    ladder_designs: tuple[Design, ...] = LADDER_DESIGNS
    recipe_episodes: int = 8
    recipes: tuple[RecipeVariant, ...] = field(default_factory=default_recipes)
    reference_episodes: int = 8
    reference_pixels: tuple[int, ...] = (2, 8)
    references: tuple[MaskReference, ...] = tuple(MaskReference)
    reference_recipe: RecipeVariant | None = None
    protocol_episodes: int = 8
    protocol_pixels: tuple[int, ...] = (2,)
    restarts: int = 3
    floors: tuple[Floor, ...] = ()
    floor_test_factors: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        self._check_floor_test_factors()
        if not self.ladder or list(self.ladder) != sorted(set(self.ladder)):
            raise ValueError(f"ladder {self.ladder}: need increasing episode counts")
        for n in (*self.ladder, self.recipe_episodes, self.reference_episodes,
                  self.protocol_episodes):  # fmt: skip
            check_int("training episodes", n, 1, 1000)
        for k in (*self.reference_pixels, *self.protocol_pixels):
            check_int("pixels", k, 1)
        check_int("restarts", self.restarts, 2)
        if not self.recipes or self.recipes[0].changes:
            raise ValueError("recipes: the first variant is the base recipe (no changes)")
        names = [r.name for r in self.recipes]
        if len(set(names)) != len(names):
            raise ValueError(f"recipes {names}: give each name once")
        object.__setattr__(self, "references", tuple(MaskReference(r) for r in self.references))
        if self.reference_recipe is not None and self.reference_recipe.diagnostic:
            raise ValueError(
                f"reference_recipe {self.reference_recipe.name!r}: a diagnostic, not a recipe"
            )
        ladder_names = {d.name for d in self.ladder_designs}
        for f in self.floors:
            if not {f.design, f.baseline} <= ladder_names:
                raise ValueError(
                    f"floor {f.design} against {f.baseline}: both must be ladder designs "
                    f"({sorted(ladder_names)})"
                )

    @property
    def episodes_factor(self) -> float:
        """The multiple of the plan's samples the episodes render at (their ``samples_factor``)."""
        return float(self.episodes.fidelity.get("samples_factor") or 1.0)

    def _check_floor_test_factors(self) -> None:
        """Positive, distinct (as their renders' ``Fx``), not the episodes' own, with floors."""
        factors = self.floor_test_factors
        if isinstance(factors, str) or not isinstance(factors, tuple | list):
            raise ValueError(f"floor_test_factors {factors!r}: need a sequence, e.g. (4, 16)")
        for factor in factors:
            check_number("floor_test_factors", factor, 0, 1e4, lo_open=True)
        object.__setattr__(self, "floor_test_factors", tuple(float(f) for f in factors))
        names = [f"{f:g}x" for f in factors]
        if factors and not self.floors:
            raise ValueError(f"floor_test_factors {factors}: give floors to read on those tests")
        own = f"{self.episodes_factor:g}x"
        if own in names:
            raise ValueError(
                f"floor_test_factors {factors}: a factor other than the episodes' own "
                f"({own}: their tests are read anyway)"
            )
        if len(set(names)) < len(names):
            raise ValueError(f"floor_test_factors {factors}: distinct factors ({names})")

    def comparison(
        self, train_episodes: int, designs: tuple[Design, ...], **changes: Any
    ) -> ComparisonConfig:
        """The shared episodes with ``train_episodes``, ``designs`` and other ``changes``.

        Per task, only :attr:`task`, unless ``changes`` give the protocol.
        """
        from dataclasses import replace

        changes.setdefault("tasks", self.episodes.tasks if "protocol" in changes else (self.task,))
        return replace(self.episodes, train_episodes=train_episodes, designs=designs, **changes)
