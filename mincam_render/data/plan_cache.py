"""Fidelity plans kept on disk, so a description is planned once, not once per render.

A plan (the settings and measured decisions of
:func:`mincam_render.render.fidelity.decide_fidelity`) depends on the scene
description, the camera, the fidelity targets, the number of frames (backgrounds
are amortized over them) and the renderer, not on the episode: every plan is
measured on the *planning episode* (the description's sequence at seed
:data:`PLAN_SEED`), so all episodes of a study (train, validation and test seeds)
share one plan, and a cached plan is exactly the plan that would be measured.

Plans are looked up by the sha256 of :func:`plan_fields`, first among the plans
shipped with the package (package data, ``scenes/plans/`` in a clone, written by
``scripts/ship_plans.py``), then in the user's cache directory (``$MINCAM_RENDER_PLAN_CACHE``, else
the platform's user cache directory, via ``platformdirs``). A file that does not
parse or whose fields do not hash to its name is ignored with a warning (and
planned again). Bump :data:`PLANNER_VERSION` when the planner changes what it
decides: older plans then stop matching.

A plan holds the Mitsuba variant it was measured with (``fields["renderer"]
["variant"]``, part of its key), and a plan of another variant is **measured
again, never reused**. Reuse would need a check that the two variants' noise
is the same, and the only check that proves it is the measurement itself;
re-measuring keeps the rule above (a kept plan is exactly the plan that would
be measured here), which a user comparing CPU and GPU renders relies on. The
cost is minutes per description on the first GPU run (the plans shipped with
the repository are measured with ``llvm_ad_mono``); :func:`find_plan` says so
when a plan of another variant is kept.
"""

from __future__ import annotations

import enum
import functools
import hashlib
import json
import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import NotRequired, TypedDict

from mincam_render.core.package_data import shipped_path
from mincam_render.core.strict_json import JsonObject
from mincam_render.render.differential import DifferenceSeeds
from mincam_render.render.precision import ErrorScale

log = logging.getLogger(__name__)

#: Seed of the planning episode (whatever the dataset's seed).
PLAN_SEED = 0
#: Version of the planner's decisions; part of every plan's key. 4: probe seeds
#: from ``core.seeds.stream_seed``, pvlib daylight, paths by networkx and the
#: S9119-01 diode of the families' cameras (dataset format 4).
PLANNER_VERSION = 4
#: Environment variable naming the user's plan cache directory.
CACHE_ENV = "MINCAM_RENDER_PLAN_CACHE"
#: The planning of every plan before targets relative to the label signal: relative
#: to each frame's total, ``X - C`` seeded per background window.
TOTAL_PLANNING = {
    "error_scale": ErrorScale.FRAME.value,
    "difference_seeds": DifferenceSeeds.WINDOW.value,
}
#: Request fields that do not change a plan (the episode and its storage layout).
EPISODE_FIELDS = ("family", "seed", "overrides", "shard_frames", "splits")


class PlanSource(enum.StrEnum):
    """Where a kept plan was found."""

    SHIPPED = "shipped"  # with the package (scenes/plans/)
    CACHE = "cache"  # the user's cache directory


#: The label-signal sources of the plans kept before the source was part of a
#: plan's key (:class:`~mincam_render.render.fidelity.signal.SignalSource`
#: values): their plans keep their keys; a later source (frame steps) is a field.
KEYLESS_SIGNALS = frozenset({"movers", "lights", "frames"})


class Planning(TypedDict):
    """What a request leaves to the family or the planner, resolved (:func:`plan_fields`).

    ``label_signal`` only where it is not one of :data:`KEYLESS_SIGNALS`.
    """

    error_scale: str
    target_error: float
    difference_seeds: str
    label_signal: NotRequired[str]


class KeptPlan(TypedDict):
    """A plan as a plan file keeps it: :meth:`FidelityPlan.settings` and its decisions.

    Both are the JSON records the planner wrote
    (:class:`~mincam_render.render.fidelity.FidelityPlan` reads them back).
    """

    settings: JsonObject
    decisions: JsonObject


@dataclass(frozen=True)
class FoundPlan:
    """A kept plan (:func:`find_plan`) and where it was found."""

    plan: KeptPlan
    where: PlanSource


