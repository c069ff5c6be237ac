"""Leaving out what a scene does not need, each choice decided from a measured error.

:func:`decide_fidelity` renders a few probe frames of a family (spread over the
sequence, at fixed seeds; :mod:`.probes`) and decides, one function per knob
(:mod:`.knobs`, :mod:`.differential_choice`), each recording the error it was
decided from:

- **shared render**: one render at the board centre replicated to all detectors,
  when the largest parallax between a detector and the board centre,
  ``|b| d / z_min`` on the mask plane, stays below ``parallax_fraction`` of a
  texel (``b`` the detector offset, ``d`` the mask distance, ``z_min`` the
  nearest scene depth from a grid of rays cast from the board centre), or when
  the parallax changes measurements by less than ``SHARED_ERROR_SHARE`` of the
  target error (measured with common random numbers: the same samples with every
  detector moved to the board centre, so noise cancels);
- **bounce depth**: the shallowest of ``CANDIDATE_DEPTHS`` (2 = direct light
  only) whose measurements differ from a depth-``DEEP_REFERENCE_DEPTH`` render
  by less than ``indirect_fraction``; probes use common random numbers, so the
  difference is the light of the bounces left out, not noise. The scene's own
  integrator depth is measured and recorded too, not trusted;
- **samples per texel** from the target measurement error: the Monte Carlo
  error of measurements, estimated from two renders with different seeds at a
  pilot sample count, falls as ``1/sqrt(spp)``; the choice is then checked
  against a reference at 8x the samples;
- **differential rendering** (families with a static background, see
  :mod:`mincam_render.render.differential`) when its cost per frame, counted in paths
  traced with the backgrounds amortized, is lower than the plain
  render's. Its settings come from an error budget of ``PLAN_ERROR_SHARE`` of
  the target: the biases are measured first (sharing ``X - C`` from the board
  centre, interpolating the daylight within a window), and the noises of
  ``X - C`` and of the backgrounds share what is left in the cheapest split
  (:func:`.budget.split_noise_budget`); ``X - C`` is traced as deep as the
  backgrounds; the choice is checked against a plain reference whose predicted
  noise is ``REFERENCE_NOISE_SHARE`` of the target (subtracted in quadrature);
- **storage float16** when the relative measurement error it adds (per-frame
  power-of-two scaling, see :mod:`mincam_render.render.precision`) stays below
  ``dtype_error_bound`` for random printable masks, else float32;
- **mask resolution**: kept at the camera's. A transport image at a coarser
  resolution gives *exact* measurements for masks of that resolution (its
  texels are sums of the finer ones), so resolution is a design choice of the
  mask (swept in training), not an accuracy knob of the render;
- **monochrome variant** (photodiodes are single-channel) and **no temporal
  history** unless the family has ``TemporalLabels``: recorded, nothing to measure.

Errors are relative errors of measurements ``P = sum T M`` for random printable
masks (:func:`mincam_render.render.precision.measurement_relative_error`), RMS and max
over probe frames, detectors and masks, relative to one of two things
(:class:`~mincam_render.render.precision.ErrorScale`):

- the **total**: each frame's own measurement (or their mean over frames), as
  before; the bounds of the biases (path depth, float16) stay in this scale;
- the **label signal**: the RMS over frames of the part of each measurement
  that the state the labels are computed from changes (:mod:`.signal`: what
  movers and doors change, ``X - C``; what each switched light adds; the
  frames themselves less their mean; or, for a task read from motion, the
  steps from one frame to the next, where a frame's independent error counts
  sqrt(2) times), rendered on ``SIGNAL_FRAMES`` frames (or frame pairs) of
  the planning episode as two estimates whose covariance has no noise term.
  One person changes a workspace measurement by about 1 % of its total, so
  "1 % of the total" can be as large as what the camera must read.

The Monte Carlo target (spp of frames and backgrounds, the noise budget, the
check) is in the family's ``planning_error_scale`` with its task-checked
``signal_target_error`` (``benchmarks/bench_task_fidelity.py``), unless the
request names a scale or a target. Every plan records its error against the
reference in both, for random masks and single-texel box pixels
(``decisions["achieved"]["against_reference"]``), and the label signal's RMS.
Every decision records its value, its source (``flag``, ``auto`` or
``full``), the bound and the measured figures. The plan is then checked
against a high-spp reference (:mod:`.check`) and returned as a frozen
:class:`FidelityPlan`.
"""

