"""Measure the fidelity plans of shipped scene descriptions and ship them in scenes/plans/.

A render whose description, camera, targets, frame count and renderer match a
shipped plan starts rendering at once instead of planning (minutes for indoor
families). Re-run this after a change of ``scenes/*.toml``, of the planner
(bump ``plan_cache.PLANNER_VERSION``) or of the pinned renderer;
``tests/datasets/test_plan_cache.py`` fails on a stale shipped plan.

Usage:
    .venv/bin/python scripts/ship_plans.py workspace:10000 lighting:3000
    (FAMILY:FRAMES, at the command line's default fidelity targets)
    .venv/bin/python scripts/ship_plans.py --main-job
    (the episodes of ``mincam-render pipeline`` at its defaults)
"""

from __future__ import annotations

import argparse
import logging
import time

from mincam_render.data.render_job import RenderRequest, plan_render


def main() -> None:
    """Plan each FAMILY:FRAMES afresh and write it into scenes/plans/."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("plans", nargs="*", metavar="FAMILY:FRAMES")
    parser.add_argument("--main-job", action="store_true", help="the pipeline's default episodes")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    requests = {}
    for item in args.plans:
        family, _, frames = item.partition(":")
        requests[item] = RenderRequest(family=family, num_frames=int(frames))
    if args.main_job:
        from mincam_render.studies.comparison.study import ComparisonConfig, episode_requests

        for name, request in episode_requests(ComparisonConfig()).items():
            key = f"main job {request.family}:{request.num_frames}"
            if name.endswith("-0"):  # one plan per episode length
                requests.setdefault(key, request)
    for item, request in requests.items():
        t0 = time.perf_counter()
        plan_render(request, ship=True)
        print(f"{item}: planned in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
