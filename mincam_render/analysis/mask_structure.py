"""What trained masks look like and what they look at.

Two kinds of figures for masks ``M[pixel, row, col]`` (transmittance):

* **Spatial structure**: the total variation per texel
  (:func:`~mincam_render.optics.maskplane.total_variation_per_texel`; 0 for a
  uniform mask, about ``2 (hi - lo)`` for a checkerboard of the printable
  limits) and the fraction of texels within 5 % of the printable range from
  either limit (binary speckle has nearly all of them there).
* **What a mask looks at**: the label map ``c[row, col]`` is, per texel of the
  camera's view (the mean transport over detectors, training frames), the
  absolute correlation over frames between the texel's power and the task's
  labels (the root mean square over label elements). A mask's *label weight*
  is its transmittance-weighted mean of ``c`` over the mean of ``c``: 1 for a
  mask that weighs every texel alike, above 1 for one that passes more light
  from where the labels change (for people: where they walk and sit). Its
  *label alignment* is the correlation over texels between the mask and ``c``.

Arrays are numpy.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_render.learn.training_data import TrainingData

#: A texel counts as at a printable limit within this fraction of the range.
LIMIT_FRACTION = 0.05


@dataclass(frozen=True)
class MaskStructure:
    """Structure and label figures of one set of masks (module docstring).

    Args:
        tv_per_texel: total variation per texel of each mask (transmittance).
        at_limits: fraction of each mask's texels within 5 % of the range of a limit.
        label_weight: each mask's transmittance-weighted mean of the label map
            over the map's mean (1: no preference).
        label_alignment: correlation over texels of each mask with the label map.
        labels: the labels the map was computed for.
    """

    tv_per_texel: tuple[float, ...]
    at_limits: tuple[float, ...]
    label_weight: tuple[float, ...]
    label_alignment: tuple[float, ...]
    labels: tuple[str, ...]


def label_map(views: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """``c[texel]``: RMS over targets of |corr over frames| of each texel's power with them.

    Args:
        views: ``x[frame, texel]`` (W).
        targets: ``y[frame, element]``.

    Returns:
        ``c[texel]`` in [0, 1]; 0 where a texel or a target does not vary.
    """
    x = views - views.mean(axis=0)
    y = targets - targets.mean(axis=0)
    sx, sy = np.sqrt((x**2).sum(axis=0)), np.sqrt((y**2).sum(axis=0))
    cov = x.T @ y  # [texel, element]
    denom = np.outer(sx, sy)
    corr = np.divide(cov, denom, out=np.zeros_like(cov), where=denom > 0)
    return np.sqrt(np.mean(corr**2, axis=1))


def mask_structure(
    masks: np.ndarray,
    transmittance_range: tuple[float, float],
    label_map_: np.ndarray,
    labels: tuple[str, ...],
) -> MaskStructure:
    """:class:`MaskStructure` of ``masks[pixel, row, col]`` against ``label_map_[row, col]``."""
    import torch

    from mincam_render.optics.maskplane import total_variation_per_texel

    m = np.asarray(masks, np.float64)
    lo, hi = transmittance_range
    band = LIMIT_FRACTION * (hi - lo)
    c = np.asarray(label_map_, np.float64).reshape(m.shape[1:])
    tv = [float(total_variation_per_texel(torch.from_numpy(mk[None]))) for mk in m]
    at = [float(np.mean((mk - lo < band) | (hi - mk < band))) for mk in m]
    weight = [float((mk * c).sum() / mk.sum() / c.mean()) if c.mean() > 0 else 1.0 for mk in m]
    align = [_correlation(mk.ravel(), c.ravel()) for mk in m]
    return MaskStructure(tuple(tv), tuple(at), tuple(weight), tuple(align), tuple(labels))


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    denom = np.sqrt((a**2).sum() * (b**2).sum())
    return float((a * b).sum() / denom) if denom > 0 else 0.0


def plot_mask_views(
    masks: np.ndarray,
    view: np.ndarray,
    label_map_: np.ndarray,
    structure: MaskStructure,
    path: str | os.PathLike,
    *,
    title: str,
) -> Path:
    """A PNG: the camera's view, the label map, then every mask with its figures.

    Every panel is indexed like the transport images (``[row, col]`` of the
    mask plane), so a mask lies over the view it multiplies.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    k = len(masks)
    cols = min(k + 2, 6)
    rows = -(-(k + 2) // cols)
    fig, axes = plt.subplots(
        rows, cols, figsize=(2.1 * cols, 2.5 * rows), squeeze=False, layout="constrained"
    )
    panels = [("view (mean transport)", view, "gray"), ("label map |corr|", label_map_, "magma")]
    panels += [
        (
            f"mask {j}: TV {structure.tv_per_texel[j]:.2f}\n"
            f"label weight {structure.label_weight[j]:.2f}",
            masks[j],
            "gray",
        )
        for j in range(k)
    ]
    for ax, (name, img, cmap) in zip(axes.flat, panels, strict=False):
        ax.imshow(np.asarray(img).reshape(masks.shape[1:]), cmap=cmap)
        ax.set_title(name, fontsize=7)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in list(axes.flat)[len(panels) :]:
        ax.axis("off")
    fig.suptitle(title, fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


#: Training frames the label map is computed on at most (evenly spaced).
MAP_FRAMES = 4000


def view_and_label_map(train: TrainingData) -> tuple[np.ndarray, np.ndarray]:
    """``(view[row, col], c[row, col])``: the mean training view (W) and its label map."""
    from mincam_render.learn.reference_masks import fit_frames, task_targets, views

    frames = fit_frames(train, MAP_FRAMES)
    x = views(train, frames)
    shape = train.camera.mask_resolution
    return x.mean(axis=0).reshape(shape), label_map(x, task_targets(train, frames)).reshape(shape)


def run_structure(
    run_dir: str | os.PathLike, view_map: tuple[np.ndarray, np.ndarray], labels: tuple[str, ...]
) -> MaskStructure:
    """:class:`MaskStructure` of a finished minimalist run's masks."""
    from mincam_render.learn.restore import run_masks

    masks, camera, _ = run_masks(run_dir)
    return mask_structure(masks, camera.transmittance_range, view_map[1], labels)