from __future__ import annotations

import dataclasses
import enum
import logging
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol

from mincam_render.core.checks import check_int
from mincam_render.core.strict_json import JsonObject
from mincam_render.render.differential import BackgroundSettings
from mincam_render.render.fidelity.check import Draft, check_against_reference
from mincam_render.render.fidelity.differential_choice import decide_differential
from mincam_render.render.fidelity.knobs import (
    decide_dtype,
    decide_max_depth,
    decide_shared_render,
    decide_spp,
    recorded_decisions,
)
from mincam_render.render.fidelity.probes import Probes, Stages
from mincam_render.render.fidelity.records import Decision
from mincam_render.render.precision import StorageDtype, storage_dtype

if TYPE_CHECKING:
    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.render.fidelity.probes import PlanRequest
    from mincam_render.render.fidelity.signal import ProbedFamily

    class FidelityRequest(PlanRequest, Protocol):
        """A render request as :func:`decide_fidelity` reads it (``RenderRequest`` has it)."""

        @property
        def fidelity(self) -> Fidelity:
            """AUTO measures each choice left None; FULL takes full-fidelity defaults."""


log = logging.getLogger(__name__)


class Fidelity(enum.Enum):
    """How render settings not given explicitly are chosen."""

    AUTO = "auto"  # measured from scene and camera (mincam_render.render.fidelity)
    FULL = "full"  # no shortcuts: per-detector renders, scene integrator, float32


@dataclasses.dataclass(frozen=True, kw_only=True)
class FidelityPlan:
    """Render settings of a family seen by a camera, with the decision behind each.

    Args:
        spp: samples per texel of each frame (>= 1).
        max_depth: path depth of frames; 0 = the scene's own integrator.
        shared_render: one render from the board centre copied to every detector.
        mask_resolution: texels per side of the transport images (>= 1).
        dtype: storage type (:class:`~mincam_render.render.precision.StorageDtype`
            or its value, as a plan's JSON holds it).
        background: differential rendering's background settings, or None for
            plain renders.
        decisions: per knob :meth:`~.records.Decision.as_json`, plus ``achieved``
            (:meth:`~.records.Achieved.as_json`) and ``probe_frames``: the JSON
            record a plan file keeps, written to the manifest as it is.

    Raises:
        ValueError: a setting outside its range, naming it.
    """

    spp: int
    max_depth: int
    shared_render: bool
    mask_resolution: int
    dtype: StorageDtype
    background: BackgroundSettings | None
    decisions: JsonObject

    def __post_init__(self) -> None:
        for name, low in (("spp", 1), ("max_depth", 0), ("mask_resolution", 1)):
            check_int(name, getattr(self, name), low)
        object.__setattr__(self, "dtype", storage_dtype(self.dtype))

    def settings(self) -> JsonObject:
        """The settings' JSON form, as the manifest's ``job.render`` and the plan cache hold it."""
        return {
            "spp": self.spp,
            "max_depth": self.max_depth,
            "shared_render": self.shared_render,
            "mask_resolution": self.mask_resolution,
            "dtype": self.dtype.value,
            "background": None if self.background is None else self.background.as_json(),
        }

    @classmethod
    def from_dict(cls, settings: Mapping[str, Any], decisions: JsonObject) -> FidelityPlan:
        """A plan read back from :meth:`settings` and its decisions (a kept plan)."""
        background = settings["background"]
        return cls(
            **{k: v for k, v in settings.items() if k != "background"},
            background=None if background is None else BackgroundSettings.from_dict(background),
            decisions=decisions,
        )


