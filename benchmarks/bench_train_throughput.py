r"""Training throughput: samples/s of our training step against a fast plain-torch peer.

Side by side, in the same run, on the same data, one row per configuration:

* ours: :func:`mincam_render.learn.train.train_step` -- the exact step ``train_model``
  runs (batch from :class:`~mincam_render.learn.train.DatasetBatches`, random gain,
  :class:`~mincam_render.learn.models.MincamCamera` with sensor noise, the task loss,
  backward, Adam, the logit projection; batches gathered into a reused buffer,
  temporal batches whose windows cover most frames measured over the stored
  frames in place);
* peer: a plain-torch step written here for speed, independently of the
  package's camera: the transport held in its own ``(K, F, N)`` float32 layout,
  the batch gathered with one ``index_select``, the masks applied by ``bmm``,
  the same electronics (gain, shot + read noise, uniform quantisation, leaky
  saturation) written inline, the same :class:`~mincam_render.learn.models.Head` and
  loss, fused Adam with the same learning rates. Temporal rows give the peer
  the same shared-frame trick (each frame of the batch's union measured once).

Both are checked to give the same noiseless measurements before timing; each
is warmed up, then the two are timed over several repeats (median, all
repeats kept), alternating every ``steps / CHUNKS`` steps within a repeat.
Rows: K in {1, 8, 16} x batch in {64, 256} x mask 32^2, 64^2 on random
frames in memory; one row training from an on-disk
workspace dataset (float16, memory-mapped); one temporal traffic row (history
30, forward differences). Also the evaluation share of training wall time at
the default settings. Writes ``benchmarks/results/train_throughput.json``
(machine, git revision, rows, ratios, floors).

Usage (render the two datasets once, then run from a clean tree):
    mincam-render render workspace --frames 512 --fidelity full --spp 1 \
        --detectors 8 --mask-res 32 --dtype float16 --out /tmp/ws16
    mincam-render render traffic --frames 600 --fidelity full --spp 1 \
        --detectors 8 --mask-res 32 --dtype float16 --out /tmp/traffic16
    flock /tmp/mincam_bench.lock python benchmarks/bench_train_throughput.py \
        --dataset /tmp/ws16 --temporal-dataset /tmp/traffic16 [--steps 200] [--repeats 5]
"""

from __future__ import annotations

import argparse
import copy
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from provenance import machine  # noqa: E402

from mincam_render.core import strict_json
from mincam_render.core.labels import LabelKind, LabelSpec  # noqa: E402
from mincam_render.data.dataset import open_dataset  # noqa: E402
from mincam_render.learn import train as tr  # noqa: E402
from mincam_render.learn.models import task_loss, temporal_features  # noqa: E402
from mincam_render.optics.camera import MM, DetectorLayout, FreeformCamera  # noqa: E402
from mincam_render.optics.sensor import ELEMENTARY_CHARGE_C  # noqa: E402

#: Each repeat alternates ours and the peer this many times (``steps / CHUNKS``
#: steps each): with whole repeats alternated (200 steps, 0.25 s at 1 px), the
#: other core's bursts of load moved single rows by +-25 % from repeat to repeat.
CHUNKS = 10

#: Floors of issue 15.
MIN_RATIO = 1.0
MIN_ON_DISK_SAMPLES_PER_S = 25_000
MIN_TEMPORAL_SAMPLES_PER_S = 2_000


