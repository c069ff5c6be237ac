"""`mincam-render repair`: an edited or damaged manifest is rebuilt from its request and shards."""

from __future__ import annotations

import json
import shutil

import pytest
from click.testing import CliRunner
from support import TINY_PATCHES

from mincam_render.cli.main import main
from mincam_render.data import dataset as ds
from mincam_render.data.render_job import render_dataset
from mincam_render.data.repair import repair_dataset


def _edit(root, change) -> None:
    path = root / ds.MANIFEST_NAME
    manifest = json.loads(path.read_text())
    change(manifest)
    path.write_text(json.dumps(manifest))


def _without_versions(manifest: dict) -> dict:
    return {k: v for k, v in manifest.items() if k != "versions"}


def test_an_edited_field_is_restored_and_every_shard_kept(tiny_patches, tiny_patches_copy):
    original, root = tiny_patches, tiny_patches_copy
    _edit(root, lambda m: m["job"]["render"].__setitem__("spp", 99))
    with pytest.raises(ds.DatasetError, match="mincam-render repair"):
        ds.open_dataset(root)
    summary = repair_dataset(root)
    assert summary.kept == [0, 1, 2] and summary.dropped == {}
    assert summary.restored_fields == ["job"]
    repaired = ds.read_manifest(root)
    assert _without_versions(repaired) == _without_versions(ds.read_manifest(original))
    assert ds.open_dataset(root).verify() == []


def test_a_stripped_checksum_with_an_edit_is_refused_then_repaired(tiny_patches, tiny_patches_copy):
    original, root = tiny_patches, tiny_patches_copy

    def strip_and_edit(m):
        del m[ds.MANIFEST_CHECKSUM_KEY]
        m["camera"]["mask_distance_m"] *= 10

    _edit(root, strip_and_edit)
    with pytest.raises(ds.DatasetError, match="no manifest_sha256"):
        ds.open_dataset(root)
    summary = repair_dataset(root)
    assert summary.kept == [0, 1, 2] and summary.restored_fields == ["camera"]
    assert _without_versions(ds.read_manifest(root)) == _without_versions(
        ds.read_manifest(original)
    )


def test_a_damaged_shard_is_dropped_and_the_render_command_restores_it(
    tiny_patches, tiny_patches_copy
):
    original, root = tiny_patches, tiny_patches_copy
    npy, _ = ds.shard_paths(root, 1)
    data = bytearray(npy.read_bytes())
    data[len(data) // 2] ^= 0x40
    npy.write_bytes(bytes(data))
    (root / ds.MANIFEST_NAME).write_text("{ truncated")
    with pytest.raises(ds.DatasetError, match="cannot repair without a readable manifest"):
        repair_dataset(root)
    shutil.copy(original / ds.MANIFEST_NAME, root / ds.MANIFEST_NAME)
    _edit(root, lambda m: m.__setitem__("num_frames", 16))
    summary = repair_dataset(root)
    assert summary.kept == [0, 2] and "sha256" in summary.dropped[1]
    assert not ds.read_manifest(root)["complete"]
    render_dataset(TINY_PATCHES, root, workers=0)
    for i in range(3):
        assert (
            ds.shard_paths(root, i)[0].read_bytes() == ds.shard_paths(original, i)[0].read_bytes()
        )


def test_shards_of_another_request_are_not_kept(tiny_patches_copy):
    """An edited request: the shards were rendered for the original one, so none is kept."""
    root = tiny_patches_copy
    _edit(root, lambda m: m["request"].__setitem__("seed", 4))
    summary = repair_dataset(root)
    assert summary.kept == [] and set(summary.dropped.values()) == {"rendered for another request"}


def test_cli_repair_reports_in_lines(tiny_patches_copy, tmp_path):
    root = tiny_patches_copy
    _edit(root, lambda m: m["job"]["render"].__setitem__("spp", 99))
    res = CliRunner().invoke(main, ["repair", str(root)])
    assert res.exit_code == 0, res.output
    assert "kept 3 of 3 shards; fields restored from the request's plan: job" in res.output
    missing = CliRunner().invoke(main, ["repair", str(tmp_path / "nothing")])
    assert missing.exit_code == 2 and "cannot repair" in missing.output


def test_a_differential_dataset_keeps_its_shards(differential_dataset_copy):
    """Differential shards record their request's hash (they recorded a background key,
    so `repair` kept none of them and a killed render re-rendered its unrecorded shards)."""
    root = differential_dataset_copy
    manifest = ds.read_manifest(root)
    assert manifest["job"]["render"]["background"] is not None  # differential indeed
    shards = list(range(len(manifest["shards"])))
    for i in shards:
        meta = json.loads(ds.shard_paths(root, i)[1].read_text())
        assert meta["request_sha256"] == manifest["job"]["request_sha256"]
    _edit(root, lambda m: m["job"]["render"].__setitem__("spp", 99))
    summary = repair_dataset(root)
    assert summary.kept == shards == [0, 1, 2] and summary.dropped == {}