def decide_fidelity(
    family: ProbedFamily,
    camera: FreeformCamera,
    request: FidelityRequest,
    *,
    progress: bool = False,
) -> FidelityPlan:
    r"""Choose render settings for ``family`` seen by ``camera`` (see the module doc).

    The Monte Carlo error is planned relative to the request's scale (else the
    family's ``planning_error_scale``): relative to the total, or to the label
    signal,

    .. math::

        e = \frac{\sqrt{\langle (P - P_\text{ref})^2 \rangle}}
                 {\sqrt{\langle (S - \bar S)^2 \rangle_\text{frames}}}

    where ``S`` is a measurement of what the labels' state changes in a frame
    (movers and doors: the frame less its static background; switched lights:
    each light's own light, the weakest light's; otherwise the frame less its
    mean over frames), ``P`` the plan's measurement and ``P_ref`` the reference's,
    pooled over probe frames, detectors and random printable masks.

    Args:
        family: a :class:`~mincam_render.scenes.base.SceneFamily`.
        camera: the camera to render (mask resolution already final).
        request: a :class:`~mincam_render.data.render_job.RenderRequest`; its explicit
            settings win, its bounds drive the automatic choices.
        progress: show a progress bar naming what is being measured (stderr).

    Raises:
        ValueError: ``--differential`` for a family without a static background.
    """
    auto = request.fidelity is Fidelity.AUTO
    p = Probes(family, camera, request)
    stages = Stages(_PLAN_STAGES, enabled=progress)
    decisions: dict[str, Decision] = {}
    stages.start("parallax: one shared render vs one per detector")
    decisions["shared_render"] = shared = decide_shared_render(p, auto)
    draft = Draft(bool(shared.value), camera.rendered_camera(bool(shared.value)))
    stages.start("path depth vs a deep reference")
    decisions["max_depth"] = decide_max_depth(p, auto, draft.render_cam, draft.shared)
    draft.max_depth = int(decisions["max_depth"].value)
    stages.start("Monte Carlo error at the pilot spp")
    decisions["spp"], draft.e_pilot = decide_spp(
        p, auto, draft.render_cam, draft.max_depth, draft.shared
    )
    draft.spp = int(decisions["spp"].value)
    stages.start("differential rendering: background and difference")
    decisions["differential"] = decide_differential(
        p, auto, draft.render_cam, draft.max_depth, draft.spp
    )
    _adopt_differential(decisions, draft, request)
    stages.start("the plan against a high-spp reference")
    chosen, achieved = check_against_reference(p, auto, decisions, draft)
    stages.start("float16 storage error")
    dtype = decide_dtype(p, auto, chosen)
    stages.close()
    record: JsonObject = {name: d.as_json() for name, d in decisions.items()}
    if achieved is not None:
        record["achieved"] = achieved.as_json()
    record["dtype"] = dtype.as_json()
    record.update({name: d.as_json() for name, d in recorded_decisions(p).items()})
    record["probe_frames"] = p.indices
    log.info("fidelity: %s", {k: v["value"] for k, v in record.items() if "value" in v})
    return FidelityPlan(
        spp=draft.spp,
        max_depth=draft.max_depth,
        shared_render=draft.shared,
        mask_resolution=camera.mask_resolution[0],
        dtype=storage_dtype(str(dtype.value)),
        background=draft.background,
        decisions=record,
    )


#: Measurements of a plan (the progress bar's steps): sharing, depth, spp, differential,
#: the check against a reference, storage.
_PLAN_STAGES = 6


def _adopt_differential(decisions: dict[str, Decision], draft: Draft, request: PlanRequest) -> None:
    """With differential rendering, frames take its spp and depth; backgrounds get settings."""
    diff = decisions["differential"]
    if not diff.value:
        return
    figures = diff.measured
    draft.background = BackgroundSettings(
        interval_s=request.background_interval_s,
        spp=figures["background_spp"],
        max_depth=draft.max_depth or None,
        shared_difference=figures.get("shared_difference", {}).get("value", False),
        difference_seeds=figures["difference_seeds"]["value"],
    )
    for name, value, in_background in (
        ("spp", figures["frame_spp"], figures["background_spp"]),
        ("max_depth", figures["frame_max_depth"], draft.max_depth),
    ):
        plain = decisions[name]
        decisions[name] = dataclasses.replace(
            plain.with_measured(plain_value=plain.value),
            value=value,
            reason=f"{plain.reason}; differential rendering renders frames with {name} {value} "
            f"and backgrounds with {in_background} (see 'differential')",
        )
    draft.spp, draft.max_depth = figures["frame_spp"], figures["frame_max_depth"]
