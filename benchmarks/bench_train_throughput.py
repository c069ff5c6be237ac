"""Training throughput: samples/s of the minimalist-camera training step.

Side by side, in the same run and on the same data (transport images read from
a dataset on disk when ``--dataset`` is given, else random frames in memory of
the same shape):

* ours: :class:`mincam_render.models.MincamCamera` (Dr.Jit mask-plane op via
  ``dr.wrap``, the sensor model, the head) through ``train_model``'s step
  (Adam, gain augmentation, noise);
* peer: a **reimplementation** (written here, not the paper authors' code) of
  the camera model of the paper's published training code as described in the
  paper: sigmoid-bounded masks as a plain ``torch`` linear layer applied to the
  flattened image, the same sensor noise and leaky saturation written in torch,
  and the same head and optimiser.

Both are checked to give the same noiseless pixel values before timing; each
is warmed up, then timed over several repeats (median and spread). Prints the
figures and writes ``benchmarks/results/train_throughput.json`` (machine, git
revision, training set size, wall time).

Usage:
    PYTHONPATH=. python benchmarks/bench_train_throughput.py [--dataset DIR]
        [--pixels 8] [--res 32] [--batch-size 64] [--steps 100] [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from bench_patches_paper import machine  # noqa: E402

from mincam_render import train as tr  # noqa: E402
from mincam_render.camera import MM, DetectorLayout, FreeformCamera  # noqa: E402
from mincam_render.generators.base import LabelKind, LabelSpec  # noqa: E402
from mincam_render.models import Head  # noqa: E402


class PaperStyleCamera(torch.nn.Module):
    """Reimplementation: masks as a linear layer on the flattened image (all torch)."""

    def __init__(self, mincam) -> None:
        super().__init__()
        self.cam = mincam.camera
        self.detectors = mincam.detectors
        self.weight = torch.nn.Parameter(
            mincam.logits.detach().clone().reshape(mincam.num_pixels, -1)
        )
        self.head = Head(mincam.head.in_features, mincam.head.label_specs)
        self.head.load_state_dict(mincam.head.state_dict())

    def measure(self, t, *, gain=None, noise=True, generator=None):
        b = t.shape[0]
        # the paper's camera sees one image; each pixel k dots it with its mask
        x = t[:, 0].index_select(1, self.detectors).reshape(b, len(self.detectors), -1)
        lo, hi = self.cam.transmittance_range
        m = lo + (hi - lo) * torch.sigmoid(self.weight)
        p = (x * m[None]).sum(-1)  # a linear layer per pixel on the flattened image
        if gain is not None:
            p = p * gain[:, None]
        e = self.cam.electronics
        cur = e.responsivity_a_per_w * p
        v = e.gain_v_per_a * cur
        if noise:
            kw = {"generator": generator}
            v = (
                v
                + e.gain_v_per_a
                * torch.sqrt(1.602e-19 * cur.clamp(min=1e-30) / e.integration_time_s)
                * torch.randn(v.shape, **kw)
                + e.read_noise_v * torch.randn(v.shape, **kw)
                + e.lsb_v * torch.rand(v.shape, **kw)
            )
        over = v - e.full_scale_v
        return torch.where(over > 0, e.full_scale_v + e.saturation_slope * over, v)[:, None]

    def forward(self, t, *, gain=None, noise=True, generator=None):
        return self.head(self.measure(t, gain=gain, noise=noise, generator=generator)[:, 0])


def step_rate(model, data, batch, steps, repeats):
    """Median samples/s of forward+backward+Adam over ``repeats`` runs of ``steps`` steps."""
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    src = tr.DatasetBatches(data, batch)
    g = torch.Generator().manual_seed(0)
    from mincam_render.models import task_loss

    def run(n):
        for _ in range(n):
            t, y = src.next(g)
            gain = 0.8 + 0.4 * torch.rand(len(t), generator=g)
            loss, _ = task_loss(model.head, model(t, gain=gain, generator=g), y)
            opt.zero_grad()
            loss.backward()
            opt.step()

    run(10)  # warm-up: Dr.Jit kernel compilation, allocator
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run(steps)
        rates.append(steps * batch / (time.perf_counter() - t0))
    return rates


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dataset", type=Path, default=None)
    ap.add_argument("--pixels", type=int, default=8)
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--frames", type=int, default=2000)
    ap.add_argument("--batch-size", type=int, default=64)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    t_start = time.perf_counter()
    if a.dataset is not None:
        from mincam_render.dataset import open_dataset

        data = tr.TrainingData.from_dataset(open_dataset(a.dataset), "train")
        source = str(a.dataset)
    else:
        rng = np.random.default_rng(0)
        cam = FreeformCamera(
            mask_resolution=(a.res, a.res),
            layout=DetectorLayout.grid(rows=2, cols=-(-a.pixels // 2), pitch_m=20 * MM),
        )
        t = rng.uniform(0, 1e-9, (a.frames, cam.num_detectors, a.res, a.res)).astype(np.float32)
        data = tr.TrainingData(
            transport=t,
            labels={"count": rng.integers(0, 10, (a.frames, 1)).astype(np.float32)},
            label_specs=(LabelSpec(name="count", kind=LabelKind.COUNT),),
            camera=cam,
            fps=30.0,
        )
        source = "random frames in memory"
    ours = tr.build_mincam(data, a.pixels)
    peer = PaperStyleCamera(ours)
    t, _ = data.batch(np.arange(16))
    v_ours = ours.measure(t, noise=False)
    v_peer = peer.measure(t, noise=False)
    torch.testing.assert_close(v_ours, v_peer, rtol=1e-4, atol=1e-9)  # same model
    r_ours = step_rate(ours, data, a.batch_size, a.steps, a.repeats)
    r_peer = step_rate(peer, data, a.batch_size, a.steps, a.repeats)
    res = {
        "machine": machine(),
        "data": source,
        "train_samples": len(data),
        "pixels": a.pixels,
        "mask_resolution": list(data.camera.mask_resolution),
        "batch_size": a.batch_size,
        "steps_per_repeat": a.steps,
        "torch_threads": a.threads,
        "ours_samples_per_s": {"median": statistics.median(r_ours), "all": r_ours},
        "peer_reimplementation_samples_per_s": {"median": statistics.median(r_peer), "all": r_peer},
        "ratio_ours_over_peer": statistics.median(r_ours) / statistics.median(r_peer),
        "wall_time_s": time.perf_counter() - t_start,
        "note": "peer = our reimplementation of the paper's camera model (torch linear layer "
        "on the flattened image with sigmoid masks), not the authors' code",
    }
    print(
        f"{a.pixels} pixels, {a.res}x{a.res} texels, batch {a.batch_size}, "
        f"{a.threads} torch thread(s), data: {source} ({len(data)} samples)"
    )
    print(
        f"  ours (Dr.Jit mask plane): {res['ours_samples_per_s']['median']:9.0f} samples/s "
        f"(min {min(r_ours):.0f}, max {max(r_ours):.0f})"
    )
    print(
        f"  peer (torch reimpl.)    : {res['peer_reimplementation_samples_per_s']['median']:9.0f}"
        f" samples/s (min {min(r_peer):.0f}, max {max(r_peer):.0f})"
    )
    print(f"  ratio ours / peer: {res['ratio_ours_over_peer']:.2f}")
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "train_throughput.json"
    path.write_text(json.dumps(res, indent=2, default=str))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
