"""Throughput and memory of dataset rendering, next to a plain Mitsuba render.

Usage:
    python benchmarks/bench_render.py [--out benchmarks/results/render.json]
        [--families patches workspace] [--frames 64] [--dataset-frames 0] [--repeats 3]
        [--memory-frames 2000] [--rss-every 100] [--threads 0] [--workers CORES]

For each available scene family at its default camera: plans the render with
``--fidelity auto`` (the decisions and their measured errors go into the JSON),
warms up (JIT compilation and kernel recording are not timed), then times
``--repeats`` passes over ``--frames`` frames of :func:`render_shard` (scene
update, labels, transport render, float16 encoding: everything but the disk
write) and reports frames/s and detector-samples/s (median and spread). A plain
``mi.render`` of the same scene, updated to the same frames, with a perspective
sensor of as many pixels as rendered texels and the same spp, sampler
(stratified) and integrator (the sun-patch path tracer of
:mod:`mincam_render.render.sun_patch` for a family with a window, with the sun
sampled apart), is timed alongside: ``overhead = ours / plain - 1``. For differentially rendered
frames the rays are those of ``X`` (one board-centre detector when the
difference is shared). Both run in one process on every core. Then
``--workers`` processes, the cores shared among them as ``mincam-render
render`` runs them by default, render a shard each at once:
``frames_per_s_workers`` (one worker's scene updates and kernel tracing, which
run on one core, overlap with another's rendering).

Differentially rendered families (:mod:`mincam_render.render.differential`) render their
static backgrounds once per dataset: the plan is made for ``--dataset-frames``
frames (e.g. 68000, the paper's workspace training set), the backgrounds of
the timed frames are rendered and timed apart (converged renders and ``C``
separately), and ``frames_per_s_with_backgrounds`` charges every frame its
share of all the dataset's backgrounds (its count of converged components,
each light alone and the daylight at every window end, and of ``C`` per
background) on top of ``1 / frames_per_s_workers``.

Memory: renders ``--memory-frames`` frames of the first family in ONE process
(no worker recycling, the harshest case) and samples the resident set size
every ``--rss-every`` frames; growth is measured from the first sample after
warm-up to the last, and (robust to the allocator's swings) as the median of
the second half of the samples against the first half's.
``--memory-frames 10000`` reproduces the issue's target.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from contextlib import nullcontext
from pathlib import Path

import drjit as dr
import mitsuba as mi
from provenance import cpu_times, machine

from mincam_render.core import strict_json
from mincam_render.core.seeds import frame_seed
from mincam_render.data.render_job import (
    RenderRequest,
    _load_family,
    _render_camera,
    background_keys,
    plan_render,
    render_backgrounds,
    render_shard,
)
from mincam_render.render import backend
from mincam_render.render import mitsuba_scene as ms
from mincam_render.render.differential import BackgroundSettings
from mincam_render.render.sun_patch import sun_sampled_apart
from mincam_render.render.transport import render_transport
from mincam_render.scenes.registry import FAMILY_NAMES


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def time_backgrounds(job: dict, frames: int) -> tuple[dict | None, dict]:
    """Backgrounds of the first ``frames`` frames of a differential job, and their costs.

    A background is a weighted sum of converged components (each light alone,
    the daylight at the ends of its window) shared between backgrounds, plus
    one render of ``C``. Components and ``C`` are timed apart (after a
    warm-up) and charged by the dataset's own counts.
    """
    if job["render"].get("background") is None:
        return None, {}
    r = job["render"]
    settings = BackgroundSettings.from_dict(r["background"])
    family = _load_family(job)
    keys = background_keys(family, job)
    needed = list(dict.fromkeys(keys[:frames]))
    list(render_backgrounds(job, family, keys, needed[:1]))  # warm-up: JIT compilation
    t0 = time.perf_counter()
    out = {bg.key: bg for bg in render_backgrounds(job, family, keys, needed)}
    total = time.perf_counter() - t0
    # C alone, to split the total
    scene = family.build_scene()
    family.set_background(scene, keys.index(needed[0]), settings.interval_s)
    cam = _render_camera(job)[1].rendered_camera(settings.shared_difference)
    for _ in range(2):  # the first call may compile (a new scene object)
        t0 = time.perf_counter()
        render_transport(scene, cam, spp=r["spp"], seed=1, max_depth=r["max_depth"] or None)
        seconds_c = time.perf_counter() - t0
    components_needed = {c for bg in out.values() for c in bg.components}
    seconds_component = max(total - len(needed) * seconds_c, 0.0) / max(len(components_needed), 1)
    n_components = len(job["background_components"])
    n_backgrounds = len(job["backgrounds"])
    return out, {
        "converged_renders": n_components,
        "seconds_per_converged_render": seconds_component,
        "seconds_per_same_seed_render": seconds_c,
        "seconds_all_backgrounds": n_components * seconds_component + n_backgrounds * seconds_c,
    }


def time_workers(job: dict, workers: int, repeats: int, backgrounds: dict | None) -> list[float]:
    """Wall seconds of ``workers`` processes rendering shards 0..workers-1 at once.

    As ``mincam-render render`` runs them: spawned processes, the cores shared
    among them (:func:`render_job._worker_init`); a warm-up round first.
    """
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, wait

    from mincam_render.data.render_job import _worker_init
    from mincam_render.data.worker_pool import threads_per_worker

    shards = range(workers)
    walls = []
    with ProcessPoolExecutor(
        max_workers=workers,
        mp_context=mp.get_context("spawn"),
        initializer=_worker_init,
        initargs=(threads_per_worker(workers), None),
    ) as pool:
        for round_ in range(repeats + 1):
            t0 = time.perf_counter()
            wait([pool.submit(render_shard, job, i, backgrounds) for i in shards])
            if round_:  # round 0 warms up: scene build, JIT, kernel recording
                walls.append(time.perf_counter() - t0)
    return walls


def bench_family(name: str, frames: int, repeats: int, dataset_frames: int, workers: int) -> dict:
    request = RenderRequest(
        family=name, num_frames=max(frames * workers, 8, dataset_frames), shard_frames=frames
    )
    t0 = time.perf_counter()
    manifest = plan_render(request)
    plan_s = time.perf_counter() - t0
    job = manifest["job"]
    r = job["render"]
    camera, render_cam = _render_camera(job)
    rows, cols = camera.mask_resolution
    # the rays a frame traces: differential frames render X only, from the board
    # centre when the difference is shared
    background = r.get("background") or {}
    traced_cam = render_cam.rendered_camera(bool(background.get("shared_difference")))
    rendered_texels = traced_cam.num_detectors * rows * cols
    detector_samples = camera.num_detectors * rows * cols * r["spp"]

    backgrounds, background_costs = time_backgrounds(job, frames * workers)
    render_shard(job, 0, backgrounds)  # warm-up: scene build, JIT, kernel recording
    ours = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        render_shard(job, 0, backgrounds)
        ours.append(time.perf_counter() - t0)

    # plain Mitsuba: same scene and frames, same rays per frame, same integrator
    # (the sun-patch path tracer for a family with a window) and samples
    # stratified the same way
    family = _load_family(job)
    scene = family.build_scene()
    window = family.sun_window()
    depth = r["max_depth"] or -1
    if window is not None:
        integrator = mi.load_dict(ms.sun_patch_integrator(*window, max_depth=depth))
    elif r["max_depth"]:
        integrator = mi.load_dict({"type": "path", "max_depth": depth})
    else:
        integrator = None
    sensor = mi.load_dict(
        {
            "type": "perspective",
            "fov": camera.fov_deg,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=list(camera.position), target=list(camera.look_at), up=list(camera.up)
            ),
            "film": {
                "type": "hdrfilm",
                "width": cols * traced_cam.num_detectors,
                "height": rows,
                "rfilter": {"type": "box"},
                "pixel_format": "luminance",
            },
            "sampler": {"type": "multijitter", "sample_count": r["spp"]},
        }
    )

    def plain_pass():
        for i in range(frames):
            family.set_frame(scene, i)
            kw = {"integrator": integrator} if integrator is not None else {}
            with sun_sampled_apart(scene) if window is not None else nullcontext():
                mi.render(
                    scene, sensor=sensor, spp=r["spp"], seed=frame_seed(0, i) & 0xFFFFFFFF, **kw
                ).numpy()

    plain_pass()
    plain = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        plain_pass()
        plain.append(time.perf_counter() - t0)
    med, pmed = statistics.median(ours), statistics.median(plain)
    walls = time_workers(job, workers, repeats, backgrounds)
    workers_fps = workers * frames / statistics.median(walls)
    n_backgrounds = len(job.get("backgrounds", []))
    background_s = background_costs.get("seconds_all_backgrounds", 0.0)
    amortized_s = 1.0 / workers_fps + background_s / job["num_frames"]
    return {
        "family": name,
        "detectors": camera.num_detectors,
        "mask_resolution": [rows, cols],
        "spp": r["spp"],
        "max_depth": r["max_depth"],
        "shared_render": r["shared_render"],
        "dtype": r["dtype"],
        "fidelity": manifest["fidelity"],
        "plan_seconds": plan_s,
        "frames": frames,
        "rays_per_frame": rendered_texels * r["spp"],
        "dataset_frames": job["num_frames"],
        "differential": job["render"].get("background"),
        "backgrounds": n_backgrounds,
        **background_costs,
        "frames_per_s_with_backgrounds": 1.0 / amortized_s,
        "frames_per_s": frames / med,
        "frames_per_s_min_max": [frames / max(ours), frames / min(ours)],
        "workers": workers,
        "frames_per_s_workers": workers_fps,
        "frames_per_s_workers_min_max": [
            workers * frames / max(walls),
            workers * frames / min(walls),
        ],
        "detector_samples_per_s": frames * detector_samples / med,
        "plain_mitsuba_frames_per_s": frames / pmed,
        "overhead_ratio": med / pmed,
        "seconds_ours": ours,
        "seconds_plain": plain,
    }


def bench_memory(name: str, frames: int, every: int) -> dict:
    request = RenderRequest(family=name, num_frames=frames, shard_frames=every)
    job = plan_render(request)["job"]
    samples = []
    t0 = time.perf_counter()
    backgrounds = time_backgrounds(job, frames)[0]  # all the frames' (None: plain renders)
    for shard in range(-(-frames // every)):
        render_shard(job, shard, backgrounds)
        samples.append(
            {
                "frames": min(frames, (shard + 1) * every),
                "rss_mb": rss_bytes() / 2**20,
                "seconds": time.perf_counter() - t0,
            }
        )
    return {"family": name, "frames": frames, "rss_every": every, **memory_summary(samples)}


def memory_summary(samples: list[dict]) -> dict:
    """Growth of the resident set over a long render, from ``samples`` (first one: warm-up).

    ``rss_growth_fraction``: last sample against the first after warm-up; it
    swings with the allocator (the RSS of one render moves by +-10 % between
    samples). ``rss_growth_median_fraction``: median of the second half of
    the samples against the first half's, which a leak moves and a swing does not.
    """
    after = [s["rss_mb"] for s in samples[1:]] or [samples[0]["rss_mb"]]
    half = max(len(after) // 2, 1)
    first, second = statistics.median(after[:half]), statistics.median(after[half:] or after)
    return {
        "samples": samples,
        "rss_growth_fraction": after[-1] / after[0] - 1.0,
        "rss_growth_median_fraction": second / first - 1.0,
        "rss_peak_mb": max(s["rss_mb"] for s in samples),
        "rss_peak_first_half_mb": max(after[:half]),
        "rss_peak_second_half_mb": max(after[half:] or after),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/render.json"))
    ap.add_argument("--families", nargs="*", default=None)
    ap.add_argument("--frames", type=int, default=64)
    ap.add_argument(
        "--dataset-frames",
        type=int,
        default=0,
        help="frames of the planned dataset (amortizes differential backgrounds); 0 = --frames",
    )
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="worker processes of the parallel timing (default: the render command's)",
    )
    ap.add_argument("--memory-frames", type=int, default=2000)
    ap.add_argument("--rss-every", type=int, default=100)
    ap.add_argument("--threads", type=int, default=0, help="Dr.Jit threads (0 = all cores)")
    args = ap.parse_args()
    info = backend.describe()
    if args.threads:
        dr.set_thread_count(args.threads)
    results, skipped = [], {}
    for name in args.families or FAMILY_NAMES:
        steal0, total0 = cpu_times()
        try:
            row = bench_family(name, args.frames, args.repeats, args.dataset_frames, args.workers)
            steal1, total1 = cpu_times()
            # CPU time the hypervisor gave to other machines: timings of a
            # shared host vary with it (same code, 1.7x slower at 13 % steal)
            row["cpu_steal_fraction"] = (steal1 - steal0) / max(total1 - total0, 1)
        except Exception as err:  # a family still being written, missing SUMO, ...
            skipped[name] = f"{type(err).__name__}: {err}"
            print(f"{name}: skipped ({skipped[name][:160]})")
            continue
        results.append(row)
        print(
            f"{name}: {row['detectors']} det x {row['mask_resolution'][0]}x"
            f"{row['mask_resolution'][1]} x {row['spp']} spp (shared={row['shared_render']}, "
            f"max_depth={row['max_depth']}, {row['dtype']}): {row['frames_per_s']:.1f} frames/s, "
            f"{row['detector_samples_per_s'] / 1e6:.2f} M detector-samples/s; plain Mitsuba "
            f"{row['plain_mitsuba_frames_per_s']:.1f} frames/s; ratio {row['overhead_ratio']:.2f}; "
            f"{row['workers']} workers: {row['frames_per_s_workers']:.1f} frames/s "
            f"(CPU steal {100 * row['cpu_steal_fraction']:.0f} %)"
        )
        if row["differential"]:
            print(
                f"  differential: {row['backgrounds']} backgrounds ({row['converged_renders']} "
                f"converged renders at {row['seconds_per_converged_render']:.1f} s, "
                f"{row['seconds_per_same_seed_render']:.2f} s per C) for "
                f"{row['dataset_frames']} frames: "
                f"{row['frames_per_s_with_backgrounds']:.2f} frames/s including backgrounds"
            )
    memory = None
    if args.memory_frames > 0 and results:
        memory = bench_memory(results[0]["family"], args.memory_frames, args.rss_every)
        print(
            f"memory ({memory['family']}, {memory['frames']} frames, one process): RSS "
            f"{memory['samples'][0]['rss_mb']:.0f} -> {memory['samples'][-1]['rss_mb']:.0f} MB, "
            f"growth after warm-up {100 * memory['rss_growth_fraction']:+.1f} % (last sample), "
            f"{100 * memory['rss_growth_median_fraction']:+.1f} % (median of the second half "
            "against the first)"
        )
    report = {
        "benchmark": "bench_render",
        "machine": machine(),
        "variant": info["variant"],
        "versions": info,
        "dr_thread_count": dr.thread_count(),
        "frames": args.frames,
        "repeats": args.repeats,
        "results": results,
        "skipped": skipped,
        "memory": memory,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(strict_json.dumps(report, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
