"""The privacy-utility curve: which designs sit in the corner (low task error, low attack success).

A minimalist design is *in the corner against* a baseline when the baseline
is no better at the task (its task-error interval does not lie wholly below
the design's) and the design's attack success is lower with separated 95 %
intervals, for the reconstruction of the people (PSNR on the view's
foreground) and for re-identification (top-1). That is the verdict.

Beside it, as the studies do (``docs/studies.md``), the paired difference
design − baseline of each attack figure on the same test episodes: episodes
whose people are hard for every attacker drop out, so it is the sharper test.
A design is *more private on the same episodes* than a matched baseline when
both paired intervals lie wholly below 0. It is reported, not the verdict.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from mincam_render.analysis.statistics import (
    EpisodeErrors,
    Interval,
    Pooling,
    paired_difference,
)
from mincam_render.studies.comparison.config import Design
from mincam_render.studies.privacy.result import CornerVerdict, DesignAudit, PrivacyResult

#: Attack figures where a higher value means a more successful attacker.
ATTACK_FIGURES = ("fg_psnr_db", "reid_top1")


def audit_designs(privacy: PrivacyResult) -> dict[str, Design]:
    """``{name: design}`` of a privacy audit's designs (from its ``config``, not their names)."""
    return privacy.design_kinds()


def _below(a: Interval, b: Interval) -> bool:
    """Interval ``a`` lies wholly below interval ``b``."""
    return bool(a.high < b.low)


def _episode_figure(design: DesignAudit, figure: str, samples: Mapping[str, int]) -> EpisodeErrors:
    """``figure`` of ``design``'s attacker seeds as ``[seed, test episode]`` (mean pooling)."""
    per_seed = design.attack.per_seed
    names = sorted(per_seed[0])
    return EpisodeErrors(
        error=np.array([[s[e].figure(figure) for e in names] for s in per_seed]),
        frames=np.array([samples[e] for e in names]),
        pooling=Pooling.MEAN,
    )


def paired_attack_differences(
    design: DesignAudit, baseline: DesignAudit, samples: Mapping[str, int], seed: int
) -> dict[str, Interval]:
    """``{figure: interval}``: ``design``'s attack figure minus ``baseline``'s, paired.

    Args:
        design: the minimalist design's audit.
        baseline: the baseline's audit.
        samples: frames of every test episode.
        seed: the bootstrap's seed (the comparison's).
    """
    return {
        f: paired_difference(
            _episode_figure(design, f, samples), _episode_figure(baseline, f, samples), seed=seed
        )
        for f in ATTACK_FIGURES
    }


def _verdict(name: str, matched: list[str], corner: list[str], paired: list[str]) -> str:
    """One line: the interval verdict, then the paired reading."""
    if not matched:
        return f"{name}: every baseline is better at the task (no match to compare)"
    if corner:
        line = f"{name}: in the corner against {', '.join(corner)}"
    else:
        line = (
            f"{name}: not in the corner: no task-matched baseline "
            f"({', '.join(matched)}) is beaten on both attacks with separated intervals"
        )
    both = ", ".join(paired) if paired else "none"
    return f"{line}; paired on the same episodes, lower on both attacks than: {both}"


def corner_verdicts(
    designs: Mapping[str, DesignAudit],
    kinds: Mapping[str, Design],
    samples: Mapping[str, int],
    seed: int,
) -> dict[str, CornerVerdict]:
    """Per minimalist design: the task-matched baselines, and those it is more private than.

    Args:
        designs: every design's audit (task error, attack figures with
            intervals, per attacker seed figures per test episode).
        kinds: ``{name: design}`` (:meth:`~.result.PrivacyResult.design_kinds`).
        samples: frames of every test episode.
        seed: the bootstrap's seed of the paired differences (the comparison's).

    Returns:
        ``{minimalist design: its verdict}``.
    """
    baselines = [n for n in designs if not kinds[n].is_mincam]
    out = {}
    for name, d in designs.items():
        if not kinds[name].is_mincam:
            continue
        matched = [b for b in baselines if not _below(designs[b].task_error, d.task_error)]
        beats = {
            f: tuple(b for b in matched if _below(d.figure(f), designs[b].figure(f)))
            for f in ATTACK_FIGURES
        }
        corner = [b for b in matched if all(b in beats[f] for f in ATTACK_FIGURES)]
        paired = {b: paired_attack_differences(d, designs[b], samples, seed) for b in matched}
        below = [b for b in matched if all(p.high < 0 for p in paired[b].values())]
        out[name] = CornerVerdict(
            task_matched=tuple(matched),
            more_private_than=beats,
            in_corner_against=tuple(corner),
            paired=paired,
            paired_more_private_than=tuple(below),
            verdict=_verdict(name, matched, corner, below),
        )
    return out


def rederive_verdicts(privacy: PrivacyResult) -> PrivacyResult:
    """``privacy`` with its corner verdicts derived again from its figures."""
    corner = corner_verdicts(
        privacy.designs, privacy.design_kinds(), privacy.samples(), privacy.seed
    )
    return dataclasses.replace(privacy, corner=corner)
