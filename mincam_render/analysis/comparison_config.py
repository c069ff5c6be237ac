"""What the main job compares: camera designs and the comparison's configuration, as data.

No PyTorch or Mitsuba import, so the command line shows these defaults at once.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from mincam_render.core.checks import check_int, check_number
from mincam_render.learn.train_config import HeadKind, TrainConfig


@dataclass(frozen=True)
class Design:
    """One camera design: a minimalist camera of ``pixels`` or a baseline of ``grid``.

    Args:
        pixels: freeform pixels (minimalist camera), or None for a baseline.
        grid: ``(rows, cols)`` of a conventional camera, or None.
        sensor_model: train the minimalist camera with the detector model (noise,
            saturation); False is the paper's supplement-A ablation: masks trained
            without the model, then frozen while a fresh head is trained with it,
            and tested with it.
        head: the inference network (replaces the recipe's ``TrainConfig.head``).
        privacy_weight: masks trained with the adversarial privacy term of this
            weight (replaces the recipe's ``TrainConfig.privacy_weight``); 0: the
            task alone. A minimalist camera's option only.
    """

    pixels: int | None = None
    grid: tuple[int, int] | None = None
    sensor_model: bool = True
    head: HeadKind = HeadKind.MLP
    privacy_weight: float = 0.0

    def __post_init__(self) -> None:
        if (self.pixels is None) == (self.grid is None):
            raise ValueError(f"{self}: give exactly one of pixels (mincam) or grid (baseline)")
        if self.pixels is not None:
            check_int("Design.pixels", self.pixels, 1)
        if self.grid is not None:
            object.__setattr__(self, "grid", (int(self.grid[0]), int(self.grid[1])))
        object.__setattr__(self, "head", HeadKind(self.head))
        check_number("Design.privacy_weight", self.privacy_weight, 0, 1e3, numpy=True)
        if self.privacy_weight and self.grid is not None:
            raise ValueError(f"{self}: a privacy weight trains masks; a baseline has none")

    @property
    def name(self) -> str:
        """``mincam-8px``, ``mincam-8px-nosensor``, ``baseline-8x8``; ``-tcn`` for that head.

        A privacy weight of 1 adds ``-private1`` (before the head's suffix).
        """
        suffix = "" if self.head is HeadKind.MLP else f"-{self.head.value}"
        if self.grid is not None:
            return f"baseline-{self.grid[0]}x{self.grid[1]}{suffix}"
        private = f"-private{self.privacy_weight:g}" if self.privacy_weight else ""
        sensor = "" if self.sensor_model else "-nosensor"
        return f"mincam-{self.pixels}px{sensor}{private}{suffix}"

    @property
    def is_mincam(self) -> bool:
        """A minimalist camera (it has masks to keep)."""
        return self.pixels is not None

    def train_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`mincam_render.learn.train.train_run`."""
        if self.grid is not None:
            return {"baseline_grid": self.grid}
        return {"pixels": self.pixels, "sensor_model": self.sensor_model}


@dataclass(frozen=True, kw_only=True)
class ComparisonConfig:
    """What the main job renders and trains.

    Args:
        family: scene family name or description (.toml).
        seed: root seed of every episode and training seed.
        fps: frame rate of the episodes (1/s); 2 fps: 1,200 frames = 10 min of activity.
        overrides: values replacing the scene description's in every episode (nested
            as in the TOML, e.g. ``{"camera": {"detectors": 16}}``; ``fps`` is its own
            field).
        light_scale: every emitter's radiance times this factor (> 0), applied to
            the rendered episodes (transport is linear in it), so light levels
            share one render.
        train_episodes: training episodes (static tasks; a temporal task trains on one).
        train_frames: frames of each training episode.
        val_frames: frames of the validation episode.
        test_frames: frames of each test episode.
        test_episodes: number of test episodes (>= 2 for an interval over episodes).
        seeds: training seeds per design (>= 2 for an interval over seeds).
        designs: the camera designs; with two, the verdict compares them.
        train: the training recipe (its ``seed`` is replaced per training seed, its
            ``head`` by each design's).
        fidelity: :class:`RenderRequest` fidelity fields (``{}`` = measured, auto).
        mask_res: mask texels per side rendered (None: the family camera's); a
            baseline grid can be at most this fine (64 x 64 needs 64).
    """

    family: str = "workspace"
    seed: int = 0
    fps: float = 2.0
    overrides: Mapping[str, Any] = field(default_factory=dict)
    light_scale: float = 1.0
    train_episodes: int = 2
    train_frames: int = 1200
    val_frames: int = 600
    test_frames: int = 600
    test_episodes: int = 3
    seeds: int = 3
    designs: tuple[Design, ...] = (Design(pixels=8), Design(grid=(8, 8)))
    train: TrainConfig = TrainConfig()
    fidelity: Mapping[str, Any] = field(default_factory=dict)
    mask_res: int | None = None

    def __post_init__(self) -> None:
        for name in ("train_frames", "val_frames", "test_frames"):
            check_int(name, getattr(self, name), 30, unit="frames")
        for name in ("train_episodes", "test_episodes", "seeds"):
            check_int(name, getattr(self, name), 1)
        check_number("light_scale", self.light_scale, 0, lo_open=True, numpy=True)
        if "fps" in self.overrides:
            raise ValueError("overrides: give the frame rate as fps, not as an override")
        self._check_grids()
        names = [d.name for d in self.designs]
        if len(names) < 2 or len(set(names)) != len(names):
            raise ValueError(f"designs {names}: need at least two, each once")

    def _check_grids(self) -> None:
        """Refuse, before any render, a baseline grid finer than the rendered ``mask_res``."""
        if self.mask_res is None:
            return
        check_int("mask_res", self.mask_res, 1, 4096)
        for d in self.designs:
            if d.grid is not None and max(d.grid) > self.mask_res:
                raise ValueError(
                    f"{d.name}: a {d.grid[0]}x{d.grid[1]} baseline needs at least "
                    f"{max(d.grid)} texels per side; mask_res = {self.mask_res}"
                )
