"""What the task-level check of a fidelity plan runs, as data (no PyTorch or Mitsuba import)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from mincam_render.core.checks import check_int, check_number
from mincam_render.data.render_job.rescale import FULL_PATH_DEPTH
from mincam_render.learn.train_config import TrainConfig
from mincam_render.render.differential import DifferenceSeeds
from mincam_render.studies.comparison.config import ComparisonConfig, Design

#: The designs render noise is checked with: the paper's 2-pixel camera, 8 freeform
#: pixels, and box cameras down to single texels (32x32 at 32 texels per side:
#: the finest pixel, the one render noise hurts most).
CHECK_DESIGNS = (
    Design(pixels=2),
    Design(pixels=8),
    Design(grid=(8, 8)),
    Design(grid=(32, 32)),
)


@dataclass(frozen=True, kw_only=True)
class SampleLevel:
    """One fidelity of the check: the plan's episodes re-rendered with other samples.

    Args:
        name: its name in tables (``1x``, ``4x``, ``1x-frame-seeds``).
        factor: samples of frames and backgrounds relative to the plan's (> 0).
        episodes: the directory of its episode datasets (``train-0``, ``val-0``, ...).
        max_depth: path depth; None: the plan's.
        difference_seeds: which frames share the seed of ``X - C``.
        planned: the plan itself, rendered as a user renders it (auto fidelity):
            ``factor`` 1, the plan's depth and seeds.
    """

    name: str
    factor: float
    episodes: Path
    max_depth: int | None = FULL_PATH_DEPTH
    difference_seeds: DifferenceSeeds = DifferenceSeeds.WINDOW
    planned: bool = False

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("SampleLevel.name is empty: give every level a name")
        check_number("SampleLevel.factor", self.factor, 0, 1e4, lo_open=True)
        if self.max_depth is not None:
            check_int("SampleLevel.max_depth", self.max_depth, 1, 64)
        object.__setattr__(self, "episodes", Path(self.episodes))
        object.__setattr__(self, "difference_seeds", DifferenceSeeds(self.difference_seeds))
        if self.planned and (self.factor != 1 or self.max_depth is not None):
            raise ValueError(f"level {self.name!r}: the plan itself has factor 1 and its own depth")


@dataclass(frozen=True, kw_only=True)
class TaskFidelityConfig:
    """The task-level check of one family's plan (``docs/fidelity.md``).

    Every level trains and tests the same designs with the same seeds on the
    same episodes (scene seeds) rendered at its fidelity; a level is accepted
    against the reference when every design's test figure moves by less than
    ``acceptance_share`` of the half-width of its 95 % interval.

    Args:
        comparison: the episodes (counts, frames, frame rate), designs, seeds,
            recipe and task (``tasks``) every level trains and tests.
        levels: the fidelities, one of them the plan (``planned``).
        reference: the level the others are judged against (the most samples).
        second_reference: a level whose episodes give the label signal's second
            estimate (None: the reference's alone); when the reference is the
            plan (a reduced check), the level the plan's own noise is measured
            against.
        acceptance_share: share of a design's 95 % half-width its figure may move.
        replicate_seeds: training seeds of a replicate at every level (seeds
            after the comparison's): how far a figure moves when only the
            training seeds change, the floor the acceptance is read against.
        noise_episodes: episodes whose render noise is measured at every level.
        background_interval_s: the plan's background window (s): the noise's second lag.
        test_levels: levels of which only the test episodes are rendered (not
            trained): runs of other levels are tested on them (``cross``).
        cross: ``(trained, tested)`` level names: the runs trained at the first
            tested on the second's test episodes (same scene seeds), which
            separates what render noise does in training data from what it does
            in test data; ``tested`` is among ``levels`` or ``test_levels``.
    """

    comparison: ComparisonConfig = field(
        default_factory=lambda: ComparisonConfig(
            val_episodes=4,
            test_episodes=3,
            seeds=8,
            designs=CHECK_DESIGNS,
            tasks=("people_count",),
            train=TrainConfig(),  # the design protocol's recipe: no gain augmentation
        )
    )
    levels: tuple[SampleLevel, ...] = ()
    reference: str = "4x"
    second_reference: str | None = None
    acceptance_share: float = 0.25
    replicate_seeds: int = 8
    noise_episodes: tuple[str, ...] = ("test-0", "test-1", "test-2")
    background_interval_s: float = 60.0
    test_levels: tuple[SampleLevel, ...] = ()
    cross: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        names = [lv.name for lv in self.levels]
        every = names + [lv.name for lv in self.test_levels]
        if len(set(every)) != len(every):
            raise ValueError(f"levels and test levels {every}: give each name once")
        if any(lv.planned for lv in self.test_levels):
            raise ValueError("a test level cannot be the plan: the plan is trained")
        for trained, tested in self.cross:
            if trained not in names or tested not in every or trained == tested:
                raise ValueError(
                    f"cross ({trained!r}, {tested!r}): train at one of the levels {names} "
                    f"and test at another level or test level {every}"
                )
        for name in (self.reference, self.second_reference):
            if name is not None and name not in names:
                raise ValueError(f"level {name!r} is not among the levels {names}")
        if sum(lv.planned for lv in self.levels) != 1:
            raise ValueError(f"levels {names}: exactly one is the plan (planned=True)")
        check_number("acceptance_share", self.acceptance_share, 0, 1, lo_open=True)
        check_int("replicate_seeds", self.replicate_seeds, 0, 100)
        check_number("background_interval_s", self.background_interval_s, 0, 1e6, lo_open=True)

    def level(self, name: str) -> SampleLevel:
        """The level (or test level) called ``name``."""
        return next(lv for lv in (*self.levels, *self.test_levels) if lv.name == name)

    @property
    def plan(self) -> SampleLevel:
        """The level that renders the plan itself."""
        return next(lv for lv in self.levels if lv.planned)

    @property
    def trained(self) -> ComparisonConfig:
        """The comparison every level trains: its seeds, then the replicate's."""
        from dataclasses import replace

        return replace(self.comparison, seeds=self.comparison.seeds + self.replicate_seeds)

    @property
    def window_frames(self) -> int:
        """Frames of one background window at the episodes' frame rate."""
        return max(1, int(round(self.background_interval_s * self.comparison.fps)))
