"""Opening a dataset written by other package versions warns only when shards remain to render."""

from __future__ import annotations

import logging

from support import TINY_PATCHES

from mincam_render.data import dataset as ds
from mincam_render.data.render_job import render_dataset

LOGGER = "mincam_render.data.render_job.manifest"


def _written_by_another_revision(root) -> None:
    manifest = ds.read_manifest(root)
    manifest["versions"] = {**manifest["versions"], "git_revision": "0" * 40}
    ds.write_manifest(root, manifest)


def _version_warnings(caplog) -> list[str]:
    messages = [r.getMessage() for r in caplog.records if r.name == LOGGER]
    return [m for m in messages if "package versions" in m]


def test_a_finished_dataset_of_other_versions_opens_quietly_and_a_resumed_one_warns(
    tiny_patches_copy, caplog
):
    root = tiny_patches_copy
    _written_by_another_revision(root)
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        render_dataset(TINY_PATCHES, root, workers=0)
    assert not _version_warnings(caplog)
    for path in ds.shard_paths(root, 1):
        path.unlink()
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        render_dataset(TINY_PATCHES, root, workers=0)
    (warning,) = _version_warnings(caplog)
    assert "(1 of 3 shards to render) with other package versions" in warning
    assert "0" * 40 in warning
