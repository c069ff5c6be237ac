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

from collections.abc import Mapping
from typing import Any

import numpy as np

from mincam_render.analysis.statistics import EpisodeErrors, Pooling, paired_difference
from mincam_render.studies.comparison.config import Design, designs_by_name

#: Attack figures where a higher value means a more successful attacker.
ATTACK_FIGURES = ("fg_psnr_db", "reid_top1")


def audit_designs(privacy: Mapping[str, Any]) -> dict[str, Design]:
    """``{name: design}`` of a privacy audit's designs (from its ``config``, not their names)."""
    return designs_by_name(privacy["config"]["comparison"]["designs"])


def _below(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    """Interval ``a`` lies wholly below interval ``b`` (``{"mean", "ci95"}``)."""
    return bool(a["ci95"][1] < b["ci95"][0])


def _episode_figure(privacy: Mapping[str, Any], design: str, figure: str) -> EpisodeErrors:
    """``figure`` of ``design``'s attacker seeds as ``[seed, test episode]`` (mean pooling)."""
    per_seed = privacy["designs"][design]["per_seed"]
    names = sorted(per_seed[0])
    return EpisodeErrors(
        error=np.array([[s[e][figure] for e in names] for s in per_seed]),
        frames=np.array([privacy["episodes"][e]["samples"] for e in names]),
        pooling=Pooling.MEAN,
    )


def paired_attack_differences(
    privacy: Mapping[str, Any], design: str, baseline: str
) -> dict[str, dict[str, Any]]:
    """``{figure: {"mean", "ci95"}}``: ``design``'s attack figure minus ``baseline``'s, paired."""
    seed = int(privacy["config"]["comparison"]["seed"])
    return {
        f: paired_difference(
            _episode_figure(privacy, design, f), _episode_figure(privacy, baseline, f), seed=seed
        ).as_dict()
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


def corner_verdicts(privacy: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Per minimalist design: the task-matched baselines, and those it is more private than.

    Args:
        privacy: ``privacy.json``'s contents (``designs`` with ``task_error``,
            ``fg_psnr_db``, ``reid_top1`` as ``{"mean", "ci95"}`` and ``per_seed``
            figures per test episode; ``episodes`` with their ``samples``;
            ``config.comparison`` with its ``designs`` and ``seed``).

    Returns:
        ``{design: {"task_matched": [baselines no better at the task],
        "more_private_than": {figure: [matched baselines it beats on that figure]},
        "in_corner_against": [matched baselines it beats on every figure],
        "paired": {baseline: {figure: design - baseline, paired}},
        "paired_more_private_than": [matched baselines below on every figure, paired],
        "verdict": one line}}``.
    """
    designs = privacy["designs"]
    kinds = audit_designs(privacy)
    baselines = [n for n in designs if not kinds[n].is_mincam]
    out = {}
    for name, d in designs.items():
        if not kinds[name].is_mincam:
            continue
        matched = [b for b in baselines if not _below(designs[b]["task_error"], d["task_error"])]
        beats = {f: [b for b in matched if _below(d[f], designs[b][f])] for f in ATTACK_FIGURES}
        corner = [b for b in matched if all(b in beats[f] for f in ATTACK_FIGURES)]
        paired = {b: paired_attack_differences(privacy, name, b) for b in matched}
        below = [b for b in matched if all(p["ci95"][1] < 0 for p in paired[b].values())]
        out[name] = {
            "task_matched": matched,
            "more_private_than": beats,
            "in_corner_against": corner,
            "paired": paired,
            "paired_more_private_than": below,
            "verdict": _verdict(name, matched, corner, below),
        }
    return out
