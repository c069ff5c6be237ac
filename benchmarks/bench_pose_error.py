r"""Camera pose error: the mask-plane approximation against real re-renders.

Robust training and ``report robustness`` model a camera turned or moved off its
designed pose without rendering again: the moved camera's measurement is the
rendered transport measured through an effective mask
(:mod:`mincam_render.optics.pose`, exact for rotations, for offsets at the
plane ``pose_depth_m``). This benchmark renders workspace frames at the
designed pose and at moved poses (:func:`~mincam_render.optics.pose.posed_camera`,
the family camera's board-centre detector: a pose error is common to every
detector) and compares, for random printable masks
(:func:`~mincam_render.render.precision.measurement_relative_error`, pooled
over the frames):

* ``unmodelled``: the designed pose's transport against the moved camera's
  render: what ignoring the pose error costs;
* ``model``: the approximation (the adjoint of the effective-mask splat applied
  to the designed pose's render) against the moved camera's render;
* ``noise_floor``: two renders of the designed pose at independent seeds
  (the moved renders share the designed pose's seeds: common random numbers);
* ``model_excess``: ``sqrt(max(model^2 - noise_floor^2, 0))``, the model's
  error beyond the Monte Carlo noise (conservative: the model's input carries
  noise too);
* ``extrapolated_fraction``: the moved camera's angular weight whose content
  lies outside the rendered field (border-replicated).

Orientations of 0.5, 1, 2, 4 deg about each axis (pan, tilt, roll) and all
three at once (pan +a, tilt -a, roll +a); offsets of 1, 2, 5 cm along each axis
(right, up, forward) and all three (+c, -c, +c), modelled at the plane depths
1, 2 (the default) and 4 m, and with each frame's depth map
(:func:`~mincam_render.render.fidelity.depth_map_m`, every texel's content at
its own depth; not yet available to training). Also the cost of one draw's
splat in the mask plane (8 masks of 32x32 texels). Writes
``benchmarks/results/pose_error.json``.

Usage (2 minutes on 2 shared cores at the defaults, 12 under heavy load):
    nice -n 10 python benchmarks/bench_pose_error.py [--frames 4] [--spp 1024]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from provenance import machine, write_result  # noqa: E402

from mincam_render.optics.camera import FreeformCamera  # noqa: E402
from mincam_render.optics.fabrication import posed_masks  # noqa: E402
from mincam_render.optics.perturbation import CM, DEG, PerturbationModel  # noqa: E402
from mincam_render.optics.pose import pose_warp, posed_camera  # noqa: E402
from mincam_render.render.fidelity import depth_map_m  # noqa: E402
from mincam_render.render.precision import measurement_relative_error  # noqa: E402
from mincam_render.scenes import load_family  # noqa: E402

OUT = Path(__file__).parent / "results" / "pose_error.json"
ANGLES_DEG = (0.5, 1.0, 2.0, 4.0)
OFFSETS_CM = (1.0, 2.0, 5.0)
DEPTHS_M = (1.0, 2.0, 4.0)
#: Unit pose vectors: each axis alone, then all three.
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0), "all": (1.0, -1.0, 1.0)}
ROTATION_AXES = {"x": "pan", "y": "tilt", "z": "roll", "all": "pan+tilt+roll"}
OFFSET_AXES = {"x": "right", "y": "up", "z": "forward", "all": "right+up+forward"}


def approximated(t: np.ndarray, camera: FreeformCamera, rot: Any, off_m: Any, depths: list):
    """The moved camera's transport ``[frame, 1, R, C]`` as the model gives it.

    ``depths``: per frame, a plane depth (m) or a depth map. The adjoint of the
    library's own effective-mask splat (its gradient: the splat is linear), so
    that ``sum T_approx M = sum T posed_masks(M)``; and the mean extrapolated share.
    """
    out, extrapolated = [], []
    for frame, depth in zip(t, depths, strict=True):
        warp = pose_warp(camera, rot, off_m, depth)
        m = torch.ones((1, *frame.shape[-2:]), dtype=torch.float64, requires_grad=True)
        (posed_masks(m, warp) * torch.from_numpy(frame.astype(np.float64))).sum().backward()
        assert m.grad is not None
        out.append(m.grad.numpy())
        extrapolated.append(warp.extrapolated_fraction())
    return np.stack(out), float(np.mean(extrapolated))


def render_frames(args: argparse.Namespace) -> tuple[Any, FreeformCamera, list, list[int]]:
    """The family, its board-centre camera, its scene and the frames to render."""
    fam = load_family("workspace", seed=args.seed, num_frames=args.episode_frames)
    cam = fam.camera().centre_camera()
    scene = fam.build_scene()
    frames = np.linspace(0, args.episode_frames - 1, args.frames + 2)[1:-1].round().astype(int)
    return fam, cam, scene, frames.tolist()


def render(fam: Any, scene: Any, cam: FreeformCamera, frames: list[int], spp: int, seed: int):
    """``T[frame, 1, R, C]`` of ``cam`` at ``frames`` (W), seeds ``seed + frame``."""
    out = []
    for i in frames:
        fam.set_frame(scene, i)
        out.append(fam.render_transport(scene, cam, spp=spp, seed=seed + i))
    return np.stack(out)


def condition(errors: dict, scale: str, lo_hi: tuple[float, float]) -> dict[str, float]:
    """The figures of one moved pose (see the module docstring)."""

    def err(a: np.ndarray, b: np.ndarray) -> float:
        return measurement_relative_error(a, b, lo_hi, scale=scale)["rms"]

    floor = errors["floor"]
    model = err(errors["approx"], errors["moved"])
    return {
        "unmodelled": err(errors["nominal"], errors["moved"]),
        "model": model,
        "noise_floor": floor,
        "model_excess": float(np.sqrt(max(model**2 - floor**2, 0.0))),
        "extrapolated_fraction": errors["extrapolated"],
    }


def splat_cost_ms(cam: FreeformCamera, repeats: int = 200) -> dict[str, float]:
    """Median ms of one draw's pose step for 8 masks of 32x32 texels (numpy splat + torch)."""
    rng = np.random.default_rng(0)
    model = PerturbationModel()
    mask = torch.rand((8, 32, 32), requires_grad=True)
    build, apply = [], []
    for _ in range(repeats):
        d = model.draw(8, rng)
        t0 = time.perf_counter()
        warp = pose_warp(cam, d.pose_rotation_rad, d.pose_offset_m, d.pose_depth_m)
        t1 = time.perf_counter()
        posed_masks(mask, warp).sum().backward()
        t2 = time.perf_counter()
        build.append(t1 - t0)
        apply.append(t2 - t1)
    return {"splat_ms": 1e3 * float(np.median(build)), "apply_ms": 1e3 * float(np.median(apply))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=4, help="workspace frames (spread evenly)")
    ap.add_argument("--episode-frames", type=int, default=600)
    ap.add_argument("--spp", type=int, default=1024, help="samples per texel of every render")
    ap.add_argument("--seed", type=int, default=0, help="scene seed")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    torch.set_num_threads(1)
    t_start = time.perf_counter()
    fam, cam, scene, frames = render_frames(args)
    lo_hi, scale = cam.transmittance_range, fam.planning_error_scale
    nominal = render(fam, scene, cam, frames, args.spp, 0)
    other = render(fam, scene, cam, frames, args.spp, 10**6)
    floor = measurement_relative_error(other, nominal, lo_hi, scale=scale)["rms"]
    depth_maps = []
    for i in frames:
        fam.set_frame(scene, i)
        depth_maps.append(depth_map_m(scene, cam))
    print(f"{len(frames)} frames at {args.spp} spp; noise floor of two renders {floor:.4f}")
    base = {"nominal": nominal, "floor": floor}
    rotations = []
    for a in ANGLES_DEG:
        for axis, unit in AXES.items():
            rot = a * DEG * np.asarray(unit)  # rad
            moved = render(fam, scene, posed_camera(cam, rot, np.zeros(3)), frames, args.spp, 0)
            approx, extra = approximated(nominal, cam, rot, np.zeros(3), [2.0] * len(frames))
            r = condition(
                base | {"moved": moved, "approx": approx, "extrapolated": extra}, scale, lo_hi
            )
            rotations.append({"angle_deg": a, "axes": ROTATION_AXES[axis], **r})
            print(
                f"{a:4g} deg {ROTATION_AXES[axis]:>14}: unmodelled {r['unmodelled']:.4f}, model "
                f"{r['model']:.4f} (excess {r['model_excess']:.4f}), extrapolated "
                f"{r['extrapolated_fraction']:.3f}"
            )
    offsets = []
    for c in OFFSETS_CM:
        for axis, unit in AXES.items():
            off = c * CM * np.asarray(unit)
            moved = render(fam, scene, posed_camera(cam, np.zeros(3), off), frames, args.spp, 0)
            row: dict[str, Any] = {"offset_cm": c, "axes": OFFSET_AXES[axis], "by_depth_m": {}}
            for depth in (*DEPTHS_M, "depth_map"):
                per_frame = depth_maps if depth == "depth_map" else [depth] * len(frames)
                approx, extra = approximated(nominal, cam, np.zeros(3), off, per_frame)
                ex = {"moved": moved, "approx": approx, "extrapolated": extra}
                row["by_depth_m"][str(depth)] = condition(base | ex, scale, lo_hi)
            offsets.append(row)
            d2 = row["by_depth_m"]["2.0"]
            print(
                f"{c:4g} cm {OFFSET_AXES[axis]:>16}: unmodelled {d2['unmodelled']:.4f}, model at "
                + ", ".join(f"{d:g} m {row['by_depth_m'][str(d)]['model']:.4f}" for d in DEPTHS_M)
                + f", depth map {row['by_depth_m']['depth_map']['model']:.4f}"
            )
    cost = splat_cost_ms(fam.camera())
    print(
        f"pose step per draw (8 masks 32x32): splat {cost['splat_ms']:.3f} ms, apply+backward "
        f"{cost['apply_ms']:.3f} ms"
    )
    result = {
        "benchmark": "bench_pose_error",
        "machine": machine(),
        "command": "nice -n 10 python benchmarks/bench_pose_error.py " + " ".join(sys.argv[1:]),
        "family": "workspace",
        "scene_seed": args.seed,
        "frames": frames,
        "spp": args.spp,
        "error_scale": scale,
        "camera": {"mask_resolution": list(cam.mask_resolution), "fov_deg": cam.fov_deg},
        "nearest_depth_m": [float(d.min()) for d in depth_maps],
        "median_depth_m": [float(np.median(d)) for d in depth_maps],
        "depth_by_row_m": [np.median(d, axis=1).round(3).tolist() for d in depth_maps],
        "noise_floor": floor,
        "rotations": rotations,
        "offsets": offsets,
        "pose_step_cost": cost,
        "wall_time_s": time.perf_counter() - t_start,
    }
    write_result(args.out, result)


if __name__ == "__main__":
    main()
