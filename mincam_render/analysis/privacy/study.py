"""The privacy audit: task error against attack success, per design (:func:`analyze_privacy`).

1. Render and train as the comparison does (:func:`run_comparison`): workspace
   episodes with a roster of people, each design trained for the task (people
   count) with several seeds; the test episodes give the task error.
2. Render the full view of every frame of every episode
   (:func:`mincam_render.data.views.render_views`) and read who is present.
3. Per design and attacker seed ``i`` (attacking the design's training run
   ``i`` modulo its seeds): measure every episode through the trained design
   with sensor noise, train the decoder and the re-identification classifier on
   the training episodes (validation episode for early stopping), score both on
   each test episode.
4. Intervals over attacker seeds and test episodes
   (:mod:`mincam_render.analysis.statistics`), beside the trivial attacker
   (the mean training view; the most often present person).
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mincam_render.analysis.privacy.config import PrivacyConfig
from mincam_render.analysis.privacy.curve import corner_verdicts
from mincam_render.analysis.privacy.identities import episode_states, presence, roster_of
from mincam_render.analysis.privacy.metrics import (
    display,
    prior_scores,
    reconstruction_quality,
    reid_top1,
    white_level,
)
from mincam_render.analysis.statistics import EpisodeErrors, bootstrap_interval, converged
from mincam_render.core.seeds import stream_seed

#: The attack figures, in ``privacy.json``'s order.
FIGURES = ("psnr_db", "ssim", "reid_top1")


@dataclasses.dataclass(frozen=True)
class Episode:
    """One episode as the attacker sees it: its frames' display views and who is present."""

    name: str
    path: str
    views: np.ndarray  # display images [frame, row, col] in [0, 1]
    present: np.ndarray  # [frame, identity] 0/1


def load_episodes(
    paths: Mapping[str, str], views_dir: Path, cfg: PrivacyConfig, progress: bool
) -> dict[str, Episode]:
    """Every episode's views (rendered or reused) as display images, and its presence labels.

    The white level is the training episodes' (the attacker's own data).
    """
    from mincam_render.data.dataset import open_dataset
    from mincam_render.data.views import render_views

    raw, present = {}, {}
    for name, path in paths.items():
        a = cfg.attack
        raw[name] = np.asarray(
            render_views(path, views_dir / name, width=a.view_width, spp=a.view_spp,
                         progress=progress)
        )  # fmt: skip
        ds = open_dataset(path)
        present[name] = presence(episode_states(ds), roster_of(ds))
    white = white_level(np.concatenate([v for k, v in raw.items() if k.startswith("train-")]))
    return {k: Episode(k, paths[k], display(raw[k], white), present[k]) for k in paths}


def _intervals(
    per_seed: Sequence[Mapping[str, float]], frames: Mapping[str, int], seed: int
) -> dict[str, Any]:
    """``{"mean", "ci95"}`` of per-seed ``{episode: figure}`` (mean pooling over frames)."""
    names = sorted(frames)
    errors = EpisodeErrors(
        error=np.array([[s[e] for e in names] for s in per_seed]),
        frames=np.array([frames[e] for e in names]),
        pooling="mean",
    )
    return bootstrap_interval(errors, seed=seed).as_dict()


def _attack_once(
    run_dir: str, data: Mapping[str, Any], episodes: Mapping[str, Episode], cfg: PrivacyConfig,
    seed: int,
) -> dict[str, Any]:  # fmt: skip
    """One attacker seed against one trained design: per test episode PSNR, SSIM, top-1."""
    from mincam_render.analysis.privacy import attacks
    from mincam_render.learn.train import TrainingData

    train = TrainingData.concat([data[k] for k in sorted(data) if k.startswith("train-")])
    camera = attacks.design_camera(run_dir, train)
    x = {k: attacks.measurements(camera, d, seed=stream_seed(seed, f"noise/{k}"))
         for k, d in data.items()}  # fmt: skip
    train_names = sorted(k for k in data if k.startswith("train-"))
    xt = np.concatenate([x[k] for k in train_names])
    vt = np.concatenate([episodes[k].views for k in train_names])
    pt = np.concatenate([episodes[k].present for k in train_names])
    val = episodes["val-0"]
    decoder = attacks.train_decoder((xt, vt), (x["val-0"], val.views), cfg.attack, seed)
    ridge = attacks.fit_ridge((xt, vt), (x["val-0"], val.views))
    shape = val.views.shape[1:]
    # the attacker keeps whichever decoder reconstructs its validation episode better
    errors = {
        "mlp": float(np.mean((attacks.decode(decoder, x["val-0"], shape) - val.views) ** 2)),
        "ridge": float(np.mean((ridge.decode(x["val-0"], shape) - val.views) ** 2)),
    }
    kind = min(errors, key=errors.__getitem__)

    def reconstruct(xs: np.ndarray) -> np.ndarray:
        return attacks.decode(decoder, xs, shape) if kind == "mlp" else ridge.decode(xs, shape)

    reid = attacks.train_reid((xt, pt), (x["val-0"], val.present), cfg.attack, seed)
    out: dict[str, Any] = {"episodes": {}, "examples": {}, "decoder": kind,
                           "decoder_val_mse": errors, "ridge_penalty": ridge.penalty}  # fmt: skip
    for name in sorted(k for k in data if k.startswith("test-")):
        ep = episodes[name]
        recon = reconstruct(x[name])
        quality = reconstruction_quality(ep.views, recon)
        top1 = reid_top1(reid.predict(x[name]), ep.present)
        out["episodes"][name] = {**quality, "reid_top1": top1}
        out["examples"][name] = recon
    out["convergence"] = {"decoder": converged(decoder.history), "reid": converged(reid.history)}
    return out


