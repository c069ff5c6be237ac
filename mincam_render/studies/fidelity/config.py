"""What the fidelity benchmark measures: its families and sizes, and its fixed settings."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

from mincam_render.core.checks import check_int
from mincam_render.core.strict_json import JsonObject

#: Path depth of the converged reference (as the fidelity decisions' deep reference).
REFERENCE_DEPTH = 16
#: Side of the "point" detector (m); its transport is rescaled by the area ratio.
POINT_DETECTOR_SIZE_M = 1e-6
#: Knobs in the order rows are produced.
KNOBS = ("spp", "mask_res", "max_depth", "render", "detector", "storage", "paper", "auto")
#: Background window (s) of the label signal of differential families (a render
#: request's default).
SIGNAL_INTERVAL_S = 60.0
#: An effect whose estimated systematic error stays below this can be left out.
NEGLIGIBLE_EFFECT = 0.01


@dataclasses.dataclass(frozen=True, kw_only=True)
class FidelityBenchConfig:
    """One fidelity benchmark: its families and sizes (defaults: a few minutes a family).

    Args:
        families: shipped family names or scene TOML paths, at least one.
        num_frames: frames rendered per setting, spread over the sequence, >= 1.
        sequence_frames: length of the family's sequence the frames are taken from.
        reference_spp: samples per texel of the reference (split in two halves).
        base_spp: samples per texel of the base setting the other knobs start from.
        spp_levels: levels of the ``spp`` knob.
        mask_res_levels: coarser mask resolutions (texels per side) to try; levels
            that do not divide the camera's resolution are skipped.
        depth_levels: path depths to try (the scene's own depth is added).
        num_masks: masks of each kind per detector.
        repeats: timed runs per setting (median reported).
        mask_resolution: override of the camera's mask resolution, or None.
        include_auto: run the automatic fidelity decision and bench its choice.
        seed: family seed (trajectories) and render seeds.
        signal_seconds: scene time (s) the label signal's frames are spread over
            (at the family's frame rate): the bench's short sequence holds too few
            changes of the labels' state to show their spread. None measures no
            error relative to the label signal (as results written before it was).
    """

    families: tuple[str, ...]
    num_frames: int = 2
    sequence_frames: int = 60
    reference_spp: int = 256
    base_spp: int = 16
    spp_levels: tuple[int, ...] = (1, 4, 16, 64)
    mask_res_levels: tuple[int, ...] = (16, 8)
    depth_levels: tuple[int, ...] = (1, 2, 5)
    num_masks: int = 8
    repeats: int = 1
    mask_resolution: int | None = None
    include_auto: bool = True
    seed: int = 0
    signal_seconds: float | None = 600.0

    def __post_init__(self) -> None:
        def bad(name: str, allowed: str) -> ValueError:
            return ValueError(
                f"FidelityBenchConfig.{name} = {getattr(self, name)!r} is invalid: "
                f"allowed {allowed}"
            )

        families = tuple(self.families)
        if not families or not all(isinstance(f, str) and f for f in families):
            raise bad("families", "one or more family names or scene paths")
        object.__setattr__(self, "families", families)
        for name, lo, hi in (
            ("num_frames", 1, 1000),
            ("sequence_frames", 1, 10**6),
            ("reference_spp", 2, 1 << 20),
            ("base_spp", 1, 1 << 20),
            ("num_masks", 2, 1000),
            ("repeats", 1, 100),
        ):
            check_int(f"FidelityBenchConfig.{name}", getattr(self, name), lo, hi)
        if self.num_frames > self.sequence_frames:
            raise bad("num_frames", f"at most sequence_frames = {self.sequence_frames}")
        for name, hi in (("spp_levels", 1 << 20), ("mask_res_levels", 4096), ("depth_levels", 64)):
            v = tuple(getattr(self, name))
            if not all(isinstance(x, int) and 1 <= x <= hi for x in v):
                raise bad(name, f"integers in [1, {hi}]")
            object.__setattr__(self, name, v)
        if self.mask_resolution is not None and not 1 <= self.mask_resolution <= 4096:
            raise bad("mask_resolution", "None or an integer in [1, 4096]")
        if self.signal_seconds is not None and not 1e-3 <= self.signal_seconds <= 1e6:
            raise bad("signal_seconds", "None or a number of seconds in [1e-3, 1e6]")

    def sizes_json(self) -> JsonObject:
        """The ``config`` record of each family's result: every field but ``families``.

        ``signal_seconds`` is left out when None (results from before it existed).
        """
        record = {
            f.name: list(v) if isinstance(v := getattr(self, f.name), tuple) else v
            for f in dataclasses.fields(self)
            if f.name != "families"
        }
        if self.signal_seconds is None:
            del record["signal_seconds"]
        return record

    @classmethod
    def from_json(cls, record: Mapping[str, Any], families: Sequence[str]) -> FidelityBenchConfig:
        """The config of a result: its ``config`` record (:meth:`sizes_json`) and families."""
        sizes: JsonObject = {k: tuple(v) if isinstance(v, list) else v for k, v in record.items()}
        sizes.setdefault("signal_seconds", None)
        return cls(families=tuple(families), **sizes)
