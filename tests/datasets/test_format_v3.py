"""Datasets of format version 3 (written before format 4): read, trained on, not resumed.

``tests/data/dataset_v3`` is a 24-frame patches dataset (2 detectors, 8 x 8
texels, float16, 3 shards) rendered by the format-3 code (commit 4ff124f).
Format 4 renders other bytes for the same request (seeds, daylight, paths,
diode response: docs/format_v4.md), so resuming it could not be exact.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from mincam_render.data import dataset as ds
from mincam_render.data.render_job import RenderRequest, render_dataset
from mincam_render.learn import train as tr

FIXTURE = Path(__file__).parent.parent / "data" / "dataset_v3"
#: The request the fixture was rendered from (the kept format 3 dataset in tests/data,
#: so not conftest's ``tiny_patches``: it is tiny_patches' request stored as float16).
V3_REQUEST = RenderRequest(
    family="patches",
    num_frames=24,
    seed=1,
    overrides={"camera": {"detectors": 2, "mask_resolution": 8}},
    shard_frames=8,
    spp=2,
    dtype="float16",
)


@pytest.fixture
def v3_copy(tmp_path: Path) -> Path:
    out = tmp_path / "v3"
    shutil.copytree(FIXTURE, out)
    return out


def test_v3_dataset_is_read_and_verified(v3_copy):
    d = ds.open_dataset(v3_copy)
    assert d.manifest["format_version"] == 3 < ds.FORMAT_VERSION
    assert d.verify() == []  # every shard passes its checksums
    t = d.transport("train")
    assert t.dtype == np.float32 and t.shape[1:] == (2, 8, 8)
    assert np.isfinite(t).all() and float(t.min()) >= 0.0 < float(t.max())
    counts = d.labels("train")["count"]
    assert counts.shape == (t.shape[0], 1) and set(np.unique(counts)) <= set(range(11))


def test_v3_dataset_trains(v3_copy, variant):
    d = ds.open_dataset(v3_copy)
    train, val = (tr.TrainingData.from_dataset(d, s) for s in ("train", "val"))
    model = tr.build_mincam(train, 2)
    res = tr.train_model(model, train, val, tr.TrainConfig(max_steps=3, batch_size=4, eval_every=1))
    assert res.steps == 3 and np.isfinite(tr.evaluate(model, val).error)


def test_v3_dataset_is_not_resumed_and_the_message_names_the_fix(v3_copy, variant):
    m = ds.read_manifest(v3_copy)
    m["shards"][2], m["complete"] = None, False  # an interrupted v3 render
    ds.write_manifest(v3_copy, m)
    before = sorted(p.name for p in (v3_copy / ds.SHARD_DIR).iterdir())
    with pytest.raises(ds.DatasetError, match=r"format version 3.*writes 4.*another --out"):
        render_dataset(V3_REQUEST, v3_copy, workers=0)
    assert sorted(p.name for p in (v3_copy / ds.SHARD_DIR).iterdir()) == before
