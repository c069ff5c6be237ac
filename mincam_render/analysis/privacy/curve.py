"""The privacy-utility curve: which designs sit in the corner (low task error, low attack success).

A minimalist design is *in the corner against* a baseline when the baseline
is no better at the task (its task-error interval does not lie wholly below
the design's) and the design's attack success is lower with separated 95 %
intervals, for the reconstruction of the people (PSNR on the view's
foreground) and for re-identification (top-1).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: Attack figures where a higher value means a more successful attacker.
ATTACK_FIGURES = ("fg_psnr_db", "reid_top1")


def _below(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    """Interval ``a`` lies wholly below interval ``b`` (``{"mean", "ci95"}``)."""
    return bool(a["ci95"][1] < b["ci95"][0])


def corner_verdicts(privacy: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Per minimalist design: the task-matched baselines, and those it is more private than.

    Args:
        privacy: ``privacy.json``'s contents (``designs`` with ``task_error``,
            ``fg_psnr_db``, ``reid_top1`` as ``{"mean", "ci95"}``).

    Returns:
        ``{design: {"task_matched": [baselines no better at the task],
        "more_private_than": {figure: [matched baselines it beats on that figure]},
        "in_corner_against": [matched baselines it beats on every figure],
        "verdict": one line}}``.
    """
    designs = privacy["designs"]
    baselines = [n for n in designs if n.startswith("baseline-")]
    out = {}
    for name, d in designs.items():
        if not name.startswith("mincam-"):
            continue
        matched = [b for b in baselines if not _below(designs[b]["task_error"], d["task_error"])]
        beats = {f: [b for b in matched if _below(d[f], designs[b][f])] for f in ATTACK_FIGURES}
        corner = [b for b in matched if all(b in beats[f] for f in ATTACK_FIGURES)]
        if not matched:
            line = f"{name}: every baseline is better at the task (no match to compare)"
        elif corner:
            line = f"{name}: in the corner against {', '.join(corner)}"
        else:
            line = (
                f"{name}: not in the corner: no task-matched baseline "
                f"({', '.join(matched)}) is beaten on both attacks with separated intervals"
            )
        out[name] = {
            "task_matched": matched,
            "more_private_than": beats,
            "in_corner_against": corner,
            "verdict": line,
        }
    return out
