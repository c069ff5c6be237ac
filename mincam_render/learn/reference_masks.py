r"""Reference masks a learned design must beat, at the same pixel count and with the same head.

Each reference is a set of ``K`` directions ``v_j`` in the camera's view
(texels of the mean transport over the rendered detectors, ``x = mean_k T_k``),
made printable by an affine map onto the printable range,

.. math:: M_j = m_{lo} + (m_{hi} - m_{lo})\,\frac{v_j - \min v_j}{\max v_j - \min v_j},

so pixel ``j`` reads ``a_j\, v_j \cdot T_j + b_j \sum T_j``: the direction plus a
share of the total light (a transparency cannot subtract). Pixel ``j`` reads
detector ``j``; the parallax between detectors is sub-texel beyond ~1 m.

* :attr:`MaskReference.PCA` -- the first ``K`` principal components of the
  training views (unsupervised: what varies most).
* :attr:`MaskReference.PLS` -- partial least squares of the views on the task's
  labels (supervised linear masks: the directions of largest covariance with
  the standardised labels; ``scikit-learn``'s ``PLSRegression``).
* :attr:`MaskReference.DISTILLED` -- a network trained on the full-resolution
  view (a box-pixel camera at the texel grid) distilled into ``K`` masks: with
  ``W`` its first layer acting on the pixel values (its input standardisation
  folded in), the rank-``K`` map ``A M`` closest to ``W`` over the training
  views (reduced-rank regression: ``M = U_K^T W``, ``U_K`` the top ``K``
  eigenvectors of ``W \Sigma W^T``, ``\Sigma`` the views' covariance).

Arrays are numpy unless a docstring says torch.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import torch

from mincam_render.core.labels import LabelKind
from mincam_render.learn.evaluation import even_indices
from mincam_render.learn.models import MAX_LOGIT, BaselineCamera, MincamCamera
from mincam_render.learn.train_config import MaskReference, TrainConfig
from mincam_render.learn.training_data import TrainingData

#: Training frames the directions are fitted on at most (evenly spaced).
MAX_FIT_FRAMES = 20_000


def printable_masks(directions: np.ndarray, transmittance_range: tuple[float, float]) -> np.ndarray:
    """``M[pixel, row, col]`` in the printable range from ``directions[pixel, row, col]``.

    Each direction is mapped affinely onto ``[lo, hi]`` (its minimum to ``lo``, its
    maximum to ``hi``); a constant direction gives a uniform mask at ``hi``.
    """
    lo, hi = transmittance_range
    v = np.asarray(directions, np.float64)
    vmin = v.min(axis=(1, 2), keepdims=True)
    span = v.max(axis=(1, 2), keepdims=True) - vmin
    unit = np.divide(v - vmin, span, out=np.ones_like(v), where=span > 0)
    return lo + (hi - lo) * unit


def fit_frames(data: TrainingData, limit: int = MAX_FIT_FRAMES) -> np.ndarray:
    """Indices of the training frames the directions are fitted on (at most ``limit``, even)."""
    return even_indices(len(data.transport), limit)


def views(data: TrainingData, frames: np.ndarray) -> np.ndarray:
    """``x[frame, texel]`` (W): the mean transport over detectors of ``frames``."""
    out = []
    for a in range(0, len(frames), 1024):
        chunk = torch.from_numpy(np.asarray(frames[a : a + 1024], np.int64))
        mean = data.frames_w(chunk).mean(dim=1)
        out.append(mean.reshape(len(chunk), -1).double().numpy())
    return np.concatenate(out)


def task_targets(data: TrainingData, frames: np.ndarray) -> np.ndarray:
    """``y[frame, output]``: every label element of ``frames``, standardised (0/1 for states)."""
    cols = []
    for s in data.label_specs:
        y = np.asarray(data.labels[s.name], np.float64)[frames]
        if s.kind is not LabelKind.BINARY:
            std = y.std(axis=0)
            y = (y - y.mean(axis=0)) / np.where(std > 0, std, 1.0)
        cols.append(y)
    return np.concatenate(cols, axis=1)


def pca_directions(x: np.ndarray, k: int) -> np.ndarray:
    """``v[k, texel]``: the first ``k`` principal components of views ``x[frame, texel]``."""
    from sklearn.decomposition import PCA

    return PCA(n_components=k, svd_solver="full").fit(x).components_


def pls_directions(x: np.ndarray, y: np.ndarray, k: int) -> np.ndarray:
    """``v[k, texel]``: partial least squares rotations of views ``x`` on targets ``y``.

    ``x @ v.T`` are the PLS scores (``x_rotations_``), the linear read-outs of
    the views that covary most with the targets.
    """
    from sklearn.cross_decomposition import PLSRegression

    pls = PLSRegression(n_components=k, scale=False).fit(x, y)
    return np.asarray(pls.x_rotations_).T


def distilled_directions(teacher: BaselineCamera, x: np.ndarray, k: int) -> np.ndarray:
    """``v[k, texel]``: the rank-``k`` distillation of a full-resolution camera's first layer.

    Args:
        teacher: a trained box-pixel camera at the texel grid (MLP head).
        x: ``[frame, texel]`` training views (W).
        k: masks.

    Returns:
        ``U_K^T W`` with ``W`` the first layer on views (W), ``U_K`` the top
        ``k`` eigenvectors of ``W Σ W^T`` (module docstring).
    """
    head = teacher.head
    first = head.first_layer
    var = head.input_norm.running_var
    if not isinstance(first, torch.nn.Linear) or var is None:
        raise ValueError("distillation needs a teacher with the paper's MLP head")
    if head.in_features != x.shape[1]:
        raise ValueError(
            f"the teacher reads {head.in_features} pixels; the views have {x.shape[1]} texels"
        )
    scale = 1.0 / (float(teacher.exposure_w) * np.sqrt(var.double().numpy() + head.input_norm.eps))
    w = first.weight.detach().double().numpy() * scale[None, :]  # [hidden, texel] on views (W)
    cov = np.cov(x, rowvar=False)
    _, vecs = np.linalg.eigh(w @ cov @ w.T)
    top = vecs[:, ::-1][:, :k]  # eigh sorts ascending
    return top.T @ w


def reference_directions(
    kind: MaskReference,
    data: TrainingData,
    k: int,
    *,
    teacher: Callable[[], BaselineCamera] | None = None,
) -> np.ndarray:
    """``v[k, row, col]``: the directions of reference ``kind`` fitted on training ``data``.

    Args:
        kind: which reference.
        data: the training split (the task's labels only, for PLS).
        k: pixels.
        teacher: for ``DISTILLED``, a function returning the trained
            full-resolution camera (called only then).

    Raises:
        ValueError: more pixels than the views have texels, or ``DISTILLED``
            without a teacher.
    """
    rows, cols = data.camera.mask_resolution
    if not 1 <= k <= rows * cols:
        raise ValueError(f"{k} reference masks: need 1 to {rows * cols} (the texels)")
    kind = MaskReference(kind)
    if kind is not MaskReference.PCA and data.history > 1:
        raise ValueError(
            f"{kind.value} reference masks fit single frames to their labels; a task with a "
            f"history of {data.history} frames has only the pca reference"
        )
    frames = fit_frames(data)
    x = views(data, frames)
    if kind is MaskReference.PCA:
        v = pca_directions(x, k)
    elif kind is MaskReference.PLS:
        v = pls_directions(x, task_targets(data, frames), k)
    else:
        if teacher is None:
            raise ValueError("distilled reference masks need a trained full-resolution teacher")
        v = distilled_directions(teacher(), x, k)
    return v.reshape(k, rows, cols)


def set_reference_masks(
    model: MincamCamera,
    kind: MaskReference,
    train: TrainingData,
    val: TrainingData | Sequence[TrainingData],
    config: TrainConfig,
    teacher_dir: Path | None,
    *,
    frozen: bool = True,
) -> None:
    """Give ``model`` the printable masks of reference ``kind`` fitted on ``train`` (torch).

    ``frozen``: the masks stay fixed and only the head trains (the reference
    itself); False: training starts from them (end to end, initialised by the
    reference). ``DISTILLED`` first trains its teacher, a box-pixel camera at
    the texel grid with the paper's head (its first layer is what is distilled)
    and ``config``'s training recipe, into ``teacher_dir`` (resumable; None: in
    memory).

    Raises:
        ValueError: a camera of signed pixels (references are fitted as
            single printable masks).
    """
    from mincam_render.learn.builders import build_baseline

    if model.signed:
        raise ValueError(f"reference masks ({kind}) are single printable masks; not signed pairs")
    from mincam_render.learn.loop import train_model

    def teacher() -> BaselineCamera:
        net = build_baseline(train, train.camera.mask_resolution, seed=config.seed)
        train_model(net, train, val, config, out_dir=teacher_dir)
        return net

    v = reference_directions(kind, train, model.num_pixels, teacher=teacher)
    lo, hi = model.camera.transmittance_range
    unit = torch.as_tensor((printable_masks(v, (lo, hi)) - lo) / (hi - lo))
    with torch.no_grad():  # the printable limits themselves at the logits' bound
        model.logits.copy_(torch.logit(unit, eps=math.exp(-MAX_LOGIT)).clamp(-MAX_LOGIT, MAX_LOGIT))
    model.logits.requires_grad_(not frozen)
