"""The manifest of a new render: its configuration and the fidelity plan, kept or measured.

The plan comes from :mod:`mincam_render.data.plan_cache` when one is kept for the
request's description, camera, targets and frame count; otherwise it is
measured on the planning episode (:mod:`mincam_render.render.fidelity`) and kept.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mincam_render.core.strict_json import JsonObject
from mincam_render.data import dataset as ds
from mincam_render.data.render_job.request import RenderRequest
from mincam_render.render.capabilities import history_frames
from mincam_render.render.fidelity import FidelityPlan

if TYPE_CHECKING:
    from mincam_render.data import plan_cache
    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.scenes.base import SceneFamily

log = logging.getLogger(__name__)


def package_versions() -> dict[str, str]:
    """Versions of the packages that determine the output; the git revision of a checkout.

    ``git_revision`` is there only when this package runs from a git checkout
    (:func:`source_revision`); an installed package is named by its version.
    """
    import importlib.metadata as md

    out = {}
    for name in ("mitsuba", "drjit", "torch", "numpy", "mincam_render"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            out[name] = "not installed"
    revision = source_revision()
    if revision is not None:
        out["git_revision"] = revision
    return out


def source_revision() -> str | None:
    """The git commit of the checkout this package runs from; None if it is not one.

    Only when git tracks this very file is ``HEAD`` the revision of the code that
    runs: a package installed into an environment that lies inside some other
    work tree (a virtual environment in a project's repository) is not that
    repository's commit.
    """
    import subprocess

    here = Path(__file__).resolve()
    git = ["git", "-C", str(here.parent)]
    try:
        tracked = subprocess.run(
            [*git, "ls-files", "--error-unmatch", here.name], capture_output=True, timeout=10
        )
        if tracked.returncode != 0:
            return None
        head = subprocess.run(
            [*git, "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10, check=True
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() or None


def _describe_family(request: RenderRequest) -> tuple[SceneFamily, JsonObject, bool]:
    """``(family, description, rebuild flag)``: the description is the family config's JSON."""
    from mincam_render.core.config import parse, to_dict
    from mincam_render.scenes.registry import load_family

    family = load_family(
        request.family,
        seed=request.seed,
        num_frames=request.num_frames,
        overrides=request.overrides,
    )
    description = json.loads(json.dumps(to_dict(family.config), default=ds._json_default))
    try:
        rebuilt = parse(type(family.config), description, source="manifest")
        rebuild = rebuilt == family.config
    except ValueError:
        rebuild = False
    return family, description, rebuild


def plan_render(
    request: RenderRequest, *, use_cache: bool = True, ship: bool = False, progress: bool = False
) -> dict:
    """The manifest of a new render: configuration, fidelity decisions, empty shards.

    The fidelity plan comes from :mod:`mincam_render.data.plan_cache` when one is kept
    for the request's description, camera, targets and frame count; otherwise it is
    measured (a few small renders of the planning episode) and kept in the user's
    cache. Writes nothing else.

    Args:
        request: what to render.
        use_cache: look up and keep plans; False always measures (and keeps nothing).
        ship: measure the plan and write it among the shipped plans
            (``scenes/plans/``, :mod:`mincam_render.data.plan_cache`).
        progress: show a progress bar while the plan is measured.

    Returns:
        The manifest (a JSON-ready dict; format: :mod:`mincam_render.data.dataset`).
    """
    from mincam_render.render import backend
    from mincam_render.scenes.registry import family_reference

    if request.samples_factor is not None:
        raise ValueError(
            "plan_render: a request with samples_factor renders as another request; "
            "plan rescale.resolved_request(request) instead"
        )
    backend.use_variant()
    family, description, rebuild = _describe_family(request)
    identity = request.identity(description)
    camera = family.camera()
    if request.mask_res is not None:
        camera = dataclasses.replace(camera, mask_resolution=(request.mask_res, request.mask_res))
    plan = _fidelity_plan(
        request,
        family_reference(type(family)),
        identity,
        camera,
        use_cache and not ship,
        ship,
        progress,
    )
    job = _job_section(request, identity, family, description, rebuild, camera, plan)
    return _manifest(request, identity, family, description, job, plan)


def _job_section(
    request: RenderRequest,
    identity: dict,
    family: SceneFamily,
    description: dict,
    rebuild: bool,
    camera: FreeformCamera,
    plan: FidelityPlan,
) -> dict:
    """The manifest's ``job``: all a worker needs to render a shard (and its backgrounds)."""
    from mincam_render.render.differential import background_family, background_parts
    from mincam_render.scenes.registry import family_reference

    job: JsonObject = {
        "request_sha256": hashlib.sha256(ds.json_bytes(identity)).hexdigest(),
        "family": {
            "name": family_reference(type(family)),
            "source": str(request.family),
            "overrides": request.overrides or {},
            "description": description,
            "rebuild_from_description": rebuild,
        },
        "seed": request.seed,
        "num_frames": request.num_frames,
        "shard_frames": request.shard_frames,
        "camera": ds.camera_to_dict(camera),
        "render": {
            "spp": plan.spp,
            "max_depth": plan.max_depth,
            "shared_render": plan.shared_render,
            "mask_resolution": plan.mask_resolution,
            "dtype": plan.dtype,
            "background": plan.settings()["background"],
        },
    }
    if plan.background is not None:
        parts = background_parts(
            background_family(family), job["num_frames"], plan.background.interval_s
        )
        job["backgrounds"] = list(parts)
        job["background_parts"] = parts
        job["background_components"] = list(dict.fromkeys(c for p in parts.values() for c in p))
    return job


def _manifest(
    request: RenderRequest,
    identity: dict,
    family: SceneFamily,
    description: dict,
    job: dict,
    plan: FidelityPlan,
) -> dict:
    """The manifest of a new render of ``job``: no shard or background rendered yet."""
    from mincam_render.render import backend

    backgrounds = components = None
    if plan.background is not None:
        backgrounds = [None] * len(job["backgrounds"])
        components = [None] * len(job["background_components"])
    info = backend.describe()
    num_shards = -(-request.num_frames // request.shard_frames)
    return {
        "format": ds.FORMAT_NAME,
        "format_version": ds.FORMAT_VERSION,
        "request": identity,
        "family": {
            "name": family.name,
            "fps": float(family.fps),
            "needs_history": history_frames(family) > 1,
            "history_frames": history_frames(family),
            "description": description,
        },
        "num_frames": request.num_frames,
        "shard_frames": request.shard_frames,
        "num_shards": num_shards,
        "splits": {
            k: list(v) for k, v in ds.split_ranges(request.num_frames, request.splits).items()
        },
        "camera": job["camera"],
        "label_specs": [ds.label_spec_to_dict(s) for s in family.labels],
        "fidelity": plan.decisions,
        "job": job,
        "transport": {
            "units": "W per unit transmittance",
            "axes": "T[frame, detector, row, col]; row 0 = up side of the view, col 0 = left",
            "stored_as": "stored * scale = T, scale a per-frame power of two (frames[i].scale)",
            "dtype": plan.dtype,
        },
        "frame_seed": "splitmix64(splitmix64(seed) ^ index) & (2^63 - 1)",
        "variant": info["variant"],
        "versions": package_versions(),
        "shards": [None] * num_shards,
        "backgrounds": backgrounds,
        "background_components": components,
        "complete": False,
    }


def resolved_planning(family_name: str, request: RenderRequest) -> plan_cache.Planning:
    """What the family and the planner resolve of ``request``'s planning (part of a plan's key).

    The target's scale and value, the difference seeds and, for a label-signal
    source newer than :data:`~mincam_render.data.plan_cache.KEYLESS_SIGNALS`,
    the source: what the plan's signal figures (and a signal-scale target) are
    relative to.
    """
    from mincam_render.data import plan_cache
    from mincam_render.render.differential import DifferenceSeeds
    from mincam_render.render.fidelity.constants import DIFFERENCE_SEEDS
    from mincam_render.render.fidelity.probes import planning_targets
    from mincam_render.scenes.registry import family_class

    cls = family_class(family_name)
    scale, target = planning_targets(cls.planning_error_scale, cls.signal_target_error, request)
    planning: plan_cache.Planning = {
        "error_scale": scale.value,
        "target_error": target,
        "difference_seeds": DifferenceSeeds(request.difference_seeds or DIFFERENCE_SEEDS).value,
    }
    if str(cls.label_signal) not in plan_cache.KEYLESS_SIGNALS:
        planning["label_signal"] = str(cls.label_signal)
    return planning


def _fidelity_plan(
    request: RenderRequest,
    family_name: str,
    identity: dict,
    camera: FreeformCamera,
    use_cache: bool,
    ship: bool,
    progress: bool,
) -> FidelityPlan:
    """The fidelity plan of a request: kept, or measured on the planning episode."""
    from mincam_render.data import plan_cache
    from mincam_render.render import backend
    from mincam_render.render.fidelity import decide_fidelity

    info = backend.describe()
    versions = package_versions()
    renderer = {"variant": info["variant"], **{k: versions[k] for k in ("mitsuba", "drjit")}}
    planning = resolved_planning(family_name, request)
    fields = plan_cache.plan_fields(identity, family_name, renderer, planning)
    found = plan_cache.find_plan(fields) if use_cache else None
    if found is not None:
        log.info("fidelity plan %s (%s)", plan_cache.plan_key(fields)[:12], found.where.value)
        return FidelityPlan.from_dict(found.plan["settings"], found.plan["decisions"])
    t0 = time.perf_counter()
    plan_request = dataclasses.replace(request, seed=plan_cache.PLAN_SEED)
    family, _, _ = _describe_family(plan_request)
    measured = decide_fidelity(family, camera, plan_request, progress=progress)
    decisions = measured.decisions
    decisions["planning_episode"] = {"seed": plan_cache.PLAN_SEED, "frames": request.num_frames}
    # measured figures are reported to 6 significant digits: last-bit differences
    # of floating-point sums between two planning runs must not change the bytes
    # of otherwise identical manifests; the JSON round trip makes a fresh plan
    # equal to a kept one
    plan: plan_cache.KeptPlan = json.loads(
        json.dumps({"settings": measured.settings(), "decisions": _rounded(decisions)})
    )
    seconds = time.perf_counter() - t0
    log.info("fidelity planned in %.1f s", seconds)
    if use_cache or ship:
        try:
            plan_cache.store_plan(fields, plan, seconds, plan_cache.shipped_dir() if ship else None)
        except OSError as err:
            log.warning("could not keep the fidelity plan in %s: %s", plan_cache.cache_dir(), err)
    return FidelityPlan.from_dict(plan["settings"], plan["decisions"])


def _rounded(obj: Any, digits: int = 6) -> Any:
    """``obj`` with every float rounded to ``digits`` significant digits (recursively)."""
    if isinstance(obj, float):
        return float(f"{obj:.{digits}g}") if math.isfinite(obj) else obj
    if isinstance(obj, dict):
        return {k: _rounded(v, digits) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return type(obj)(_rounded(v, digits) for v in obj)
    return obj
