"""Models: shapes, losses per label kind, gradients reaching the mask logits."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.learn.models import (
    INIT_TRANSMITTANCE,
    BaselineCamera,
    CountLoss,
    Head,
    MincamCamera,
    box_pixels,
    task_loss,
    temporal_features,
)
from mincam_render.optics.camera import MM, DetectorLayout, FreeformCamera
from mincam_render.optics.maskplane import transmittance

SPECS = (
    LabelSpec(name="count", kind=LabelKind.COUNT),
    LabelSpec(name="zones", kind=LabelKind.BINARY, size=3, median_filter_s=0.5),
    LabelSpec(name="speed", kind=LabelKind.REGRESSION, size=2, unit="mph"),
)


def _camera(k: int = 3, res: int = 8) -> FreeformCamera:
    return FreeformCamera(
        mask_resolution=(res, res), layout=DetectorLayout.row(count=k, pitch_m=20 * MM)
    )


def _labels(b: int, rng) -> dict[str, torch.Tensor]:
    return {
        "count": torch.tensor(rng.integers(0, 5, (b, 1)), dtype=torch.float32),
        "zones": torch.tensor(rng.integers(0, 2, (b, 3)), dtype=torch.float32),
        "speed": torch.tensor(rng.uniform(0, 30, (b, 2)), dtype=torch.float32),
    }


@pytest.mark.parametrize("history", [1, 4])
def test_mincam_shapes_and_init(variant, rng, history):
    cam = _camera()
    head = Head(3 * max(history - 1, 1), SPECS)
    model = MincamCamera(cam, head, history=history)
    m = model.transmittance().detach().numpy()
    assert m.shape == (3, 8, 8)
    assert INIT_TRANSMITTANCE[0] - 1e-5 <= m.min() and m.max() <= INIT_TRANSMITTANCE[1] + 1e-5
    t = torch.from_numpy(rng.uniform(0, 1e-9, (5, history, 3, 8, 8)).astype(np.float32))
    out = model(t, noise=True, generator=torch.Generator().manual_seed(0))
    assert {k: tuple(v.shape) for k, v in out.items()} == {
        "count": (5, 1),
        "zones": (5, 3),
        "speed": (5, 2),
    }


def test_head_input_count_is_checked():
    with pytest.raises(ValueError, match="inputs"):
        MincamCamera(_camera(3), Head(4, SPECS))


def test_a_bottleneck_head_reads_its_inputs_through_k_linear_combinations(rng):
    head = Head(6, SPECS, bottleneck=2)
    assert head.bottleneck == 2 and head.in_features == 6 and head.fan_in == 6
    x = torch.from_numpy(rng.normal(size=(64, 6)).astype(np.float32))
    head(x)  # training mode: the input norms learn their running statistics
    head.eval()
    # a change of the standardised inputs in the null space of the K combinations
    # leaves every output unchanged; one along a combination does not
    w = head.first_layer.weight.detach().double().numpy()  # [2, 6]
    null = np.linalg.svd(w)[2][2:]  # [4, 6], orthogonal to both combinations
    std = torch.sqrt(head.input_norm.running_var + head.input_norm.eps)
    along = torch.from_numpy(null[0]).float() * std
    moved = {k: v.detach() for k, v in head(x + 3 * along).items()}
    for name, value in head(x).items():
        torch.testing.assert_close(moved[name], value.detach(), atol=2e-5, rtol=1e-4)
    across = torch.from_numpy(w[0]).float() * std
    assert not torch.allclose(head(x + 3 * across)["count"], head(x)["count"])
    # the paper's head has no bottleneck and the state it always had
    plain = Head(6, SPECS)
    assert plain.bottleneck == 0 and plain.first_layer is plain.body[0]
    assert not any(k.startswith("readout") for k in plain.state_dict())
    with pytest.raises(ValueError, match="bottleneck"):
        Head(6, SPECS, bottleneck=-1)


def test_temporal_features_are_forward_differences():
    x = torch.arange(12.0).reshape(1, 4, 3) ** 2
    f = temporal_features(x)
    expected = (x[:, 1:] - x[:, :-1]).reshape(1, -1)
    torch.testing.assert_close(f, expected)
    assert temporal_features(x[:, :1]).shape == (1, 3)


def test_loss_per_kind_closed_form():
    head = Head(
        2,
        SPECS,
        target_mean={"count": np.array([2.0]), "speed": np.array([10.0, 20.0])},
        target_std={"count": np.array([2.0]), "speed": np.array([5.0, 5.0])},
    )
    out = {
        "count": torch.tensor([[0.5]]),
        "zones": torch.tensor([[0.0, 2.0, -1.0]]),
        "speed": torch.tensor([[1.0, -1.0]]),
    }
    lab = {
        "count": torch.tensor([[4.0]]),
        "zones": torch.tensor([[1.0, 0.0, 0.0]]),
        "speed": torch.tensor([[10.0, 20.0]]),
    }
    total, parts = task_loss(head, out, lab)
    # count: standardised target (4-2)/2 = 1 -> (0.5-1)^2
    assert parts["count"].item() == pytest.approx(0.25, rel=1e-6)
    bce = [np.log(2.0), np.log1p(np.exp(2.0)), np.log1p(np.exp(-1.0))]
    assert parts["zones"].item() == pytest.approx(np.mean(bce), rel=1e-6)
    assert parts["speed"].item() == pytest.approx(1.0, rel=1e-6)
    assert total.item() == pytest.approx(0.25 + np.mean(bce) + 1.0, rel=1e-6)
    pred = head.predict(out)
    assert pred["count"].item() == pytest.approx(3.0)
    torch.testing.assert_close(pred["zones"], torch.sigmoid(out["zones"]))
    torch.testing.assert_close(pred["speed"], torch.tensor([[15.0, 15.0]]))


def test_count_cross_entropy_closed_form():
    """Classified count: cross-entropy of softmax, expected-count prediction, gradient."""
    specs = (LabelSpec(name="count", kind=LabelKind.COUNT, size=2), SPECS[2])
    head = Head(2, specs, count_classes={"count": 3})
    assert head.count_loss("count") is CountLoss.CROSS_ENTROPY
    assert head.count_loss("speed") is CountLoss.MSE
    out = head(torch.zeros(4, 2))
    assert {k: tuple(v.shape) for k, v in out.items()} == {"count": (4, 6), "speed": (4, 2)}
    # element-major: [element 0 classes 0..2, element 1 classes 0..2]
    z = np.array([[[0.0, 1.0, 2.0], [2.0, 0.0, -1.0]]])
    logits = torch.tensor(z.reshape(1, 6), dtype=torch.float64, requires_grad=True)
    lab = torch.tensor([[2.0, 7.0]], dtype=torch.float64)  # 7 is clipped to the top class
    total, parts = task_loss(
        head, {"count": logits, "speed": torch.zeros(1, 2)}, {"count": lab, "speed": lab}
    )
    p = np.exp(z) / np.exp(z).sum(-1, keepdims=True)
    assert parts["count"].item() == pytest.approx(-np.log(p[0, [0, 1], [2, 2]]).mean(), rel=1e-12)
    parts["count"].backward()
    onehot = np.zeros_like(p)
    onehot[0, :, 2] = 1.0
    np.testing.assert_allclose(
        logits.grad.numpy(), ((p - onehot) / 2).reshape(1, 6), rtol=1e-12, atol=1e-15
    )
    pred = head.predict({"count": logits.detach(), "speed": torch.zeros(1, 2)})["count"]
    np.testing.assert_allclose(pred.numpy(), (p @ np.arange(3.0)), rtol=1e-12)


@pytest.mark.parametrize(
    ("classes", "match"),
    [
        ({"zones": 3}, "not a COUNT label"),
        ({"nope": 3}, "not a COUNT label"),
        ({"count": 1}, ">= 2"),
    ],
)
def test_count_classes_are_checked(classes, match):
    with pytest.raises(ValueError, match=match):
        Head(2, SPECS, count_classes=classes)


def test_gradients_reach_logits_by_value(variant, rng):
    """d(sum of noiseless voltages)/d logits equals the closed form."""
    cam = _camera(2, 4)
    model = MincamCamera(cam, Head(2, SPECS[:1]))
    t = torch.from_numpy(rng.uniform(0, 1e-9, (3, 2, 4, 4)).astype(np.float32))
    v = model.measure(t, noise=False)
    v.sum().backward()
    e = cam.electronics
    lo, hi = cam.transmittance_range
    s = torch.sigmoid(model.logits.detach())
    expected = e.responsivity_a_per_w * e.gain_v_per_a * t.sum(0) * (hi - lo) * s * (1 - s)
    torch.testing.assert_close(model.logits.grad, expected, rtol=1e-4, atol=0)
    assert float(model.logits.grad.abs().min()) > 0


def test_mincam_power_matches_dot_product(variant, rng):
    cam = _camera(2, 4)
    model = MincamCamera(cam, Head(2, SPECS[:1]), sensor_model=False)
    t = torch.from_numpy(rng.uniform(0, 1e-9, (3, 2, 4, 4)).astype(np.float32))
    m = transmittance(model.logits.detach(), cam.transmittance_range)
    e = cam.electronics
    expected = (t * m).sum((2, 3)) * e.responsivity_a_per_w * e.gain_v_per_a
    torch.testing.assert_close(model.measure(t)[:, 0], expected, rtol=1e-5, atol=0)


def test_detector_subset_and_reuse(variant, rng):
    cam = _camera(2, 4)
    model = MincamCamera(cam, Head(3, SPECS[:1]), detectors=[1, 1, 0], sensor_model=False)
    t = torch.from_numpy(rng.uniform(0, 1e-9, (2, 2, 4, 4)).astype(np.float32))
    with torch.no_grad():
        model.logits[:] = 0.0
    v = model.measure(t)[:, 0]
    torch.testing.assert_close(v[:, 0], v[:, 1])
    assert not torch.allclose(v[:, 0], v[:, 2])


def test_a_signed_pixel_reads_its_plus_photodiode_minus_its_minus_photodiode(variant, rng):
    """Closed form: each output is the difference of its pair's readings, noise and all."""
    cam = _camera(4, 4)
    signed = MincamCamera(cam, Head(2, SPECS[:1]), signed=True)
    plain = MincamCamera(cam, Head(4, SPECS[:1]))
    plain.load_state_dict({k: v for k, v in signed.state_dict().items() if "head" not in k},
                          strict=False)  # fmt: skip
    assert signed.num_pixels == 4 and signed.num_outputs == 2 and plain.num_outputs == 4
    t = torch.from_numpy(rng.uniform(0, 1e-9, (5, 4, 4, 4)).astype(np.float32))
    for noise in (False, True):
        v = signed.measure(t, noise=noise, generator=torch.Generator().manual_seed(3))
        r = plain.measure(t, noise=noise, generator=torch.Generator().manual_seed(3))
        assert v.shape == (5, 1, 2)
        torch.testing.assert_close(v, r[..., 0::2] - r[..., 1::2], rtol=0, atol=0)
    # the noiseless difference is the masks' difference dotted with the view
    lo, hi = cam.transmittance_range
    m = transmittance(signed.logits.detach(), (lo, hi))
    e = cam.electronics
    dot = (t * m).sum((2, 3)) * e.responsivity_a_per_w * e.gain_v_per_a
    off = MincamCamera(cam, Head(2, SPECS[:1]), signed=True, sensor_model=False)
    off.load_state_dict(signed.state_dict())
    torch.testing.assert_close(off.measure(t)[:, 0], dot[:, 0::2] - dot[:, 1::2], rtol=1e-5, atol=0)


