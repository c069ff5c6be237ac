"""Training: the loss really falls, resume equals continuing, pruning order, post-processing."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from mincam_render import train as tr
from mincam_render.camera import MM, DetectorLayout, FreeformCamera
from mincam_render.generators.base import LabelKind, LabelSpec
from mincam_render.models import CountLoss

COUNT = LabelSpec(name="count", kind=LabelKind.COUNT, median_filter_s=0.0)


def linear_task(n: int = 200, k: int = 2, res: int = 8, seed: int = 0, dead: int | None = None):
    """Frames whose count is a linear function of the top half of detector 0's image."""
    rng = np.random.default_rng(seed)
    cam = FreeformCamera(
        mask_resolution=(res, res), layout=DetectorLayout.row(count=k, pitch_m=20 * MM)
    )
    base = rng.uniform(0.0, 1.0, (n, 1, res, res)).astype(np.float32)
    t = np.repeat(base, k, axis=1) * np.float32(2e-8)
    t += rng.uniform(0, 2e-9, t.shape).astype(np.float32)
    if dead is not None:
        t[:, dead] = 0.0
    signal = base[:, 0, : res // 2].mean(axis=(1, 2)) - base[:, 0, res // 2 :].mean(axis=(1, 2))
    count = np.clip(np.rint(5 + 40 * signal), 0, None).astype(np.float32)[:, None]
    return tr.TrainingData(
        transport=t,
        labels={"count": count},
        label_specs=(COUNT,),
        camera=cam,
        fps=30.0,
        source={"family": "synthetic"},
    )


CFG = tr.TrainConfig(max_steps=150, batch_size=32, eval_every=25, patience=100, mask_lr=0.05)


def test_training_lowers_the_loss(variant):
    train, val, test = linear_task(260).split((0.7, 0.15, 0.15))
    model = tr.build_mincam(train, 2)
    before = tr.predict(model, val)[2]
    logits0 = model.logits.detach().clone()
    res = tr.train_model(model, train, val, CFG)
    after = tr.predict(model, val)[2]
    assert after < 0.6 * before, (before, after, res.history)
    assert not torch.allclose(model.logits, logits0)  # the masks moved too
    assert tr.evaluate(model, test)["error"] < float(test.labels["count"].std())


def test_baseline_trains(variant):
    train, val, _ = linear_task(260).split((0.7, 0.15, 0.15))
    model = tr.build_baseline(train, (2, 1))
    before = tr.predict(model, val)[2]
    tr.train_model(model, train, val, CFG)
    assert tr.predict(model, val)[2] < 0.6 * before


def test_resume_equals_continuing(variant, tmp_path):
    train, val, _ = linear_task(120).split((0.7, 0.15, 0.15))
    cfg = tr.TrainConfig(max_steps=20, batch_size=16, eval_every=5, patience=100)
    full = tr.build_mincam(train, 2, seed=3)
    tr.train_model(full, train, val, cfg, out_dir=tmp_path / "full")
    first = tr.build_mincam(train, 2, seed=3)
    part = tr.train_model(first, train, val, cfg, out_dir=tmp_path / "killed", stop_after_steps=12)
    assert part.steps == 12
    again = tr.build_mincam(train, 2, seed=3)  # a new process: fresh objects
    res = tr.train_model(again, train, val, cfg, out_dir=tmp_path / "killed")
    assert res.steps == 20
    for (k, a), (_, b) in zip(full.state_dict().items(), again.state_dict().items(), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-7, msg=k)
    ck_a = torch.load(tmp_path / "full" / "checkpoint.pt", weights_only=False)
    ck_b = torch.load(tmp_path / "killed" / "checkpoint.pt", weights_only=False)
    torch.testing.assert_close(
        ck_a["model"]["logits"], ck_b["model"]["logits"], rtol=1e-5, atol=1e-7
    )
    assert [h["step"] for h in ck_b["history"]] == [5, 10, 15, 20]


def test_resume_refuses_another_model(variant, tmp_path):
    train, val, _ = linear_task(80).split((0.7, 0.15, 0.15))
    cfg = tr.TrainConfig(max_steps=4, batch_size=8, eval_every=2)
    tr.train_model(tr.build_mincam(train, 2), train, val, cfg, out_dir=tmp_path)
    with pytest.raises(ValueError, match="written for"):
        tr.train_model(tr.build_mincam(train, 1), train, val, cfg, out_dir=tmp_path)


def test_pruning_drops_the_dark_detector_first(variant):
    train, val, test = linear_task(200, k=3, dead=1).split((0.7, 0.15, 0.15))
    model = tr.build_mincam(train, 3)
    tr.train_model(model, train, val, replace_cfg(max_steps=80))
    records = tr.greedy_prune(model, train, val, test, replace_cfg(max_steps=20), min_pixels=2)
    assert [r["pixels"] for r in records] == [3, 2]
    assert records[1]["removed"] == [1]
    assert records[1]["kept"] == [0, 2]


@pytest.mark.parametrize(
    ("family", "explicit", "expected"),
    [
        ("patches", None, CountLoss.CROSS_ENTROPY),  # paper Sec. 5
        ("workspace", None, CountLoss.MSE),  # paper supplement C
        ("synthetic", None, CountLoss.MSE),
        ("patches", CountLoss.MSE, CountLoss.MSE),
        ("synthetic", "cross_entropy", CountLoss.CROSS_ENTROPY),
    ],
)
def test_count_loss_defaults_to_the_papers_choice(family, explicit, expected):
    from dataclasses import replace

    data = replace(linear_task(40), source={"family": family})
    assert tr.count_loss_for(data, explicit) is expected
    classes = tr.count_classes_for(data, explicit)
    top = int(data.labels["count"].max())
    assert classes == ({"count": top + 1} if expected is CountLoss.CROSS_ENTROPY else {})
    model = tr.build_mincam(data, 2, count_loss=explicit)
    assert model.head.count_classes == classes
    assert ("count_classes" in tr.describe_model(model)) == bool(classes)


def test_train_config_count_loss_is_checked():
    assert tr.TrainConfig(count_loss="cross_entropy").count_loss is CountLoss.CROSS_ENTROPY
    with pytest.raises(ValueError, match="count_loss"):
        tr.TrainConfig(count_loss="huber")


def test_cross_entropy_count_trains_resumes_and_prunes(variant, tmp_path):
    train, val, test = linear_task(260, k=3).split((0.7, 0.15, 0.15))
    ce = CountLoss.CROSS_ENTROPY
    model = tr.build_mincam(train, 3, count_loss=ce)
    before = tr.predict(model, val)[2]
    tr.train_model(model, train, val, CFG, out_dir=tmp_path)
    after = tr.predict(model, val)[2]
    err = tr.evaluate(model, test)["error"]
    assert after < before  # cross-entropy over ~15 classes falls slower than MSE
    assert err < 0.7 * float(test.labels["count"].std())  # measured 0.57 x
    with pytest.raises(ValueError, match="written for"):  # an MSE head is another model
        tr.train_model(
            tr.build_mincam(train, 3, count_loss=CountLoss.MSE), train, val, CFG, out_dir=tmp_path
        )
    records = tr.greedy_prune(model, train, val, test, replace_cfg(max_steps=10), min_pixels=2)
    assert [r["pixels"] for r in records] == [3, 2]


def replace_cfg(**kw) -> tr.TrainConfig:
    from dataclasses import replace

    return replace(CFG, **kw)


@pytest.mark.parametrize(
    ("seconds", "fps", "window"),
    [(2.0, 30.0, 61), (0.5, 30.0, 15), (0.0, 30.0, 1), (0.5, 4.0, 3), (2.0, 1.0, 3)],
)
def test_median_filter_window(seconds, fps, window):
    assert tr.median_filter_window(seconds, fps) == window


def test_median_filter_known_sequence():
    x = np.array([1, 1, 9, 1, 1, 5, 5, 0, 5, 5], dtype=np.float64)[:, None]
    y = tr.median_filter(x, 3)
    np.testing.assert_array_equal(y[:, 0], [1, 1, 1, 1, 1, 5, 5, 5, 5, 5])
    np.testing.assert_array_equal(tr.median_filter(x, 1), x)


def test_postprocess_rounds_thresholds_and_filters():
    specs = (
        LabelSpec(name="count", kind=LabelKind.COUNT, median_filter_s=3 / 30),
        LabelSpec(name="door", kind=LabelKind.BINARY, median_filter_s=3 / 30),
        LabelSpec(name="speed", kind=LabelKind.REGRESSION, median_filter_s=0.0),
    )
    pred = {
        "count": np.array([[1.4], [1.6], [-0.7], [2.2], [2.4]]),
        "door": np.array([[0.2], [0.7], [0.1], [0.9], [0.8]]),
        "speed": np.array([[3.3], [2.1], [7.5], [1.0], [0.0]]),
    }
    post = tr.postprocess(pred, specs, fps=30.0)
    # rounded 1, 2, 0, 2, 2 -> median over 3 (edges replicated)
    np.testing.assert_array_equal(post["count"][:, 0], [1, 1, 2, 2, 2])
    # thresholded 0, 1, 0, 1, 1 -> median 0, 0, 1, 1, 1
    np.testing.assert_array_equal(post["door"][:, 0], [0, 0, 1, 1, 1])
    np.testing.assert_array_equal(post["speed"], pred["speed"])


def test_history_windows_and_forward_differences(variant):
    d = linear_task(40)
    d = tr.TrainingData(
        transport=d.transport,
        labels=d.labels,
        label_specs=d.label_specs,
        camera=d.camera,
        fps=30.0,
        history=4,
    )
    assert len(d) == 37
    t, y = d.batch(np.array([0, 36]))
    assert t.shape == (2, 4, 2, 8, 8)
    np.testing.assert_array_equal(t[1, -1].numpy(), d.transport[39])
    np.testing.assert_array_equal(y["count"].numpy(), d.labels["count"][[3, 39]])
    model = tr.build_mincam(d, 2)
    assert model.head.in_features == 2 * 3
    assert model(t)["count"].shape == (2, 1)


def test_event_file_round_trip(tmp_path):
    w = tr.EventWriter(tmp_path)
    w.scalar("loss/train", 0.5, 1)
    w.scalar("loss/val", 0.25, 300)
    w.close()
    (path,) = tmp_path.glob("events.out.tfevents.*")
    assert tr.read_events(path) == [(1, "loss/train", 0.5), (300, "loss/val", 0.25)]


def test_train_run_writes_logs_and_metrics(variant, tmp_path):
    train, val, test = linear_task(120).split((0.7, 0.15, 0.15))
    cfg = tr.TrainConfig(max_steps=10, batch_size=16, eval_every=5)
    metrics = tr.train_run(train, val, test, tmp_path, pixels=2, config=cfg)
    assert metrics["test"]["labels"]["count"]["rmse"] >= 0
    for name in (
        "run.json",
        "metrics.json",
        "checkpoint.pt",
        "history.jsonl",
        "mask_evolution.png",
    ):
        assert (tmp_path / name).is_file(), name
    assert json.loads((tmp_path / "run.json").read_text())["model"]["pixels"] == 2
    m, camera, _ = tr.run_masks(tmp_path)
    assert m.shape == (2, 8, 8)
    lo, hi = camera.transmittance_range
    assert lo <= m.min() and m.max() <= hi


def test_rendered_patches_and_on_the_fly(variant):
    from mincam_render.generators import load_family

    fam = load_family(
        "patches",
        seed=0,
        num_frames=40,
        overrides={"camera": {"detectors": 2, "mask_resolution": 8}},
    )
    data = tr.TrainingData.render(fam, range(12), spp=1)
    assert data.transport.shape == (12, 2, 8, 8) and data.transport.dtype == np.float32
    assert float(data.transport.min()) >= 0 and float(data.transport.max()) > 0
    train, val = data.split((0.75, 0.25))
    stream = tr.RenderedBatches(fam, 4, spp=1, start_frame=12)
    model = tr.build_mincam(train, 2)
    res = tr.train_model(
        model, stream, val, tr.TrainConfig(max_steps=2, batch_size=4, eval_every=1)
    )
    assert res.steps == 2 and stream.next_frame == 20