class PlainTorchPeer:
    """A fast plain-torch training step (index_select + bmm on (K, B, N)), independent code."""

    def __init__(self, data: tr.TrainingData, ours, batch_size: int, config: tr.TrainConfig):
        f = len(data.transport)
        k = ours.num_pixels
        watts = data.frames_np(0, f)[:, ours.detectors.numpy()]  # [F, K, R, C] float32
        self.t_kfn = torch.from_numpy(watts.reshape(f, k, -1).transpose(1, 0, 2).copy())
        self.labels = {n: torch.from_numpy(np.ascontiguousarray(v)) for n, v in data.labels.items()}
        self.logits = torch.nn.Parameter(ours.logits.detach().clone().reshape(k, -1))
        self.head = copy.deepcopy(ours.head)
        self.lo, self.hi = data.camera.transmittance_range
        self.e = data.camera.electronics
        self.k, self.b, self.h, self.n = k, batch_size, data.history, len(data)
        self.gain_range = config.gain_range
        lr = tr.learning_rate_for(self.head.in_features)
        self.opt = torch.optim.Adam(
            [
                {"params": list(self.head.parameters()), "lr": lr},
                {"params": [self.logits], "lr": config.mask_lr},
            ],
            fused=True,
        )

    def volts(self, idx, gain, noise, g):
        """``[B, H, K]`` volts of windows starting at ``idx``."""
        e = self.e
        if self.h > 1:
            frames, win = torch.unique(
                idx[:, None] + torch.arange(self.h), sorted=True, return_inverse=True
            )
        else:
            frames, win = idx, None
        x = self.t_kfn.index_select(1, frames)  # (K, U, N)
        m = self.lo + (self.hi - self.lo) * torch.sigmoid(self.logits)
        p = torch.bmm(m.unsqueeze(1), x.transpose(1, 2)).reshape(self.k, -1).t()  # (U, K)
        p = p[:, None] if win is None else p[win]  # (B, H, K)
        if gain is not None:
            p = p * gain[:, None, None]
        v = p * (e.gain_v_per_a * e.responsivity_a_per_w) + e.gain_v_per_a * e.dark_current_a
        if noise:
            c = e.gain_v_per_a * ELEMENTARY_CHARGE_C / e.integration_time_s
            sigma = torch.sqrt(torch.clamp(v * c + e.read_noise_v**2, min=1e-30))
            v = (
                v
                + sigma * torch.randn(v.shape, generator=g)
                + e.lsb_v * torch.rand(v.shape, generator=g)
            )
        over = torch.relu(v - e.full_scale_v)
        return v - (1.0 - e.saturation_slope) * over

    def step(self, g):
        idx = torch.randint(0, self.n, (self.b,), generator=g)
        gain = torch.empty(self.b).uniform_(*self.gain_range, generator=g)
        x = temporal_features(self.volts(idx, gain, True, g))
        y = {n: v.index_select(0, idx + (self.h - 1)) for n, v in self.labels.items()}
        loss, _ = task_loss(self.head, self.head(x), y)
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        self.opt.step()
        return loss


