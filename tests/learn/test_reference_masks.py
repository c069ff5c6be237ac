"""Reference masks: principal components, partial least squares, a distilled network."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from support import linear_task

from mincam_render.learn import train as tr
from mincam_render.learn.reference_masks import (
    MaskReference,
    distilled_directions,
    fit_frames,
    pca_directions,
    pls_directions,
    printable_masks,
    reference_directions,
    set_reference_masks,
    task_targets,
    views,
)


def _cosine(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.ravel(a), np.ravel(b)
    return float(abs(a @ b) / (np.linalg.norm(a) * np.linalg.norm(b)))


def test_printable_masks_map_each_direction_onto_the_printable_range():
    v = np.array([[[-2.0, 0.0], [1.0, 2.0]], [[3.0, 3.0], [3.0, 3.0]]])
    m = printable_masks(v, (0.01, 0.67))
    np.testing.assert_allclose(m[0], 0.01 + 0.66 * np.array([[0.0, 0.5], [0.75, 1.0]]))
    np.testing.assert_allclose(m[1], 0.67)  # a constant direction: an open mask


def test_pca_finds_the_direction_that_varies_most(rng):
    u = rng.normal(size=16)
    x = np.outer(rng.normal(size=500) * 10, u) + rng.normal(size=(500, 16)) * 0.1
    assert _cosine(pca_directions(x, 1)[0], u) > 0.999


def test_pls_finds_the_linear_read_out_of_the_label():
    data = linear_task(600, k=2, res=8)
    frames = fit_frames(data)
    v = pls_directions(views(data, frames), task_targets(data, frames), 1)[0].reshape(8, 8)
    # the count is the top half's mean brightness minus the bottom half's
    pattern = np.where(np.arange(8)[:, None] < 4, 1.0, -1.0) * np.ones((1, 8))
    assert _cosine(v, pattern) > 0.9
    assert _cosine(pca_directions(views(data, frames), 1)[0], pattern) < 0.5  # unsupervised


def test_distillation_recovers_a_rank_one_first_layer():
    data = linear_task(300, k=2, res=4)
    teacher = tr.build_baseline(data, (4, 4))
    rng = np.random.default_rng(1)
    a, u = rng.normal(size=128), rng.normal(size=16)
    with torch.no_grad():
        teacher.head.body[0].weight.copy_(torch.from_numpy(np.outer(a, u)))
        teacher.head.input_norm.running_var.fill_(4.0)
    x = views(data, fit_frames(data))
    v = distilled_directions(teacher, x, 1)[0]
    # the layer reads pixel values x / exposure standardised by sigma = 2: u / (2 exposure)
    np.testing.assert_allclose(_cosine(v, u), 1.0, rtol=1e-9)
    w = np.outer(a, u) / (2 * float(teacher.exposure_w))
    np.testing.assert_allclose(np.abs(v), np.linalg.norm(a) * np.abs(w[0]) / abs(a[0]), rtol=1e-5)


def test_reference_masks_are_refused_where_they_do_not_apply():
    data = linear_task(100, k=2, res=4)
    with pytest.raises(ValueError, match="need 1 to 16"):
        reference_directions(MaskReference.PCA, data, 17)
    with pytest.raises(ValueError, match="teacher"):
        reference_directions(MaskReference.DISTILLED, data, 2)
    signed = tr.build_mincam(data, 1, signed=True)
    with pytest.raises(ValueError, match="not signed pairs"):
        set_reference_masks(signed, MaskReference.PCA, data, data, tr.TrainConfig(), None)


@pytest.mark.parametrize("tuned", [False, True])
def test_a_reference_camera_keeps_or_tunes_its_masks(tmp_path, tuned):
    data = linear_task(240, k=2, res=4)
    train, val = data.subset(0, 180), data.subset(180, 240)
    cfg = tr.TrainConfig(max_steps=40, batch_size=16, eval_every=20)
    run = tr.train_run(train, val, None, tmp_path, pixels=2, config=cfg,
                       reference=MaskReference.PLS, tune_reference=tuned)  # fmt: skip
    masks, camera, info = tr.run_masks(tmp_path)
    assert info["reference"] == {"masks": "pls", "tuned": tuned}
    expected = printable_masks(
        reference_directions(MaskReference.PLS, train, 2), camera.transmittance_range
    )
    lo, hi = camera.transmittance_range
    close = np.abs(masks - expected).max() < 1e-3 * (hi - lo)  # the logits' bound at the limits
    assert close is not tuned
    assert run.steps == 40
