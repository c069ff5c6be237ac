"""Rendering a dataset: planning shards, worker processes or Ray, resume, progress.

A render is described by a :class:`RenderRequest` (scene family, frames, seed,
sharding, fidelity settings; :mod:`.request`). :func:`render_dataset`
(:mod:`.job`) turns it into a dataset directory (format:
:mod:`mincam_render.data.dataset`):

1. **Plan.** A new directory gets a manifest with the resolved configuration,
   the fidelity decisions (measured once, :mod:`mincam_render.render.fidelity`;
   kept in :mod:`mincam_render.data.plan_cache`) and one empty record per shard
   (:mod:`.planning`). An existing directory must hold a manifest of the *same*
   request (compared field by field), whose plan is then reused as is, so a
   resumed render is identical to an uninterrupted one (:mod:`.manifest`).
2. **Check.** Every shard is verified against its sha256: intact shards are kept
   (never re-rendered); corrupted or truncated ones are re-rendered. A
   differential job's missing backgrounds are rendered first (:mod:`.backgrounds`).
3. **Render.** Missing shards (:mod:`.shards`) are rendered by worker processes
   (:mod:`mincam_render.data.worker_pool`), in-process (``workers=0``), or as
   Ray tasks (``ray_address``) (:mod:`.executors`). Workers return arrays; only
   this process writes files, each atomically, then updates the manifest.

Frame ``i`` is rendered with seed :func:`~mincam_render.core.seeds.frame_seed`
``(seed, i)`` and the family's scene state ``i`` (a pure function of ``i``), so
any frame re-renders bit-identically whatever the order, worker count or
interruption. Here: the names other modules, tests and benchmarks use. Nothing
here imports Mitsuba, Dr.Jit or torch (the command line imports this for
``--help``).
"""

from mincam_render.data.render_job.backgrounds import background_keys, render_backgrounds
from mincam_render.data.render_job.estimate import JobEstimate, JobLimits, JobTooLarge
from mincam_render.data.render_job.executors import (
    POOL_BREAK_EVEN_S,
    RenderError,
)
from mincam_render.data.render_job.job import RenderSummary, render_dataset
from mincam_render.data.render_job.planning import (
    _describe_family,
    package_versions,
    plan_render,
    source_revision,
)
from mincam_render.data.render_job.request import RenderRequest
from mincam_render.data.render_job.scene import _load_family, _render_camera
from mincam_render.data.render_job.shards import FRAME_DELAY_ENV, _worker_init, render_shard

__all__ = [
    "FRAME_DELAY_ENV",
    "JobEstimate",
    "JobLimits",
    "JobTooLarge",
    "POOL_BREAK_EVEN_S",
    "RenderError",
    "RenderRequest",
    "RenderSummary",
    "_describe_family",
    "_load_family",
    "_render_camera",
    "_worker_init",
    "background_keys",
    "package_versions",
    "plan_render",
    "render_backgrounds",
    "render_dataset",
    "render_shard",
    "source_revision",
]
