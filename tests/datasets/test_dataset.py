"""On-disk dataset format: round trip, torch Dataset, splits, checksums, EXR export."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pytest
from support import TINY_CAMERA, TINY_PATCHES

from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.data import dataset as ds
from mincam_render.optics.camera import (
    DetectorElectronics,
    DetectorLayout,
    DirectionalResponse,
    FreeformCamera,
)
from mincam_render.render import precision


def test_round_trip_matches_direct_render(tiny_patches):
    from mincam_render.core.seeds import frame_seed
    from mincam_render.render.transport import render_transport
    from mincam_render.scenes.registry import load_family

    req = TINY_PATCHES  # rendered per detector, stored as float32: frames equal the renders
    d = ds.open_dataset(tiny_patches)
    family = load_family("patches", seed=req.seed, num_frames=24, overrides=TINY_CAMERA)
    assert d.family == "patches" and d.num_frames == 24 and d.fps == family.fps
    assert d.camera == family.camera()
    assert d.label_specs == family.labels
    scene = family.build_scene()
    for i in (0, 11, 23):
        labels = family.set_frame(scene, i)
        t = render_transport(scene, family.camera(), spp=req.spp, seed=frame_seed(req.seed, i))
        np.testing.assert_array_equal(d.frame(i), t)
        np.testing.assert_array_equal(d.frame_labels(i)["count"], labels["count"])
        meta = d.frame_metadata(i)
        assert meta["seed"] == frame_seed(req.seed, i)
        assert meta["time_s"] == pytest.approx(i / d.fps)
        assert meta["state"]["count"] == int(labels["count"][0])


def test_splits_are_contiguous_and_cover_the_sequence(tiny_patches):
    d = ds.open_dataset(tiny_patches)
    assert d.splits == {"train": (0, 17), "val": (17, 20), "test": (20, 24)}
    total = 0
    for name, (a, b) in d.splits.items():
        t, lab, times = d.transport(name), d.labels(name), d.times_s(name)
        assert t.shape == (b - a, 2, 8, 8) and t.dtype == np.float32
        assert lab["count"].shape == (b - a, 1) and lab["count"].dtype == np.float32
        np.testing.assert_allclose(times, np.arange(a, b) / d.fps)
        total += b - a
    assert total == d.num_frames
    np.testing.assert_array_equal(d.transport("val"), d.frames(17, 20))


@pytest.mark.parametrize(
    ("fractions", "expected"),
    [((0.7, 0.15, 0.15), (70, 85)), ((1.0, 0.0, 0.0), (100, 100)), ((0.5, 0.25, 0.25), (50, 75))],
)
def test_split_ranges(fractions, expected):
    r = ds.split_ranges(100, fractions)
    assert r["train"] == (0, expected[0]) and r["val"] == (expected[0], expected[1])
    assert r["test"] == (expected[1], 100)


def test_split_ranges_rejects_bad_fractions():
    with pytest.raises(ValueError, match="summing to 1"):
        ds.split_ranges(10, (0.5, 0.5, 0.5))


@pytest.mark.parametrize("history", [1, 4])
def test_torch_dataset_shapes_and_windows(tiny_patches, history):
    import torch

    d = ds.open_dataset(tiny_patches)
    tds = d.torch_dataset("train", history=history)
    assert isinstance(tds, torch.utils.data.Dataset)
    a, b = d.splits["train"]
    assert len(tds) == (b - a) - history + 1
    t, labels = tds[0]
    newest = a + history - 1
    if history == 1:
        assert t.shape == (2, 8, 8)
        np.testing.assert_array_equal(t.numpy(), d.frame(newest))
    else:
        assert t.shape == (history, 2, 8, 8)
        np.testing.assert_array_equal(t.numpy(), d.frames(a, newest + 1))  # oldest first
    assert t.dtype == torch.float32 and labels["count"].shape == (1,)
    np.testing.assert_array_equal(labels["count"].numpy(), d.frame_labels(newest)["count"])
    loader = torch.utils.data.DataLoader(tds, batch_size=3)
    batch_t, batch_l = next(iter(loader))
    assert batch_t.shape[0] == 3 and batch_l["count"].shape == (3, 1)


def test_torch_dataset_rejects_too_long_history(tiny_patches):
    with pytest.raises(ValueError, match="history"):
        ds.open_dataset(tiny_patches).torch_dataset("val", history=4)  # val is 3 frames


def test_torch_dataset_pickles(tiny_patches):
    import pickle

    tds = ds.open_dataset(tiny_patches).torch_dataset("train")
    tds[0]  # opens memory maps, which must not travel
    again = pickle.loads(pickle.dumps(tds))
    np.testing.assert_array_equal(again[5][0].numpy(), tds[5][0].numpy())


def test_float16_encoding_error_and_scales(rng):
    # one frame near moonlight, one near direct sun: per-frame power-of-two scales
    t = np.stack([rng.uniform(0, 1e-12, (2, 8, 8)), rng.uniform(0, 1e3, (2, 8, 8))]).astype(
        np.float32
    )
    stored, scales = precision.encode_transport(t, "float16")
    assert stored.dtype == np.float16 and np.all(np.abs(stored) <= 1)
    assert np.all(np.log2(scales) == np.round(np.log2(scales)))
    back = precision.decode_transport(stored, scales)
    # float16 rounding: relative 2^-11 per element for values near the frame's peak
    err = precision.measurement_relative_error(back[:, None, 0], t[:, None, 0], (0.01, 0.67))
    assert err["max"] < 2e-3
    s32, sc32 = precision.encode_transport(t, "float32")
    np.testing.assert_array_equal(precision.decode_transport(s32, sc32), t)


def test_storage_dtype_is_an_enum_converted_once_and_other_values_are_named():
    from mincam_render.data.render_job import RenderRequest
    from mincam_render.render.fidelity.plan import FidelityPlan

    req = RenderRequest(family="patches", num_frames=4, dtype="float16")
    assert req.dtype is precision.StorageDtype.FLOAT16
    # the identity (what a dataset's manifest hashes) holds the plain string, as before
    identity = req.identity({})
    assert identity["dtype"] == "float16" and type(identity["dtype"]) is str
    assert '"dtype": "float16"' in json.dumps(identity, sort_keys=True)
    allowed = "allowed None or one of float16, float32"
    with pytest.raises(ValueError, match=f"RenderRequest.dtype = 'float64' is invalid: {allowed}"):
        RenderRequest(family="patches", num_frames=4, dtype="float64")
    with pytest.raises(ValueError, match="dtype = 'half': allowed float16, float32"):
        precision.encode_transport(np.zeros((1, 1, 2, 2), np.float32), "half")
    plan = FidelityPlan(
        spp=1, max_depth=2, shared_render=True, mask_resolution=8, dtype="float32",
        background=None, decisions={},
    )  # fmt: skip
    assert plan.dtype is precision.StorageDtype.FLOAT32
    assert type(plan.settings()["dtype"]) is str
    with pytest.raises(ValueError, match="dtype = 'f32': allowed float16, float32"):
        dataclasses.replace(plan, dtype="f32")


def test_error_relative_to_each_frame_or_to_the_mean_frame():
    # uniform transport: every mask measures the same multiple of the frame's level,
    # so a constant error e_i of frame i is e_i / level_i or e_i / mean level
    levels = np.array([1.0, 10.0])
    ref = np.ones((2, 1, 4, 4)) * levels[:, None, None, None]
    test = ref + 0.1 * np.ones((2, 1, 4, 4))  # the same absolute error in both frames
    per_frame = precision.measurement_relative_error(test, ref, (0.5, 0.5))
    mean = precision.measurement_relative_error(test, ref, (0.5, 0.5), scale="mean")
    np.testing.assert_allclose(per_frame["max"], 0.1)
    np.testing.assert_allclose(per_frame["rms"], np.sqrt((0.1**2 + 0.01**2) / 2))
    np.testing.assert_allclose(mean["max"], 0.1 / 5.5)
    np.testing.assert_allclose(mean["rms"], 0.1 / 5.5)
    with pytest.raises(ValueError, match="scale = 'median'"):
        precision.measurement_relative_error(test, ref, (0.5, 0.5), scale="median")


def test_encode_rejects_non_finite():
    with pytest.raises(ValueError, match="NaN"):
        precision.encode_transport(np.full((1, 1, 2, 2), np.nan, np.float32), "float16")


def test_camera_and_label_specs_round_trip_through_json():
    cam = FreeformCamera(
        mask_resolution=(12, 16),
        layout=DetectorLayout.grid(rows=2, cols=3, pitch_m=0.021),
        position=(0.1, 0.2, 0.3),
        look_at=(1.0, 0.5, 0.3),
        up=(0.0, 0.0, 1.0),
        directional_response=DirectionalResponse(
            angles_deg=(0.0, 45.0, 90.0), relative_sensitivity=(1.0, 0.9, 0.2)
        ),
        electronics=DetectorElectronics(gain_v_per_a=3e6, adc_bits=12),
        transmittance_range=(0.02, 0.6),
    )
    back = ds.camera_from_dict(json.loads(json.dumps(ds.camera_to_dict(cam))))
    assert back == cam
    assert ds.camera_from_dict(
        ds.camera_to_dict(dataclasses.replace(cam, directional_response=None))
    ) == dataclasses.replace(cam, directional_response=None)
    spec = LabelSpec(
        name="zones",
        kind=LabelKind.BINARY,
        size=3,
        unit="",
        element_names=("a", "b", "c"),
        median_filter_s=0.5,
    )
    assert ds.label_spec_from_dict(json.loads(json.dumps(ds.label_spec_to_dict(spec)))) == spec


def test_checksum_detects_corruption(tiny_patches, tmp_path):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(tiny_patches, copy)
    d = ds.open_dataset(copy)
    assert d.verify() == []
    npy, _ = ds.shard_paths(copy, 2)
    data = bytearray(npy.read_bytes())
    data[-5] ^= 0xFF
    npy.write_bytes(bytes(data))
    bad = d.verify()
    assert [i for i, _ in bad] == [2] and "sha256" in bad[0][1]


def test_incomplete_dataset_is_refused(tiny_patches, tmp_path):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(tiny_patches, copy)
    m = ds.read_manifest(copy)
    m["shards"][1] = None
    m["complete"] = False
    ds.write_manifest(copy, m)
    with pytest.raises(ds.DatasetError, match="incomplete"):
        ds.open_dataset(copy)


def test_not_a_dataset(tmp_path):
    with pytest.raises(ds.DatasetError, match="not a mincam_render dataset"):
        ds.open_dataset(tmp_path)


def test_export_exr_round_trip(tiny_patches, tmp_path):
    from mincam_render.data.exr import read_transport_exr

    d = ds.open_dataset(tiny_patches)
    paths = d.export_exr(ds.parse_frame_list("3,10-11", d.num_frames), tmp_path)
    assert [p.name for p in paths] == ["frame-000003.exr", "frame-000010.exr", "frame-000011.exr"]
    t, meta = read_transport_exr(paths[1])
    np.testing.assert_array_equal(t, d.frame(10))
    assert (
        meta["frame"]["index"] == 10
        and meta["labels"]["count"] == d.frame_labels(10)["count"].tolist()
    )


def test_parse_frame_list_rejects_out_of_range():
    with pytest.raises(ValueError, match=r"\[0, 9\]"):
        ds.parse_frame_list("5,12", 10)


def test_stale_temporaries_of_dead_writers_are_removed(tmp_path):
    import os
    import subprocess
    import sys

    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    (tmp_path / "shards").mkdir()
    stale = tmp_path / "shards" / f".shard-00001.npy.{dead}.0123abcd.tmp"
    live = tmp_path / f".manifest.json.{os.getpid()}.89abcdef.tmp"
    other = tmp_path / ".notes.tmp"
    for p in (stale, live, other):
        p.write_bytes(b"partial")
    assert ds.remove_stale_temporaries(tmp_path) == [stale]
    assert not stale.exists() and live.exists() and other.exists()


def test_manifest_carries_its_own_checksum_and_one_without_is_refused(tmp_path):
    body = {"format": ds.FORMAT_NAME, "format_version": ds.FORMAT_VERSION, "shards": [None]}
    ds.write_manifest(tmp_path, body)
    on_disk = json.loads((tmp_path / ds.MANIFEST_NAME).read_text())
    assert on_disk[ds.MANIFEST_CHECKSUM_KEY] == hashlib.sha256(ds.json_bytes(body)).hexdigest()
    assert ds.read_manifest(tmp_path) == body  # the checksum is not part of what callers see
    on_disk["shards"] = [None, None]  # any edit
    (tmp_path / ds.MANIFEST_NAME).write_text(json.dumps(on_disk))
    with pytest.raises(ds.DatasetError, match="was changed after it was written"):
        ds.read_manifest(tmp_path)
    del on_disk[ds.MANIFEST_CHECKSUM_KEY]  # removed (then perhaps edited) by hand
    (tmp_path / ds.MANIFEST_NAME).write_text(json.dumps(on_disk))
    with pytest.raises(ds.DatasetError, match="no manifest_sha256.*mincam-render repair"):
        ds.read_manifest(tmp_path)
