"""An episode's request at other samples: the same scene, its plan's samples scaled.

Fidelity studies render the episodes a user renders (auto fidelity, a plan per
episode) again with more or fewer samples: :func:`rescaled_request` keeps
everything that fixes the scene (family, overrides, seed, frames, splits) and
replaces the fidelity with the plan's samples times a factor, at an explicit
path depth and difference seeds. A user asks for the same with
``RenderRequest.samples_factor`` (``render --samples-factor 4``), which
:func:`resolved_request` turns into that explicit request before a render
starts. :data:`SCENE_FIELDS` are the request fields that must agree for two
renders to be of the same scene.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from mincam_render.data.render_job.request import RenderRequest
from mincam_render.render.differential import DifferenceSeeds

#: Path depth of re-rendered episodes ("full path depth": far beyond where
#: another bounce changes a measurement at the plans' error).
FULL_PATH_DEPTH = 16
#: Manifest request fields that fix what happens in an episode and the texels it
#: is seen through (not how many samples render it).
SCENE_FIELDS = ("description", "seed", "num_frames", "splits", "mask_res")


def scaled_samples(samples: int, factor: float) -> int:
    """``samples`` times ``factor``, rounded, at least 1."""
    return max(1, int(samples * factor + 0.5))


def rescaled_request(
    request: RenderRequest,
    rendered: Path,
    factor: float,
    *,
    max_depth: int | None = FULL_PATH_DEPTH,
    difference_seeds: DifferenceSeeds = DifferenceSeeds.WINDOW,
) -> RenderRequest:
    """``request`` at full fidelity, its plan's samples of frames and backgrounds times ``factor``.

    The plan is read from the manifest of ``rendered`` (``request`` rendered
    there) when it exists, else planned now (measured, or looked up in the plan
    cache). ``max_depth``: path depth (None: the plan's); per-frame
    ``difference_seeds`` apply to differential renders only.
    """
    from mincam_render.data.dataset import MANIFEST_NAME, read_manifest
    from mincam_render.data.render_job.planning import plan_render

    if (rendered / MANIFEST_NAME).is_file():
        manifest = read_manifest(rendered)
    else:
        manifest = plan_render(resolved_request(request))
    return _scaled(request, manifest["job"]["render"], factor, max_depth, difference_seeds)


def resolved_request(
    request: RenderRequest, *, use_plan_cache: bool = True, progress: bool = False
) -> RenderRequest:
    """The explicit request ``request`` renders as: its ``samples_factor`` applied.

    Without a factor, ``request`` itself. With one, the plan of the request
    without it (measured, or from the plan cache unless ``use_plan_cache`` is
    False) at that many times its samples of frames and backgrounds, at the
    request's path depth if it names one, else :data:`FULL_PATH_DEPTH`, with
    the request's difference seeds (per window unless it asks for per frame).
    With neither named, this is the task-fidelity check's level of that factor:
    both render the same datasets.
    """
    from mincam_render.data.render_job.planning import plan_render

    factor = request.samples_factor
    if factor is None:
        return request
    base = dataclasses.replace(request, samples_factor=None)
    manifest = plan_render(base, use_cache=use_plan_cache, progress=progress)
    seeds = request.difference_seeds or DifferenceSeeds.WINDOW
    depth = FULL_PATH_DEPTH if request.max_depth is None else request.max_depth
    return _scaled(base, manifest["job"]["render"], factor, depth, seeds)


def _scaled(
    request: RenderRequest,
    plan: dict,
    factor: float,
    max_depth: int | None,
    difference_seeds: DifferenceSeeds,
) -> RenderRequest:
    """``request`` at full fidelity with the settings of ``plan`` (a manifest's ``job.render``).

    The samples are ``plan``'s times ``factor``, whatever factor ``request`` asked
    for: its own is already in ``plan`` when ``plan`` was rendered from it.
    """
    from mincam_render.render.fidelity import Fidelity

    bg = plan["background"]  # the request's own fields stay where there is none
    frame_seeds = bg is not None and difference_seeds is DifferenceSeeds.FRAME
    return dataclasses.replace(
        request,
        fidelity=Fidelity.FULL,
        spp=scaled_samples(plan["spp"], factor),
        max_depth=max_depth if max_depth is not None else plan["max_depth"],
        shared_render=plan["shared_render"],
        dtype=plan["dtype"],
        differential=bg is not None,
        background_spp=request.background_spp if bg is None else scaled_samples(bg["spp"], factor),
        shared_difference=request.shared_difference if bg is None else bg["shared_difference"],
        difference_seeds=difference_seeds if frame_seeds else request.difference_seeds,
        samples_factor=None,  # applied: the plan's samples are the settings now
    )


def same_scene(rendered: Path, other: Path) -> None:
    """Check that the dataset ``other`` renders the scene of ``rendered`` (:data:`SCENE_FIELDS`).

    Raises:
        ValueError: ``other`` is missing, unfinished, or of another scene (the
            fields that differ are named).
    """
    from mincam_render.data.dataset import MANIFEST_NAME, read_manifest

    if not (other / MANIFEST_NAME).is_file():
        raise ValueError(f"{other}: no dataset there (render it first)")
    theirs = read_manifest(other)
    if not theirs.get("complete"):
        raise ValueError(f"{other}: its render is unfinished (resume it first)")
    ours = read_manifest(rendered)["request"]
    differ = [f for f in SCENE_FIELDS if ours.get(f) != theirs["request"].get(f)]
    if differ:
        raise ValueError(f"{other} is not a render of the scene of {rendered}: {differ} differ")