def cache_dir() -> Path:
    """The user's plan cache directory (not created here)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    import platformdirs

    return Path(platformdirs.user_cache_dir("mincam_render")) / "plans"


def shipped_dir() -> Path:
    """The folder of the plans shipped with the package (``scenes/plans/`` in a clone)."""
    return shipped_path("plans")


def plan_fields(
    identity: JsonObject, family_name: str, renderer: dict[str, str], planning: Planning
) -> JsonObject:
    """What a plan depends on: the request identity less the episode, the renderer, the targets.

    Returns:
        The canonical JSON object a plan is kept under (:func:`plan_key`).

    Args:
        identity: :meth:`~mincam_render.data.render_job.RenderRequest.identity` (it
            holds the resolved description, so a file path and a family name
            with the same content give the same fields).
        family_name: the scene family's registered name.
        renderer: ``{"variant", "mitsuba", "drjit"}`` versions.
        planning: what the request leaves to the family or the planner, resolved
            (``{"error_scale", "target_error", "difference_seeds"}``): a family's
            task-checked target can change without its description changing. A
            field unless it is :data:`TOTAL_PLANNING` (the only planning before
            it; those plans' keys stay valid) with no ``label_signal``.
    """
    fields = {k: v for k, v in identity.items() if k not in EPISODE_FIELDS}
    fields.update(family_name=family_name, renderer=renderer, planner_version=PLANNER_VERSION)
    total = {k: v for k, v in planning.items() if k in TOTAL_PLANNING} == TOTAL_PLANNING
    if not total or "label_signal" in planning:
        fields["planning"] = planning
    return json.loads(json.dumps(fields, sort_keys=True))


def plan_key(fields: JsonObject) -> str:
    """sha256 (hex) of the canonical JSON of ``fields``."""
    return hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()


def find_plan(fields: JsonObject) -> FoundPlan | None:
    """The plan kept for ``fields`` and where, or None when none is kept.

    A missing folder of shipped plans is said once (:func:`shipped_plans_missing`).
    """
    key = plan_key(fields)
    shipped_plans_missing()
    for where, folder in ((PlanSource.SHIPPED, shipped_dir()), (PlanSource.CACHE, cache_dir())):
        path = folder / f"{key}.json"
        if not path.is_file():
            continue
        try:
            plan = json.loads(path.read_text())
            if plan_key(plan["fields"]) != key:
                raise ValueError("its fields do not hash to its name")
            return FoundPlan({"settings": plan["settings"], "decisions": plan["decisions"]}, where)
        except (OSError, ValueError, KeyError, TypeError) as err:
            log.warning("ignoring the plan %s (%s); planning again", path, err)
    for variant, path in other_variant_plans(fields):
        log.info(
            "a fidelity plan of variant %s is kept (%s), but plans are measured per "
            "variant: planning again for %s",
            variant,
            path,
            plan_variant(fields),
        )
    return None


def plan_variant(fields: JsonObject) -> str:
    """The Mitsuba variant a plan of ``fields`` is (or would be) measured with."""
    return str(fields["renderer"]["variant"])


def other_variant_plans(fields: JsonObject) -> list[tuple[str, Path]]:
    """``(variant, path)`` of kept plans of ``fields`` but of another variant (not reused)."""
    from mincam_render.render.backend import VARIANTS

    found = []
    for variant in sorted(set(VARIANTS.values()) - {plan_variant(fields)}):
        key = plan_key({**fields, "renderer": {**fields["renderer"], "variant": variant}})
        found += [
            (variant, folder / f"{key}.json")
            for folder in (shipped_dir(), cache_dir())
            if (folder / f"{key}.json").is_file()
        ]
    return found


@functools.cache
def shipped_plans_missing() -> bool:
    """Whether the shipped plans' folder is missing; the first call logs a warning if so.

    A package installed without its plans still works, but measures every plan
    again (minutes per description): said once per process, never silently.
    """
    missing = not shipped_dir().is_dir()
    if missing:
        log.warning(
            "the shipped fidelity plans are missing (no folder %s): every plan is measured "
            "again and kept in %s",
            shipped_dir(),
            cache_dir(),
        )
    return missing


def store_plan(
    fields: JsonObject, plan: KeptPlan, seconds: float, folder: Path | None = None
) -> Path:
    """Write a plan atomically into ``folder`` (default: the user's cache); returns its path.

    Args:
        fields: :func:`plan_fields` of the plan.
        plan: the settings and decisions, JSON-ready.
        seconds: wall time the planning took (kept for reports).
        folder: where to write; :func:`shipped_dir` to ship it with the package.
    """
    folder = cache_dir() if folder is None else Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{plan_key(fields)}.json"
    body = {"fields": fields, **plan, "planning_seconds": round(seconds, 1)}
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".plan-", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(body, f, indent=1, sort_keys=True)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
