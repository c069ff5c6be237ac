"""Rebuilding a dataset's manifest from its request and its shards (``mincam-render repair``).

A manifest that was edited or damaged is refused by every reader
(:func:`mincam_render.data.dataset.read_manifest`). Its ``request`` still says
what was asked, and each shard's own metadata records the hash of the request
it was rendered for and the checksum of its array. Repair plans the request
again (a kept fidelity plan gives the same settings at once) and keeps exactly
the shards that pass their own checksum and belong to that request; the rest
are left for the same ``render`` command to render again.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from dataclasses import dataclass
from pathlib import Path

from mincam_render.data import dataset as ds
from mincam_render.data.render_job import RenderRequest, package_versions, plan_render
from mincam_render.data.writer_lock import exclusive_writer

log = logging.getLogger(__name__)

#: Manifest fields that are records of work done (not what defines the data).
_RECORD_FIELDS = {"shards", "backgrounds", "background_components", "complete", "versions"}
#: Packages whose version must match for a new plan to equal the one the shards used.
_RENDERER_PACKAGES = ("mitsuba", "drjit")


@dataclass
class RepairSummary:
    """What :func:`repair_dataset` did."""

    path: Path
    num_shards: int
    kept: list[int]
    dropped: dict[int, str]
    restored_fields: list[str]


def repair_dataset(root: str | Path) -> RepairSummary:
    """Rewrite ``root``'s manifest from its request; keep the shards that prove themselves.

    Raises:
        DatasetError: no readable manifest or request to start from, or the
            dataset was rendered with another Mitsuba/Dr.Jit (a new plan could differ).
    """
    with exclusive_writer(Path(root), "repair") as root:
        damaged = _raw_manifest(root)
        _check_renderer(root, damaged)
        fresh = plan_render(_request_from_identity(root, damaged["request"]))
        restored = sorted(
            k
            for k in set(fresh) | set(damaged)
            if k not in _RECORD_FIELDS | {ds.MANIFEST_CHECKSUM_KEY}
            and fresh.get(k) != damaged.get(k)
        )
        kept, dropped = [], {}
        for i in range(fresh["num_shards"]):
            record, reason = _own_record(root, i, fresh["job"]["request_sha256"])
            fresh["shards"][i] = record
            if record is None:
                dropped[i] = reason
            else:
                kept.append(i)
        for name in ("backgrounds", "background_components"):
            if len(damaged.get(name) or []) == len(fresh[name] or []):
                fresh[name] = damaged[name]  # checked again by render before any use
        fresh["complete"] = not dropped
        ds.write_manifest(root, fresh)
    return RepairSummary(root, fresh["num_shards"], kept, dropped, restored)


def _raw_manifest(root: Path) -> dict:
    path = root / ds.MANIFEST_NAME
    try:
        manifest = json.loads(path.read_text())
        manifest["request"]["family"]
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise ds.DatasetError(
            f"{path}: cannot repair without a readable manifest and request ({err}): render "
            "again with the original command into a fresh --out directory"
        ) from None
    return manifest


def _check_renderer(root: Path, damaged: dict) -> None:
    then, now = damaged.get("versions") or {}, package_versions()
    differ = [p for p in _RENDERER_PACKAGES if then.get(p) != now.get(p)]
    if differ:
        pairs = ", ".join(f"{p} {then.get(p)} (now {now.get(p)})" for p in differ)
        raise ds.DatasetError(
            f"{root} was rendered with {pairs}: a new plan could differ from the one its "
            "shards used; repair with those versions, or render again into a fresh --out"
        )


def _request_from_identity(root: Path, identity: dict) -> RenderRequest:
    names = {f.name for f in dataclasses.fields(RenderRequest)}
    fields = {k: v for k, v in identity.items() if k in names}
    try:
        return RenderRequest(**fields | {"splits": tuple(fields.get("splits", ()))})
    except (TypeError, ValueError) as err:
        raise ds.DatasetError(f"{root}: the manifest's request is not valid ({err})") from None


def _own_record(root: Path, index: int, request_sha256: str) -> tuple[dict | None, str]:
    """The shard's record from its own files, if intact and rendered for this request."""
    record, reason = ds.verify_shard(root, index, None)
    if record is None:
        return None, reason
    meta = json.loads(ds.shard_paths(root, index)[1].read_text())
    if meta.get("request_sha256") != request_sha256:
        return None, "rendered for another request"
    return record, ""
