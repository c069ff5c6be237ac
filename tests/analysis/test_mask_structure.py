"""What masks look like and what they look at: closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from mincam_render.analysis.mask_structure import label_map, mask_structure, plot_mask_views

RANGE = (0.01, 0.67)


def test_the_label_map_is_the_absolute_correlation_of_each_texel_with_the_label(rng):
    y = rng.normal(size=(200, 1))
    views = np.concatenate([y, -2 * y + 1, np.ones((200, 1)), rng.normal(size=(200, 1))], axis=1)
    c = label_map(views, y)
    np.testing.assert_allclose(c[:3], [1.0, 1.0, 0.0], atol=1e-12)
    assert c[3] < 0.25  # an unrelated texel: |corr| ~ 1/sqrt(200)
    # two label elements: the root mean square of the two correlations
    two = label_map(views[:, :1], np.concatenate([y, rng.normal(size=(200, 1))], axis=1))
    assert np.sqrt(0.5) - 0.1 < two[0] < np.sqrt(0.5) + 0.1


def test_structure_of_uniform_binary_and_label_shaped_masks():
    c = np.zeros((4, 4))
    c[:2] = 1.0  # the label changes only in the top half of the view
    uniform = np.full((1, 4, 4), 0.3)
    s = mask_structure(uniform, RANGE, c, ("count",))
    assert s.tv_per_texel == (0.0,) and s.at_limits == (0.0,)
    assert s.label_weight == pytest.approx((1.0,)) and s.label_alignment == (0.0,)
    top = np.where(c > 0, RANGE[1], RANGE[0])[None]
    s = mask_structure(top, RANGE, c, ("count",))
    assert s.at_limits == (1.0,)  # every texel at a limit
    assert s.label_alignment == pytest.approx((1.0,))
    # its light comes from the top: weight = (8 hi / (8 hi + 8 lo)) / mean(c) = 2 hi / (hi + lo)
    assert s.label_weight == pytest.approx((2 * RANGE[1] / (RANGE[1] + RANGE[0]),))
    # one step between the halves: 4 jumps of (hi - lo) over 16 texels
    assert s.tv_per_texel == pytest.approx((4 * (RANGE[1] - RANGE[0]) / 16,))


def test_mask_views_figure(tmp_path):
    c = np.linspace(0, 1, 16).reshape(4, 4)
    masks = np.stack([np.full((4, 4), 0.3), np.where(c > 0.5, 0.67, 0.01)])
    s = mask_structure(masks, RANGE, c, ("count",))
    path = plot_mask_views(masks, c, c, s, tmp_path / "m.png", title="test")
    assert path.stat().st_size > 5_000