def test_a_signed_pixels_gradient_pulls_its_two_masks_apart(variant, rng):
    """d(output)/d(logits): the plus mask's closed form, and its negative on the minus mask."""
    cam = _camera(2, 4)
    model = MincamCamera(cam, Head(1, SPECS[:1]), signed=True)
    with torch.no_grad():
        model.logits[:] = 0.3
    view = torch.from_numpy(rng.uniform(0, 1e-9, (1, 4, 4)).astype(np.float32))
    t = view.expand(3, 2, 4, 4).contiguous()  # both photodiodes see the same view
    model.measure(t, noise=False).sum().backward()
    g = model.logits.grad
    e = cam.electronics
    lo, hi = cam.transmittance_range
    s = torch.sigmoid(torch.tensor(0.3))
    plus = e.responsivity_a_per_w * e.gain_v_per_a * 3 * view[0] * (hi - lo) * s * (1 - s)
    torch.testing.assert_close(g[0], plus, rtol=1e-4, atol=0)
    torch.testing.assert_close(g[1], -plus, rtol=1e-4, atol=0)


def test_signed_pixels_come_in_pairs_and_the_head_reads_one_input_per_pair():
    with pytest.raises(ValueError, match="3 pixels signed: a signed pixel is a pair"):
        MincamCamera(_camera(3), Head(1, SPECS[:1]), signed=True)
    with pytest.raises(ValueError, match="head has 4 inputs; this camera gives 2"):
        MincamCamera(_camera(4), Head(4, SPECS[:1]), signed=True)


