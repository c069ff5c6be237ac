"""What a task predicts: label kinds and specifications (shared by scenes, data and learning)."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from mincam_render.core.checks import check_int


class LabelKind(enum.Enum):
    """How a label is learned and post-processed (paper supplement C)."""

    COUNT = "count"  # integer >= 0; MSE loss; rounded, then median filtered
    REGRESSION = "regression"  # real value (e.g. speed); MSE loss; median filtered
    BINARY = "binary"  # 0/1 state per element; cross-entropy; median filtered


@dataclass(frozen=True, kw_only=True)
class LabelSpec:
    """One label of a family.

    Args:
        name: key in the label dict.
        kind: how it is learned.
        size: number of elements (e.g. zones or lights).
        unit: physical unit ("" for counts and states).
        element_names: a name per element (zones, lights).
        median_filter_s: temporal median filter at evaluation (s): 2 s for counts
            and speeds, 0.5 s for states, as in the paper.
        zero_below_true: evaluation rule of a REGRESSION label: after the median
            filter, the prediction is set to 0 wherever the true value is below
            this (in ``unit``); None = no such rule. The paper's traffic
            evaluation uses 3 mph (supplement, "Traffic Monitoring").
        headline: name of the task's headline metric this label is pooled into
            ("" = not part of one). Labels sharing a headline must share a kind;
            without any, the headline is the first label's figure.

    Raises:
        ValueError: a size below 1, a negative or non-finite filter length, a
            ``zero_below_true`` on a label that is not REGRESSION or not finite,
            or ``element_names`` of the wrong length.
    """

    name: str
    kind: LabelKind
    size: int = 1
    unit: str = ""
    element_names: tuple[str, ...] = ()
    median_filter_s: float = 2.0
    zero_below_true: float | None = None
    headline: str = ""

    def __post_init__(self) -> None:
        check_int(f"LabelSpec {self.name!r}: size", self.size, 1, numpy=True)
        if self.element_names and len(self.element_names) != self.size:
            raise ValueError(
                f"LabelSpec {self.name!r}: {len(self.element_names)} element_names for "
                f"size {self.size}"
            )
        if not (math.isfinite(self.median_filter_s) and self.median_filter_s >= 0):
            raise ValueError(
                f"LabelSpec {self.name!r}: median_filter_s = {self.median_filter_s!r} s, "
                "allowed a finite value >= 0"
            )
        if self.zero_below_true is not None and (
            self.kind is not LabelKind.REGRESSION or not math.isfinite(self.zero_below_true)
        ):
            raise ValueError(
                f"LabelSpec {self.name!r}: zero_below_true = {self.zero_below_true!r} "
                f"{self.unit}: allowed a finite value on a REGRESSION label, or None"
            )


def label_tasks(specs: tuple[LabelSpec, ...] | list[LabelSpec]) -> dict[str, tuple[str, ...]]:
    """The tasks of a family: ``{task: label names}``, in the labels' order.

    A task is what one set of masks is designed for (paper Sec. 7: "two [pixels]
    for each task"): the labels pooled into one headline figure form one task
    (traffic's left and right speeds), every other label is a task of its own
    (workspace: the people count, the zones, the door).
    """
    tasks: dict[str, list[str]] = {}
    for s in specs:
        tasks.setdefault(s.headline or s.name, []).append(s.name)
    return {task: tuple(names) for task, names in tasks.items()}
