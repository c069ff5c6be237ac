"""Helpers shared by test modules (importable: pytest puts this folder on sys.path).

Fixtures live in ``conftest.py``; plain functions that build test data or run
the command line live here.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.data.render_job import RenderRequest
from mincam_render.learn import train as tr
from mincam_render.optics.camera import MM, DetectorLayout, FreeformCamera
from mincam_render.optics.perturbation import PerturbationModel

REPO = Path(__file__).resolve().parents[1]
COUNT = LabelSpec(name="count", kind=LabelKind.COUNT, median_filter_s=0.0)
CHANGE = LabelSpec(name="change", kind=LabelKind.REGRESSION, median_filter_s=0.0)
#: 2 patches detectors at 8x8 texels (the overrides of the shared tiny datasets).
TINY_CAMERA = {"camera": {"detectors": 2, "mask_resolution": 8}}
#: The shared tiny dataset (``conftest.tiny_patches``): 24 patches frames in 3
#: shards of 8, 2 spp, rendered per detector and stored as float32 (so a frame
#: equals ``render_transport`` of its seed), splits train 0-17, val 17-20, test 20-24.
TINY_PATCHES = RenderRequest(
    family="patches",
    num_frames=24,
    seed=1,
    overrides=TINY_CAMERA,
    shard_frames=8,
    spp=2,
    shared_render=False,
    dtype="float32",
)
#: The shared differential dataset (``conftest.differential_dataset``): 24 s of
#: the workspace at 1 fps, backgrounds every 10 s, 3 shards of 8.
TINY_DIFFERENTIAL = RenderRequest(
    family="workspace",
    num_frames=24,
    shard_frames=8,
    overrides={"fps": 1.0, "camera": {"mask_resolution": 8, "detectors": 2}},
    spp=2,
    max_depth=3,
    shared_render=False,
    dtype="float32",
    differential=True,
    background_interval_s=10.0,
    background_spp=8,
    shared_difference=True,
)


def linear_task(
    n: int = 200,
    k: int = 2,
    res: int = 8,
    seed: int = 0,
    *,
    scale: float = 2e-8,
    background_w: float = 2e-9,
    dead: int | None = None,
) -> tr.TrainingData:
    """Frames whose count is a linear function of the top half of detector 0's image.

    Args:
        n: frames; k: detectors; res: mask texels per side.
        scale: power of a fully lit texel (W); background_w: uniform extra power
            per texel, up to this (W, 0 draws nothing); dead: a detector set dark.
    """
    rng = np.random.default_rng(seed)
    cam = FreeformCamera(
        mask_resolution=(res, res), layout=DetectorLayout.row(count=k, pitch_m=20 * MM)
    )
    base = rng.uniform(0.0, 1.0, (n, 1, res, res)).astype(np.float32)
    t = np.repeat(base, k, axis=1) * np.float32(scale)
    if background_w > 0:
        t += rng.uniform(0, background_w, t.shape).astype(np.float32)
    if dead is not None:
        t[:, dead] = 0.0
    signal = base[:, 0, : res // 2].mean(axis=(1, 2)) - base[:, 0, res // 2 :].mean(axis=(1, 2))
    count = np.clip(np.rint(5 + 40 * signal), 0, None).astype(np.float32)[:, None]
    return tr.TrainingData(
        transport=t,
        labels={"count": count},
        label_specs=(COUNT,),
        camera=cam,
        fps=30.0,
        source={"family": "synthetic"},
    )


#: A binary label beside the linear task's count (:func:`two_task_episode`).
BRIGHT_LEFT = LabelSpec(name="bright_left", kind=LabelKind.BINARY, median_filter_s=0.0)


def two_task_episode(n: int, seed: int) -> tr.TrainingData:
    """The linear count task plus a binary label of the left half's brightness (two tasks)."""
    data = linear_task(n, k=2, res=4, seed=seed)
    left = np.asarray(data.transport[:, 0, :, :2].mean(axis=(1, 2)))
    side = (left > np.median(left)).astype(np.float32)[:, None]
    return tr.TrainingData(
        transport=data.transport,
        labels={**data.labels, "bright_left": side},
        label_specs=(*data.label_specs, BRIGHT_LEFT),
        camera=data.camera,
        fps=data.fps,
        source={"family": "synthetic", "seed": seed},
    )