@pytest.mark.parametrize("grid", [(1, 1), (2, 2), (4, 2), (8, 8)])
def test_box_pixels_preserve_power(rng, grid):
    img = torch.from_numpy(rng.uniform(0, 1, (2, 8, 8)))
    b = box_pixels(img, grid)
    assert b.shape == (2, *grid)
    torch.testing.assert_close(b.sum((1, 2)), img.sum((1, 2)), rtol=1e-9, atol=0)
    torch.testing.assert_close(box_pixels(img, (2, 2))[:, 0, 0], img[:, :4, :4].sum((1, 2)))


@pytest.mark.parametrize("grid", [(16, 28), (2, 4), (8, 14), (3, 5), (32, 32)])
def test_box_pixels_are_area_correct_on_grids_that_do_not_divide(rng, grid):
    # a 32x32 transport image (the traffic camera's masks) onto the paper's aspect
    img = torch.from_numpy(rng.uniform(0, 1, (3, 32, 32)))
    b = box_pixels(img, grid)
    assert b.shape == (3, *grid)
    torch.testing.assert_close(b.sum((1, 2)), img.sum((1, 2)), rtol=1e-12, atol=0)
    # uniform radiance: every pixel gets its area's share, 32*32/(R*C) texels' worth
    flat = box_pixels(torch.full((32, 32), 2.0, dtype=torch.float64), grid)
    expected = torch.full(grid, 2.0 * 1024 / (grid[0] * grid[1]), dtype=torch.float64)
    torch.testing.assert_close(flat, expected)