def random_data(pixels: int, res: int, frames: int, seed: int = 0) -> tr.TrainingData:
    rng = np.random.default_rng(seed)
    cam = FreeformCamera(
        mask_resolution=(res, res),
        layout=DetectorLayout.grid(
            rows=1 if pixels < 2 else 2, cols=-(-pixels // 2), pitch_m=20 * MM
        ),
    )
    t = rng.uniform(0, 1e-9, (frames, cam.num_detectors, res, res)).astype(np.float32)
    return tr.TrainingData(
        transport=t,
        labels={"count": rng.integers(0, 10, (frames, 1)).astype(np.float32)},
        label_specs=(LabelSpec(name="count", kind=LabelKind.COUNT),),
        camera=cam,
        fps=30.0,
    )


def measure_row(data, pixels, batch, steps, repeats, config) -> dict:
    """Ours and the peer on ``data``: samples/s (median of ``repeats``) and their ratio."""
    ours = tr.build_mincam(data, pixels)
    peer = PlainTorchPeer(data, ours, batch, config)
    idx = torch.arange(min(16, len(data)))
    b = data.sample(idx)
    v_ours = ours.measure(**b.inputs(), noise=False)
    v_peer = peer.volts(idx, None, False, None)
    torch.testing.assert_close(v_ours, v_peer, rtol=2e-5, atol=1e-7)  # the same camera
    opt = tr.build_optimizer(ours, config)
    src = tr.DatasetBatches(data, batch)
    g_ours, g_peer = torch.Generator().manual_seed(0), torch.Generator().manual_seed(0)

    def run_ours(n):
        for _ in range(n):
            tr.train_step(ours, src, opt, g_ours, config.gain_range)

    def run_peer(n):
        for _ in range(n):
            peer.step(g_peer)

    run_ours(10)  # warm-up: allocator, first-touch of the memory map
    run_peer(10)
    r_ours, r_peer = [], []
    chunk = max(1, steps // CHUNKS)
    for _ in range(repeats):
        seconds = {run_ours: 0.0, run_peer: 0.0}
        for _ in range(CHUNKS):  # interleaved finely, so a burst of load hits both
            for run in seconds:
                t0 = time.perf_counter()
                run(chunk)
                seconds[run] += time.perf_counter() - t0
        r_ours.append(CHUNKS * chunk * batch / seconds[run_ours])
        r_peer.append(CHUNKS * chunk * batch / seconds[run_peer])
    m_ours, m_peer = statistics.median(r_ours), statistics.median(r_peer)
    return {
        "pixels": pixels,
        "mask_resolution": list(data.camera.mask_resolution),
        "batch_size": batch,
        "history": data.history,
        "ours_samples_per_s": {"median": m_ours, "all": r_ours},
        "peer_samples_per_s": {"median": m_peer, "all": r_peer},
        "ratio_ours_over_peer": m_ours / m_peer,
    }


def evaluation_share(train, val, steps: int) -> dict:
    """Evaluation's share of training wall time with ``TrainConfig()`` defaults."""
    cfg = tr.TrainConfig()
    model = tr.build_mincam(train, 8)
    opt = tr.build_optimizer(model, cfg)
    src = tr.DatasetBatches(train, cfg.batch_size)
    g = torch.Generator().manual_seed(0)
    for _ in range(10):
        tr.train_step(model, src, opt, g, cfg.gain_range)
    t0 = time.perf_counter()
    for _ in range(steps):
        tr.train_step(model, src, opt, g, cfg.gain_range)
    step_s = (time.perf_counter() - t0) / steps
    t0 = time.perf_counter()
    tr.predict(model, val, limit=cfg.max_eval_samples)
    eval_s = time.perf_counter() - t0
    share = eval_s / (eval_s + cfg.eval_every * step_s)
    return {
        "eval_every": cfg.eval_every,
        "val_samples": min(len(val), cfg.max_eval_samples),
        "step_s": step_s,
        "eval_s": eval_s,
        "eval_share_of_wall_time": share,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dataset", type=Path, required=True, help="workspace, 8 px, 32x32")
    ap.add_argument("--temporal-dataset", type=Path, required=True, help="traffic, 8 px")
    ap.add_argument("--frames", type=int, default=512, help="random frames in memory")
    ap.add_argument("--steps", type=int, default=200, help="steps per timed repeat")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    t_start = time.perf_counter()
    config = tr.TrainConfig()
    rows = []
    for res in (32, 64):
        for pixels in (1, 8, 16):
            data = random_data(pixels, res, a.frames)
            for batch in (64, 256):
                row = measure_row(data, pixels, batch, a.steps, a.repeats, config)
                rows.append({"data": "random frames in memory (float32)", **row})
                print_row(rows[-1])
    ds = open_dataset(a.dataset)
    train = tr.TrainingData.from_dataset(ds, "train")
    disk = measure_row(train, 8, 64, a.steps, a.repeats, config)
    disk = {
        "data": f"{a.dataset} ({ds.family}, {train.transport.dtype}, memory-mapped shards)",
        **disk,
    }
    rows.append(disk)
    print_row(disk)
    tds = open_dataset(a.temporal_dataset)
    temporal_train = tr.TrainingData.from_dataset(tds, "train")
    temporal = measure_row(temporal_train, 8, 64, max(a.steps // 2, 5), a.repeats, config)
    temporal = {
        "data": f"{a.temporal_dataset} ({tds.family}, {temporal_train.transport.dtype}, "
        f"history {temporal_train.history}, forward differences)",
        **temporal,
    }
    rows.append(temporal)
    print_row(temporal)
    share = evaluation_share(train, tr.TrainingData.from_dataset(ds, "val"), 200)
    print(f"evaluation: {100 * share['eval_share_of_wall_time']:.1f} % of training wall time")
    min_ratio = min(r["ratio_ours_over_peer"] for r in rows)
    res = {
        "machine": machine(),
        "torch_threads": a.threads,
        "steps_per_repeat": a.steps,
        "repeats": a.repeats,
        "alternations_per_repeat": CHUNKS,
        "rows": rows,
        "min_ratio_ours_over_peer": min_ratio,
        "on_disk_8px_32_batch64_samples_per_s": disk["ours_samples_per_s"]["median"],
        "temporal_8px_history30_samples_per_s": temporal["ours_samples_per_s"]["median"],
        "evaluation": share,
        "floors": {
            "min_ratio_ours_over_peer": MIN_RATIO,
            "on_disk_8px_32_batch64_samples_per_s": MIN_ON_DISK_SAMPLES_PER_S,
            "temporal_8px_history30_samples_per_s": MIN_TEMPORAL_SAMPLES_PER_S,
        },
        "wall_time_s": time.perf_counter() - t_start,
        "note": "peer = plain-torch step written in this benchmark for speed (index_select + "
        "bmm on (K, B, N), same electronics, head, loss, fused Adam); temporal samples are "
        "windows (each sample 30 frames)",
    }
    print(
        f"min ratio {min_ratio:.2f}; on disk {res['on_disk_8px_32_batch64_samples_per_s']:.0f} "
        f"samples/s; temporal {res['temporal_8px_history30_samples_per_s']:.0f} windows/s"
    )
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "train_throughput.json"
    path.write_text(strict_json.dumps(res, indent=2) + "\n")
    print(f"wrote {path}")


def print_row(r: dict) -> None:
    print(
        f"K={r['pixels']:2d} {r['mask_resolution'][0]}^2 batch {r['batch_size']:3d} "
        f"history {r['history']:2d}: ours {r['ours_samples_per_s']['median']:8.0f}  "
        f"peer {r['peer_samples_per_s']['median']:8.0f}  ratio {r['ratio_ours_over_peer']:.2f}"
        f"  [{r['data'][:40]}]",
        flush=True,
    )


if __name__ == "__main__":
    main()
