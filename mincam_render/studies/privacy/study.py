"""The privacy audit: task error against attack success, per design (:func:`run`).

1. Render and train as the comparison does (its ``run``): workspace
   episodes with a roster of people, each design trained for the task (people
   count) with several seeds; the test episodes give the task error.
2. Render the full view of every frame of every episode and its background
   (the frame with its people removed; :func:`mincam_render.data.views.render_views`),
   the foreground mask between them, and read who is present.
3. Per design and attacker seed ``i`` (attacking the design's training run
   ``i`` modulo its seeds): measure every episode through the trained design
   with sensor noise, train the decoders of the people (:mod:`.decoders`; the
   attacker keeps the one of the lowest validation error) and the
   re-identification classifier on the training episodes (validation episode
   for early stopping), score both on each test episode: PSNR and SSIM on the
   foreground and on the whole view, top-1 re-identification.
4. Intervals over attacker seeds and test episodes
   (:mod:`mincam_render.analysis.statistics`), beside the trivial attacker
   (each frame's background: it sees no one; the most often present person)
   and the prior (the background plus where people usually are, the read-out
   ignored), and each design's people PSNR gain over both, paired on the test
   episodes.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.analysis.statistics import (
    EpisodeErrors,
    Interval,
    Pooling,
    bootstrap_interval,
    converged,
    paired_difference,
)
from mincam_render.core import strict_json
from mincam_render.core.seeds import stream_seed
from mincam_render.studies.privacy.config import DecoderKind, PrivacyConfig
from mincam_render.studies.privacy.curve import rederive_verdicts
from mincam_render.studies.privacy.identities import episode_states, presence, roster_of
from mincam_render.studies.privacy.metrics import (
    display,
    foreground_mask,
    foreground_quality,
    prior_scores,
    reid_top1,
    white_level,
)
from mincam_render.studies.privacy.result import (
    FIGURES,
    IMAGE_FIGURES,
    AttackConvergence,
    AttackerSeed,
    AttackFigures,
    DecoderChoice,
    DesignAttack,
    DesignAudit,
    EpisodeScores,
    PriorAudit,
    PrivacyResult,
    TrivialAudit,
)

if TYPE_CHECKING:
    from mincam_render.learn.training_data import TrainingData
    from mincam_render.studies.privacy.decoders import Decoder

__all__ = ["FIGURES", "IMAGE_FIGURES", "Episode", "attack_design", "run"]


@dataclasses.dataclass(frozen=True)
class Episode:
    """One episode as the attacker sees it: views, backgrounds, foreground, who is present."""

    name: str
    path: str
    views: np.ndarray  # display images [frame, row, col] in [0, 1]
    background: np.ndarray  # the same frames without their people [frame, row, col]
    present: np.ndarray  # [frame, identity] 0/1
    mask: np.ndarray  # foreground [frame, row, col] bool (metrics.foreground_mask)

    @property
    def difference(self) -> np.ndarray:
        """What the people add: ``views - background`` (display units, [-1, 1])."""
        return (self.views - self.background).astype(np.float32)


def load_episodes(
    paths: Mapping[str, str], views_dir: Path, cfg: PrivacyConfig, progress: bool
) -> dict[str, Episode]:
    """Every episode's views and backgrounds (rendered or reused) as display images, and labels.

    The white level is the training episodes' views' (the attacker's own data).
    """
    from mincam_render.data.dataset import open_dataset
    from mincam_render.data.views import render_views

    a = cfg.attack

    def render(name: str, people: bool) -> np.ndarray:
        views = render_views(paths[name], views_dir / name, width=a.view_width, spp=a.view_spp,
                             progress=progress, people=people)  # fmt: skip
        return np.asarray(views)

    views = {k: render(k, True) for k in paths}
    backgrounds = {k: render(k, False) for k in paths}
    white = white_level(np.concatenate([v for k, v in views.items() if k.startswith("train-")]))
    out = {}
    for k, path in paths.items():
        ds = open_dataset(path)
        v, b = display(views[k], white), display(backgrounds[k], white)
        present = presence(episode_states(ds), roster_of(ds))
        out[k] = Episode(k, path, v, b, present, foreground_mask(v, b))
    return out


def score_reconstruction(episode: Episode, recon: np.ndarray) -> EpisodeScores:
    """:data:`IMAGE_FIGURES` of reconstructions ``[frame, row, col]`` of ``episode``'s views."""
    q = foreground_quality(episode.views, recon, episode.mask)
    return EpisodeScores(
        fg_psnr_db=q["fg_psnr_db"], fg_ssim=q["fg_ssim"], psnr_db=q["psnr_db"], ssim=q["ssim"]
    )


def _errors(
    per_seed: Sequence[Mapping[str, EpisodeScores]], figure: str, frames: Mapping[str, int]
) -> EpisodeErrors:
    """``figure`` of per-seed ``{episode: figures}`` as ``[seed, episode]`` (mean pooling)."""
    names = sorted(frames)
    return EpisodeErrors(
        error=np.array([[s[e].figure(figure) for e in names] for s in per_seed]),
        frames=np.array([frames[e] for e in names]),
        pooling=Pooling.MEAN,
    )


def _intervals(
    per_seed: Sequence[Mapping[str, EpisodeScores]],
    frames: Mapping[str, int],
    seed: int,
    *,
    reid: bool,
) -> AttackFigures:
    """:data:`IMAGE_FIGURES` (and ``reid_top1`` if ``reid``) over seeds and test episodes."""
    figures = FIGURES if reid else IMAGE_FIGURES
    return AttackFigures(
        **{f: bootstrap_interval(_errors(per_seed, f, frames), seed=seed) for f in figures}
    )


def _fit_decoders(
    x: Mapping[str, np.ndarray], episodes: Mapping[str, Episode], cfg: PrivacyConfig, seed: int
) -> tuple[dict[DecoderKind, Decoder], dict[DecoderKind, float]]:
    """Every decoder of :data:`~.config.DECODERS`, and each one's validation mean squared error.

    The error is of the reconstructed validation views (all pixels), the loss
    every decoder was trained on.
    """
    from mincam_render.studies.privacy.decoders import DECODERS, reconstruct, train_decoder

    train = [k for k in sorted(x) if k.startswith("train-")]
    xt = np.concatenate([x[k] for k in train])
    dt = np.concatenate([episodes[k].difference for k in train])
    val = episodes["val-0"]
    fitted = {
        kind: train_decoder(kind, (xt, dt), (x["val-0"], val.difference), cfg.attack, seed)
        for kind in DECODERS
    }
    mse = {
        k: float(np.mean((reconstruct(d, x["val-0"], val.background) - val.views) ** 2))
        for k, d in fitted.items()
    }
    return fitted, mse


def _attack_once(
    run_dir: str,
    data: Mapping[str, TrainingData],
    episodes: Mapping[str, Episode],
    cfg: PrivacyConfig,
    seed: int,
) -> tuple[AttackerSeed, dict[str, np.ndarray]]:
    """One attacker seed against one trained design, and the kept decoder's test views."""
    from mincam_render.learn.train import TrainingData
    from mincam_render.studies.privacy.attacks import design_camera, measurements, train_reid
    from mincam_render.studies.privacy.decoders import RidgeDecoder, reconstruct

    train = TrainingData.concat([data[k] for k in sorted(data) if k.startswith("train-")])
    camera = design_camera(run_dir, train)
    x = {k: measurements(camera, d, seed=stream_seed(seed, f"noise/{k}")) for k, d in data.items()}
    fitted, val_mse = _fit_decoders(x, episodes, cfg, seed)
    kind = min(val_mse, key=val_mse.__getitem__)  # the attacker keeps its best on validation
    train_names = sorted(k for k in data if k.startswith("train-"))
    pt = np.concatenate([episodes[k].present for k in train_names])
    reid = train_reid(
        (np.concatenate([x[k] for k in train_names]), pt),
        (x["val-0"], episodes["val-0"].present),
        cfg.attack,
        seed,
    )
    by_decoder: dict[DecoderKind, dict[str, EpisodeScores]] = {k: {} for k in fitted}
    scores, examples = {}, {}
    for name in sorted(k for k in data if k.startswith("test-")):
        ep = episodes[name]
        for k, d in fitted.items():
            recon = reconstruct(d, x[name], ep.background)
            by_decoder[k][name] = score_reconstruction(ep, recon)
            if k == kind:
                examples[name] = recon
        top1 = reid_top1(reid.predict(x[name]), ep.present)
        scores[name] = dataclasses.replace(by_decoder[kind][name], reid_top1=top1)
    trained = {k: converged(d.history) for k, d in fitted.items() if d.history is not None}
    closed_form = {"converged": True, "improvement": 0.0, "steps": 0}  # ridge: solved exactly
    ridge = fitted[DecoderKind.RIDGE]
    if not isinstance(ridge, RidgeDecoder):
        raise TypeError(f"the ridge decoder is a {type(ridge).__name__}")  # train_decoder's
    penalty = ridge.penalty
    return AttackerSeed(
        episodes=scores,
        by_decoder=by_decoder,
        choice=DecoderChoice(decoder=kind, decoder_val_mse=val_mse, ridge_penalty=penalty),
        convergence=AttackConvergence(
            decoder=trained.get(kind, closed_form),
            reid=converged(reid.history),
            decoders=trained,
        ),
    ), examples


def trivial_attack(episodes: Mapping[str, Episode]) -> dict[str, EpisodeScores]:
    """Per test episode: the background's figures (it sees no one), the prior's top-1 accuracy.

    Also each episode's foreground share of pixels and frames with a foreground.
    """
    train = [e for k, e in episodes.items() if k.startswith("train-")]
    present = np.concatenate([e.present for e in train])
    out = {}
    for name, ep in episodes.items():
        if not name.startswith("test-"):
            continue
        quality = foreground_quality(ep.views, ep.background, ep.mask)
        scores = prior_scores(present, len(ep.present))
        out[name] = EpisodeScores(
            fg_psnr_db=quality["fg_psnr_db"],
            fg_ssim=quality["fg_ssim"],
            psnr_db=quality["psnr_db"],
            ssim=quality["ssim"],
            fg_fraction=quality["fg_fraction"],
            fg_frames=int(quality["fg_frames"]),
            reid_top1=reid_top1(scores, ep.present),
        )
    return out


def prior_attack(episodes: Mapping[str, Episode]) -> dict[str, EpisodeScores]:
    """Per test episode: the figures of each frame's background plus the mean training difference.

    The attacker that knows where people usually are in this room (the mean of
    what they added to the training views) but ignores the read-out: what a
    decoder learns beyond it comes from the design.
    """
    train = [e for k, e in episodes.items() if k.startswith("train-")]
    usual = np.concatenate([e.difference for e in train]).mean(axis=0)
    return {
        name: score_reconstruction(ep, np.clip(ep.background + usual, 0.0, 1.0))
        for name, ep in episodes.items()
        if name.startswith("test-")
    }


def attack_design(
    runs: Sequence[str],
    data: Mapping[str, TrainingData],
    episodes: Mapping[str, Episode],
    cfg: PrivacyConfig,
    name: str,
    *,
    trivial: Mapping[str, EpisodeScores],
    prior: Mapping[str, EpisodeScores],
) -> tuple[DesignAttack, dict[str, np.ndarray]]:
    """Every attacker seed against one design: figures with intervals, the first seed's examples.

    Args:
        runs: the design's training runs (directories); attacker seed ``i``
            attacks run ``i`` modulo their number.
        data: every episode's training data (read-outs are measured from it).
        episodes: every episode as the attacker sees it.
        cfg: the audit.
        name: the design's name (the attacker seeds' stream).
        trivial: the trivial attacker's figures per test episode, for the
            paired people PSNR gain over it (``fg_psnr_gain_db``).
        prior: the prior attacker's, likewise (``fg_psnr_over_prior_db``).
    """
    results: list[AttackerSeed] = []
    examples: dict[str, np.ndarray] = {}
    for i in range(cfg.attack.seeds):
        seed = stream_seed(cfg.comparison.seed, f"attack/{name}", i)
        result, ex = _attack_once(runs[i % len(runs)], data, episodes, cfg, seed)
        results.append(result)
        examples = examples or ex
    per_seed = tuple(r.episodes for r in results)
    frames = {k: len(episodes[k].views) for k in per_seed[0]}
    seed = cfg.comparison.seed
    by_decoder = {
        k: _intervals([r.by_decoder[k] for r in results], frames, seed, reid=False)
        for k in results[0].by_decoder
    }
    return DesignAttack(
        figures=_intervals(per_seed, frames, seed, reid=True),
        fg_psnr_gain_db=_gain(per_seed, trivial, frames, seed),
        fg_psnr_over_prior_db=_gain(per_seed, prior, frames, seed),
        by_decoder=by_decoder,
        per_seed=per_seed,
        convergence=tuple(r.convergence for r in results),
        decoders=tuple(r.choice for r in results),
    ), examples


def _gain(
    per_seed: Sequence[Mapping[str, EpisodeScores]],
    reference: Mapping[str, EpisodeScores],
    frames: Mapping[str, int],
    seed: int,
) -> Interval:
    """People PSNR minus a reference attacker's, paired on the test episodes (dB)."""
    a, b = _errors(per_seed, "fg_psnr_db", frames), _errors([reference], "fg_psnr_db", frames)
    return paired_difference(a, b, seed=seed)


def _write_examples(
    path: Path, episode: Episode, recon: Mapping[str, np.ndarray], count: int
) -> None:
    """``count`` occupied frames of ``episode`` (evenly spaced): views, backgrounds, decodings."""
    occupied = np.flatnonzero(episode.present.any(axis=1))
    pool = occupied if len(occupied) >= count else np.arange(len(episode.views))
    frames = pool[np.linspace(0, len(pool) - 1, min(count, len(pool))).astype(int)]
    np.savez_compressed(
        path,
        frames=frames,
        true=episode.views[frames],
        background=episode.background[frames],
        mask=episode.mask[frames],
        designs=np.array(list(recon)),
        recon=np.stack([recon[n][frames] for n in recon]),
    )


def _trivial_audit(
    trivial: Mapping[str, EpisodeScores], frames: Mapping[str, int], task: Interval, seed: int
) -> TrivialAudit:
    """``privacy.json``'s ``trivial``: task error, attack figures with intervals, per episode."""
    return TrivialAudit(
        task_error=task,
        figures=_intervals([trivial], frames, seed, reid=True),
        fg_fraction=float(np.mean([t.fg_fraction for t in trivial.values()])),
        episodes=dict(trivial),
    )


def _prior_audit(
    prior: Mapping[str, EpisodeScores],
    trivial: Mapping[str, EpisodeScores],
    frames: Mapping[str, int],
    seed: int,
) -> PriorAudit:
    """``privacy.json``'s ``prior``: image figures with intervals, the paired gain over trivial."""
    return PriorAudit(
        figures=_intervals([prior], frames, seed, reid=False),
        fg_psnr_gain_db=_gain([prior], trivial, frames, seed),
        episodes=dict(prior),
    )


def run(
    config: PrivacyConfig,
    out: str | os.PathLike,
    *,
    workers: int = 2,
    train_workers: int = 1,
    ray_address: str | None = None,
    progress: bool = False,
) -> PrivacyResult:
    """Run the audit (module docstring) into ``out``.

    ``workers``, ``train_workers`` and ``ray_address``: where episodes render and
    the task's runs train (:func:`mincam_render.studies.comparison.study.run`);
    the attacks train in this process.

    Writes ``out/privacy.json`` (the result's :meth:`~.result.PrivacyResult.as_json`)
    and ``out/examples.npz`` (true test views, their backgrounds and foreground
    masks, and each design's reconstructions of a few test frames, for the report).
    """
    from tqdm import tqdm

    from mincam_render.studies.comparison import study as comparison

    out = Path(out)
    cfg = config
    result = comparison.run(
        cfg.comparison,
        out,
        workers=workers,
        train_workers=train_workers,
        ray_address=ray_address,
        progress=progress,
    )
    data = comparison.render_episodes(
        cfg.comparison, out / "episodes", workers=workers, progress=False
    )
    paths = {k: v.dataset for k, v in result.episodes.items()}
    episodes = load_episodes(paths, out / "views", cfg, progress)
    trivial, prior = trivial_attack(episodes), prior_attack(episodes)
    designs, examples = {}, {}
    block = result.headline
    todo = tqdm(block.designs.items(), desc="attacks", unit="design", disable=not progress)
    for name, d in todo:
        attack, ex = attack_design(d.runs, data, episodes, cfg, name, trivial=trivial,
                                   prior=prior)  # fmt: skip
        designs[name] = DesignAudit(
            pixels=d.pixels,
            task_error=d.error,
            task_state=d.state,
            task_seeds=len(d.runs),
            attack=attack,
        )
        examples[name] = ex["test-0"]
    frames = {k: len(episodes[k].views) for k in trivial}
    seed = cfg.comparison.seed
    privacy = rederive_verdicts(PrivacyResult(
        task=result.family,
        error_name=block.error_name,
        config=json.loads(json.dumps(dataclasses.asdict(cfg), default=str)),
        roster=int(episodes["test-0"].present.shape[1]),
        episodes={k: e.as_json() for k, e in result.episodes.items()},
        designs=designs,
        trivial=_trivial_audit(trivial, frames, block.trivial.error, seed),
        prior=_prior_audit(prior, trivial, frames, seed),
        comparison=str(out / "metrics.json"),
        corner={},
    ))  # fmt: skip
    _write_examples(out / "examples.npz", episodes["test-0"], examples, cfg.attack.examples)
    (out / "privacy.json").write_text(strict_json.dumps(privacy.as_json()) + "\n")
    return privacy
