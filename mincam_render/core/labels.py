"""What a task predicts: label kinds and specifications (shared by scenes, data and learning)."""

from __future__ import annotations

import enum
from dataclasses import dataclass


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
    """

    name: str
    kind: LabelKind
    size: int = 1
    unit: str = ""
    element_names: tuple[str, ...] = ()
    median_filter_s: float = 2.0