def trivial_attack(episodes: Mapping[str, Episode]) -> dict[str, dict[str, float]]:
    """Per test episode: the mean training view's PSNR/SSIM, the prior's top-1 accuracy."""
    train = [e for k, e in episodes.items() if k.startswith("train-")]
    mean_view = np.concatenate([e.views for e in train]).mean(axis=0)
    present = np.concatenate([e.present for e in train])
    out = {}
    for name, ep in episodes.items():
        if not name.startswith("test-"):
            continue
        guess = np.broadcast_to(mean_view, ep.views.shape)
        scores = prior_scores(present, len(ep.present))
        out[name] = {**reconstruction_quality(ep.views, guess),
                     "reid_top1": reid_top1(scores, ep.present)}  # fmt: skip
    return out


def attack_design(
    design: Mapping[str, Any], data: Mapping[str, Any], episodes: Mapping[str, Episode],
    cfg: PrivacyConfig, name: str,
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:  # fmt: skip
    """Every attacker seed against one design: figures with intervals, the first seed's examples."""
    runs = design["runs"]
    per_seed, conv, decoders, examples = [], [], [], {}
    for i in range(cfg.attack.seeds):
        seed = stream_seed(cfg.comparison.seed, f"attack/{name}", i)
        res = _attack_once(runs[i % len(runs)], data, episodes, cfg, seed)
        per_seed.append(res["episodes"])
        conv.append(res["convergence"])
        decoders.append({k: res[k] for k in ("decoder", "decoder_val_mse", "ridge_penalty")})
        if i == 0:
            examples = res["examples"]
    frames = {k: len(episodes[k].views) for k in per_seed[0]}
    figures = {
        f: _intervals([{e: s[e][f] for e in s} for s in per_seed], frames, cfg.comparison.seed)
        for f in FIGURES
    }
    return {**figures, "per_seed": per_seed, "convergence": conv, "decoders": decoders}, examples


def _write_examples(
    path: Path, episode: Episode, recon: Mapping[str, np.ndarray], count: int
) -> None:
    """``count`` occupied frames of ``episode`` (evenly spaced): true views and reconstructions."""
    occupied = np.flatnonzero(episode.present.any(axis=1))
    pool = occupied if len(occupied) >= count else np.arange(len(episode.views))
    frames = pool[np.linspace(0, len(pool) - 1, min(count, len(pool))).astype(int)]
    np.savez_compressed(
        path,
        frames=frames,
        true=episode.views[frames],
        designs=np.array(list(recon)),
        recon=np.stack([recon[n][frames] for n in recon]),
    )


def analyze_privacy(
    cfg: PrivacyConfig, out_dir: str | os.PathLike, *, workers: int = 2, progress: bool = False
) -> dict[str, Any]:
    """Run the audit (module docstring) into ``out_dir``; ``privacy.json``'s contents.

    Writes ``out_dir/privacy.json`` and ``out_dir/examples.npz`` (true test views
    and each design's reconstructions of a few test frames, for the report).
    """
    from mincam_render.analysis.comparison import render_episodes, run_comparison

    out = Path(out_dir)
    result = run_comparison(cfg.comparison, out, workers=workers, progress=progress)
    data = render_episodes(cfg.comparison, out / "episodes", workers=workers, progress=False)
    paths = {k: v["dataset"] for k, v in result["episodes"].items()}
    episodes = load_episodes(paths, out / "views", cfg, progress)
    designs, examples = {}, {}
    for name, d in result["designs"].items():
        attack, ex = attack_design(d, data, episodes, cfg, name)
        designs[name] = {
            "pixels": d["model"]["pixels"],
            "task_error": d["error"],
            "task_state": d["state"],
            "task_seeds": len(d["runs"]),
            **attack,
        }
        examples[name] = ex["test-0"]
    trivial = trivial_attack(episodes)
    frames = {k: len(episodes[k].views) for k in trivial}
    privacy = {
        "task": result["task"],
        "error_name": result["error_name"],
        "config": json.loads(json.dumps(dataclasses.asdict(cfg), default=str)),
        "roster": int(episodes["test-0"].present.shape[1]),
        "episodes": result["episodes"],
        "designs": designs,
        "trivial": {
            "task_error": result["trivial"]["error"],
            **{
                f: _intervals([{e: trivial[e][f] for e in trivial}], frames, cfg.comparison.seed)
                for f in FIGURES
            },
            "episodes": trivial,
        },  # fmt: skip
        "comparison": str(out / "metrics.json"),
    }
    privacy["corner"] = corner_verdicts(privacy)
    _write_examples(out / "examples.npz", episodes["test-0"], examples, cfg.attack.examples)
    (out / "privacy.json").write_text(json.dumps(privacy, indent=2, default=str) + "\n")
    return privacy