def test_box_pixels_split_a_texel_by_area():
    # 3 texels onto 2 columns: the middle texel is cut in half
    img = torch.tensor([[1.0, 10.0, 100.0]], dtype=torch.float64)
    expected = torch.tensor([[6.0, 105.0]], dtype=torch.float64)
    torch.testing.assert_close(box_pixels(img, (1, 2)), expected)


def test_baseline_of_a_non_square_grid_reads_every_pixel(rng):
    t = torch.from_numpy(rng.uniform(0, 1e-9, (4, 2, 32, 32)).astype(np.float32))
    grid = (16, 28)
    model = BaselineCamera(grid, Head(16 * 28, SPECS), exposure_w=1e-7)
    v = model.measure(t, noise=False)
    assert v.shape == (4, 1, 16 * 28)
    ref = box_pixels(t.double().mean(dim=1), grid).reshape(4, -1) / 1e-7
    torch.testing.assert_close(v[:, 0].double(), ref, rtol=1e-5, atol=1e-7)


def test_baseline_shapes_and_8bit_range(rng):
    t = torch.from_numpy(rng.uniform(0, 1e-9, (6, 3, 8, 8)).astype(np.float32))
    exposure = BaselineCamera.exposure_from(t.numpy(), (2, 2))
    model = BaselineCamera((2, 2), Head(4, SPECS), exposure_w=exposure)
    v = model.measure(t, noise=True, generator=torch.Generator().manual_seed(0))
    assert v.shape == (6, 1, 4)
    assert float(v.min()) >= 0.0 and float(v.max()) <= 1.0
    clean = model.measure(t, noise=False)
    # read noise 1 DN + uniform quantisation: the noisy image stays within a few DN
    assert float((v - clean).abs().max()) * 255 < 8
    out = model(t)
    assert out["zones"].shape == (6, 3)


def test_baseline_grid_larger_than_transport_is_refused(rng):
    t = torch.zeros(1, 1, 1, 4, 4)
    model = BaselineCamera((8, 8), Head(64, SPECS[:1]), exposure_w=1.0)
    with pytest.raises(ValueError, match="grid"):
        model.measure(t)


def _grads_of(model, t, labels, **kw):
    model.zero_grad(set_to_none=True)
    v = model.measure(t, generator=torch.Generator().manual_seed(5), **kw)
    out = model.head(temporal_features(v))
    task_loss(model.head, out, labels)[0].backward()
    return v.detach(), {n: p.grad.clone() for n, p in model.named_parameters()}