def cli_process(args: list[str], env: dict | None = None, **kw) -> subprocess.Popen:
    """``mincam-render ARGS`` in a subprocess of this interpreter (text pipes)."""
    return subprocess.Popen(
        [sys.executable, "-m", "mincam_render.cli.main", *args],
        env=dict(os.environ, PYTHONPATH=str(REPO), **(env or {})),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


def temporal_task(
    n: int = 400, k: int = 2, res: int = 4, seed: int = 0, *, history: int = 12, lag: int = 6
) -> tr.TrainingData:
    """Frames whose label is how much a scene brightness changed over the last ``lag`` frames.

    The brightness ``s[t]`` is a smooth random walk lighting all of detector 0's
    image; the REGRESSION label at frame ``t`` is ``s[t] - s[t - lag]``, which no
    single frame shows: a head must read the history (``history > lag``).
    """
    rng = np.random.default_rng(seed)
    cam = FreeformCamera(
        mask_resolution=(res, res), layout=DetectorLayout.row(count=k, pitch_m=20 * MM)
    )
    s = 1.0 + 0.5 * np.sin(np.cumsum(rng.normal(0.0, 0.3, n)))
    t = np.repeat(s[:, None, None, None], k, axis=1) * np.ones((1, 1, res, res))
    t = (t * 2e-8 + rng.uniform(0, 2e-10, (n, k, res, res))).astype(np.float32)
    change = np.zeros(n, np.float32)
    change[lag:] = s[lag:] - s[:-lag]
    return tr.TrainingData(
        transport=t,
        labels={"change": change[:, None]},
        label_specs=(CHANGE,),
        camera=cam,
        fps=30.0,
        history=history,
        source={"family": "synthetic-temporal"},
    )


#: Debian's Chromium, for the reports' headless-browser checks.
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
needs_chromium = pytest.mark.skipif(
    not CHROMIUM.is_file(),
    reason="Debian's Chromium is not installed at /usr/bin/chromium "
    "(apt-get install -y chromium) : the headless-browser check cannot run",
)


def chromium(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    """Run Debian's headless Chromium with ``args`` and a fresh profile in ``tmp_path``."""
    profile = tmp_path / "chromium-profile"
    profile.mkdir(exist_ok=True)
    return subprocess.run(
        [str(CHROMIUM), *CHROMIUM_FLAGS, f"--user-data-dir={profile}", *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


#: The recipe of the shared runs (``conftest.runs_of_each_kind``): 20 steps, no early stop.
RUN_CONFIG = tr.TrainConfig(max_steps=20, batch_size=16, eval_every=10, patience=100)
#: kind -> (temporal data?, ``train_run`` keyword arguments) of the shared runs.
RUN_KINDS = {
    "mincam": (False, {"pixels": 2}),
    "baseline": (False, {"baseline_grid": (2, 2)}),
    "tcn": (False, {"pixels": 2, "config": replace(RUN_CONFIG, head=tr.HeadKind.TCN)}),
    "temporal": (True, {"pixels": 2}),
    "temporal-tcn": (True, {"pixels": 2, "config": replace(RUN_CONFIG, head=tr.HeadKind.TCN)}),
    "robust": (
        False,
        {"pixels": 2, "config": replace(RUN_CONFIG, perturbation=PerturbationModel())},
    ),
    "privacy": (False, {"pixels": 2, "config": replace(RUN_CONFIG, privacy_weight=1.0)}),
    "head-24": (False, {"pixels": 2, "config": replace(RUN_CONFIG, head_hidden=24)}),
    "baseline-head-24": (
        False,
        {"baseline_grid": (2, 2), "config": replace(RUN_CONFIG, head_hidden=24)},
    ),
    "baseline-linear-2": (
        False,
        {"baseline_grid": (2, 2), "config": replace(RUN_CONFIG, head_bottleneck=2)},
    ),
    # one signed pixel: both detectors of the data, one output
    "signed": (False, {"pixels": 1, "config": replace(RUN_CONFIG, signed_pixels=True)}),
}


def run_splits(temporal: bool) -> tuple[tr.TrainingData, tr.TrainingData, tr.TrainingData]:
    """Train, validation and test splits (60/20/20 %) of 160 synthetic frames."""
    data = temporal_task(160) if temporal else linear_task(160)
    return data.split((0.6, 0.2, 0.2))
