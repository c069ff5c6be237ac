"""What the sim2real study compares, as data: a recording (or a SURROGATE to make), and how.

No numpy, torch or Mitsuba import: the command line reads the defaults at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mincam_render.core.checks import check_int


@dataclass(frozen=True, kw_only=True)
class Sim2RealConfig:
    """One sim2real comparison (:func:`~mincam_render.studies.sim2real.study.run`).

    Exactly one of ``recording`` and ``surrogate_family`` is given.

    Args:
        recording: a recording directory (``docs/sim2real_format.md``).
        surrogate_family: instead, a scene family whose SURROGATE-real recording
            is made first, into ``<out>/surrogate_input`` (a demo without a prototype).
        surrogate_frames: frames of that recording, in [20, 100000].
        spp: samples per texel of the simulation renders (and of the surrogate's),
            in [1, 2^20].
        steps: training steps of each task head, in [1, 10^6].
        seed: render and training seed (and the surrogate's), >= 0.
        tasks: also train and evaluate the task heads.
    """

    recording: Path | None = None
    surrogate_family: str | None = None
    surrogate_frames: int = 300
    spp: int = 4
    steps: int = 1500
    seed: int = 0
    tasks: bool = True

    def __post_init__(self) -> None:
        if (self.recording is None) == (self.surrogate_family is None):
            raise ValueError(
                f"Sim2RealConfig.recording = {self.recording!r}, "
                f"Sim2RealConfig.surrogate_family = {self.surrogate_family!r}: give one, "
                "a recording directory or a family to make a SURROGATE recording of"
            )
        if self.recording is not None:
            object.__setattr__(self, "recording", Path(self.recording))
        check_int("Sim2RealConfig.surrogate_frames", self.surrogate_frames, 20, 100000)
        check_int("Sim2RealConfig.spp", self.spp, 1, 1 << 20)
        check_int("Sim2RealConfig.steps", self.steps, 1, 10**6)
        check_int("Sim2RealConfig.seed", self.seed, 0)
        if not isinstance(self.tasks, bool):
            raise ValueError(f"Sim2RealConfig.tasks = {self.tasks!r}: allowed True or False")