@pytest.mark.parametrize("detectors", [None, (2, 0, 0)])
def test_torch_and_drjit_mask_planes_give_the_same_measurements_and_gradients(
    variant, rng, detectors
):
    """The plain-torch training path equals the Dr.Jit op: values and d/d(masks, head)."""
    from mincam_render.optics.maskplane import MaskPlaneBackend

    cam = _camera()
    model = MincamCamera(cam, Head(3, SPECS), detectors=detectors)
    t = torch.from_numpy(rng.uniform(0, 2e-9, (16, 3, 8, 8)).astype(np.float32))
    gain = torch.from_numpy(rng.uniform(0.8, 1.2, 16).astype(np.float32))
    labels = _labels(16, rng)
    # noiseless: Dr.Jit's parallel sums differ from torch's in the last bits, and the
    # ADC's quantization can turn that into a whole LSB; the noise is the same code
    # on both paths
    v_torch, g_torch = _grads_of(model, t, labels, gain=gain, noise=False)
    model.mask_plane = MaskPlaneBackend.DRJIT
    v_drjit, g_drjit = _grads_of(model, t, labels, gain=gain, noise=False)
    torch.testing.assert_close(v_torch, v_drjit, rtol=1e-5, atol=1e-7)
    assert set(g_torch) == set(g_drjit) and "logits" in g_torch
    for name, g in g_torch.items():
        # float32 sums in another order (Dr.Jit's vary run to run): at most 4.3e-6 of the
        # largest element over 30 runs; 2e-5 keeps a 5x margin (1e-6 failed 1 run in 4)
        scale = g.abs().max()
        torch.testing.assert_close(g, g_drjit[name], rtol=1e-4, atol=2e-5 * scale, msg=name)
    assert g_torch["logits"].abs().max() > 0


@pytest.mark.parametrize("camera_kind", ["mincam", "baseline"])
def test_windows_of_shared_frames_equal_stacked_windows(variant, rng, camera_kind):
    """Measuring each frame once and indexing windows equals stacking every window's frames."""
    cam, h = _camera(), 4
    if camera_kind == "mincam":
        model = MincamCamera(cam, Head(3 * (h - 1), SPECS), history=h)
    else:
        model = BaselineCamera((2, 2), Head(4 * (h - 1), SPECS), exposure_w=1e-8, history=h)
    frames = torch.from_numpy(rng.uniform(0, 1e-9, (10, 3, 8, 8)).astype(np.float32))
    windows = torch.tensor([[0, 1, 2, 3], [5, 6, 7, 8], [1, 2, 3, 4], [0, 1, 2, 3]])
    stacked = frames[windows]  # [batch, time, K, R, C]
    gain = torch.tensor([0.9, 1.0, 1.1, 1.2])
    for noise in (False, True):  # the noise is drawn per window element in both
        kw = {"gain": gain, "noise": noise}
        a = model.measure(frames, windows=windows, generator=torch.Generator().manual_seed(1), **kw)
        b = model.measure(stacked, generator=torch.Generator().manual_seed(1), **kw)
        torch.testing.assert_close(a, b, rtol=1e-6, atol=1e-9)
    with pytest.raises(ValueError, match="with windows"):
        model.measure(stacked, windows=windows)


def test_a_label_constant_in_training_is_learned_unscaled(caplog):
    # no left traffic in training: a zero spread must not blow the loss up
    with caplog.at_level("WARNING"):
        head = Head(
            2,
            SPECS,
            target_mean={"count": np.array([2.0]), "speed": np.array([0.0, 20.0])},
            target_std={"count": np.array([2.0]), "speed": np.array([0.0, 5.0])},
        )
    assert "'speed' is constant in the training split" in caplog.text
    out = {
        "count": torch.tensor([[0.0]]),
        "zones": torch.tensor([[0.0, 0.0, 0.0]]),
        "speed": torch.tensor([[3.0, 0.0]]),
    }
    lab = {
        "count": torch.tensor([[2.0]]),
        "zones": torch.tensor([[0.0, 0.0, 0.0]]),
        "speed": torch.tensor([[0.0, 20.0]]),
    }
    _, parts = task_loss(head, out, lab)
    # left: (3 - 0)^2 in mph (scale 1); right: standardised 0 -> mean of [9, 0]
    assert parts["speed"].item() == pytest.approx(4.5, rel=1e-6)
    assert head.predict(out)["speed"][0, 0].item() == pytest.approx(3.0)
