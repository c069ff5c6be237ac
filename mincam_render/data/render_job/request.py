"""What a render is asked to do: :class:`RenderRequest`, validated, with its identity."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass

from mincam_render.core.checks import check_int, check_number
from mincam_render.data import dataset as ds
from mincam_render.render import precision
from mincam_render.render.differential import DifferenceSeeds
from mincam_render.render.fidelity import Fidelity

#: Fields added after dataset format 4: left out of the identity while None.
_LATER_FIELDS = ("error_scale", "signal_target_error", "difference_seeds", "samples_factor")


@dataclass(frozen=True, kw_only=True)
class RenderRequest:
    """What to render; equal requests give byte-identical datasets.

    Args:
        family: a family name (``"patches"``) or a scene TOML path.
        num_frames: frames of the sequence, >= 1.
        seed: dataset seed (scene trajectories and frame render seeds), >= 0.
        overrides: nested dict replacing values of the scene description.
        shard_frames: frames per shard file, >= 1.
        splits: train/val/test fractions of the sequence (contiguous).
        fidelity: AUTO measures each choice below that is None; FULL takes the
            expensive option (per-detector, scene integrator, float32, 64 spp).
        spp: samples per texel, or None to decide.
        max_depth: path depth (2 = direct light), 0 = the scene's integrator, or
            None to decide.
        shared_render: one render for all detectors, or None to decide.
        mask_res: mask texels per side, or None for the family camera's.
        dtype: storage type (:class:`~mincam_render.render.precision.StorageDtype`
            or its value), or None to decide.
        target_error: target Monte Carlo measurement error relative to the total
            (the frame's or its mean, as the family says), when the plan is made
            in that scale.
        error_scale: what the plan's target is relative to
            (:class:`~mincam_render.render.precision.ErrorScale`: the frame's total,
            its mean over frames, or the label signal); None: the family's.
        signal_target_error: the target relative to the label signal, when the
            plan is made in that scale; None: the family's (chosen by the
            task-level check, ``benchmarks/bench_task_fidelity.py``).
        dtype_error_bound: largest relative measurement error float16 may add.
        indirect_fraction: drop indirect light when it changes measurements less.
        parallax_fraction: share one render when parallax is below this many texels.
        differential: render frames as a converged static background plus the
            change the movers make (:mod:`mincam_render.render.differential`), or None
            to decide (families with a static background only).
        background_interval_s: scene time (s) one background's daylight stands for.
        background_spp: samples per texel of the backgrounds, or None to decide.
        shared_difference: render the movers' change once from the board centre
            for all detectors, or None to decide (differential rendering).
        difference_seeds: which frames share the seed of the movers' change
            (:class:`~mincam_render.render.differential.DifferenceSeeds`), or None:
            the planner's default.
        samples_factor: render the plan of this request without it at this many
            times its samples of frames and backgrounds, at full path depth (the
            task-fidelity check's level of that factor, the same datasets:
            :func:`~mincam_render.data.render_job.rescale.resolved_request`); None: the plan.
    """

    family: str
    num_frames: int
    seed: int = 0
    overrides: dict | None = None
    shard_frames: int = 256
    splits: tuple[float, float, float] = (0.7, 0.15, 0.15)
    fidelity: Fidelity = Fidelity.AUTO
    spp: int | None = None
    max_depth: int | None = None
    shared_render: bool | None = None
    mask_res: int | None = None
    dtype: precision.StorageDtype | None = None
    target_error: float = 0.01
    error_scale: precision.ErrorScale | None = None
    signal_target_error: float | None = None
    dtype_error_bound: float = 1e-3
    indirect_fraction: float = 0.005
    parallax_fraction: float = 0.25
    differential: bool | None = None
    background_interval_s: float = 60.0
    background_spp: int | None = None
    shared_difference: bool | None = None
    difference_seeds: DifferenceSeeds | None = None
    samples_factor: float | None = None

    def __post_init__(self) -> None:
        def bad(name: str, allowed: str) -> ValueError:
            return ValueError(
                f"RenderRequest.{name} = {getattr(self, name)!r} is invalid: allowed {allowed}"
            )

        check_int("RenderRequest.num_frames", self.num_frames, 1)
        check_int("RenderRequest.seed", self.seed, 0, 2**63, hi_open=True)
        check_int("RenderRequest.shard_frames", self.shard_frames, 1, 1 << 20)
        ds.split_ranges(self.num_frames, self.splits)
        object.__setattr__(self, "splits", tuple(float(f) for f in self.splits))
        object.__setattr__(self, "fidelity", Fidelity(self.fidelity))
        # None: decided later (mask_res: the family camera's); max_depth 0: the scene's integrator
        for name, low, high in (
            ("spp", 1, 1 << 20),
            ("max_depth", 0, 64),
            ("mask_res", 1, 4096),
            ("background_spp", 1, 1 << 20),
        ):
            if getattr(self, name) is not None:
                check_int(f"RenderRequest.{name}", getattr(self, name), low, high)
        for name in ("differential", "shared_difference"):
            if getattr(self, name) is not None and not isinstance(getattr(self, name), bool):
                raise bad(name, "None, True or False")
        for name, kind in (
            ("dtype", precision.StorageDtype),
            ("error_scale", precision.ErrorScale),
            ("difference_seeds", DifferenceSeeds),
        ):
            value = getattr(self, name)
            if value is not None and value not in [v.value for v in kind]:
                raise bad(name, f"None or one of {', '.join(v.value for v in kind)}")
            if value is not None:
                object.__setattr__(self, name, kind(value))
        if self.signal_target_error is not None:
            check_number("RenderRequest.signal_target_error", self.signal_target_error, 1e-6, 100.0)
        if self.samples_factor is not None:
            check_number(
                "RenderRequest.samples_factor", self.samples_factor, 0.0, 1e4, lo_open=True
            )
        for name, lo, hi in (
            ("target_error", 1e-6, 1.0),
            ("dtype_error_bound", 1e-9, 1.0),
            ("indirect_fraction", 0.0, 1.0),
            ("parallax_fraction", 0.0, 100.0),
            ("background_interval_s", 1e-3, 1e6),
        ):
            check_number(f"RenderRequest.{name}", getattr(self, name), lo, hi)

    def identity(self, description: dict) -> dict:
        """JSON-ready identity: the request with the *resolved* scene description.

        Two renders into one directory must have equal identities; the resolved
        description (not the file name) makes an edited TOML count as different.
        Fields added after dataset format 4 are left out while None (their
        default), so datasets rendered before them still resume.
        """
        d = {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if not (f.name in _LATER_FIELDS and getattr(self, f.name) is None)
        }
        d["family"] = str(self.family)
        d["fidelity"] = self.fidelity.value
        d["splits"] = list(self.splits)
        d["overrides"] = self.overrides or {}
        d["description"] = description
        return json.loads(json.dumps(d, sort_keys=True, default=ds._json_default))
